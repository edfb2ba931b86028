"""How an engine under certification is named, found and made: ``"module:factory"`` specs
(parsed and checked without importing anything, then called), and the name a report gives an
engine. Shared by every family's ``backend`` module and by :mod:`peclet_verify.fixtures`.
"""
from __future__ import annotations

import importlib
import importlib.util

from peclet.core.validation import PecletArgumentError

__all__ = ["backend_name", "parse_backend_spec", "check_factory_spec", "check_module_found",
           "call_factory", "load_factory"]


def backend_name(backend) -> str:
    """The engine's ``name`` attribute, else its class name (what reports show)."""
    return getattr(backend, "name", type(backend).__name__)


def parse_backend_spec(spec):
    """``(module, factory)`` of a ``"module:factory"`` spec, or None for the reference engine
    (``None``, ``""`` or ``"reference"``); :class:`PecletArgumentError` for anything else.
    Cheap: nothing is imported."""
    if spec is None or spec in ("", "reference"):
        return None
    accepted = "'module:factory' (dotted module, Python name) or 'reference'"
    if not isinstance(spec, str) or spec.count(":") != 1:
        raise PecletArgumentError("backend", accepted, spec)
    mod_name, attr = spec.split(":")
    if not all(part.isidentifier() for part in mod_name.split(".")) or not attr.isidentifier():
        raise PecletArgumentError("backend", accepted, spec)
    return mod_name, attr


def check_factory_spec(spec, option):
    """``(module, factory)`` of a ``module:factory`` spec given to ``option``, or None for
    ``"reference"`` / empty; :class:`PecletArgumentError` naming ``option`` otherwise.
    Cheap: nothing is imported."""
    try:
        return parse_backend_spec(spec)
    except PecletArgumentError:
        raise PecletArgumentError(option, "'module:factory' (dotted module, Python name) or "
                                  "'reference'", spec) from None


def check_module_found(option, spec, module):
    """Raise ``ValueError`` (one line naming ``option`` and ``spec``) unless ``module`` can be
    found; nothing is imported."""
    try:
        found = importlib.util.find_spec(module)
    except (ImportError, ValueError) as exc:
        found, why = None, f"{type(exc).__name__}: {exc}"
    else:
        why = "no such module"
    if found is None:
        raise ValueError(f"{option} {spec!r}: cannot import module {module!r} ({why})")


def call_factory(spec, parsed, label):
    """What the factory of ``spec`` (``parsed``: its ``(module, factory)``) returns. Every
    failure (a module that does not import, no such factory, a factory that raises) is a
    ``ValueError`` starting ``"{label} {spec!r}: "``."""
    mod_name, attr = parsed
    try:
        mod = importlib.import_module(mod_name)
    except ImportError as exc:
        raise ValueError(f"{label} {spec!r}: cannot import module {mod_name!r}: {exc}") \
            from exc
    factory = getattr(mod, attr, None)
    if not callable(factory):
        raise ValueError(f"{label} {spec!r}: {mod_name} has no callable {attr!r}")
    try:
        return factory()
    except Exception as exc:  # a broken factory is a usage error for the one who named it
        raise ValueError(f"{label} {spec!r}: {attr}() raised {type(exc).__name__}: {exc}") \
            from exc


def load_factory(spec, option, default, check):
    """The backend ``factory()`` of ``spec`` returns, checked with ``check(backend)`` (which
    raises ``ValueError`` for an object that is no such backend); ``default()`` for
    ``"reference"``. Every failure is a ``ValueError`` naming ``option`` and the spec."""
    parsed = check_factory_spec(spec, option)
    if parsed is None:
        return default()
    backend = call_factory(spec, parsed, option)
    try:
        return check(backend)
    except ValueError as exc:
        raise ValueError(f"{option} {spec!r}: {exc}") from None
