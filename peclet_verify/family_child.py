"""Parent side of the DEM and mass-property families out of process, and the loader of
``module:factory`` specs for their options.

:class:`FamilyChild` is a :class:`peclet_verify.backends.ChildProcess` (as is
:class:`~peclet_verify.backends.SubprocessBackend`) for the families of
:mod:`peclet_verify.family_wire`: a child process (any interpreter or virtual environment with
numpy; it loads ``family_wire.py`` and ``wire.py`` by file path) answers
framed numpy messages on its pipes; every answer is awaited at most ``timeout`` seconds (the
start-up included), after which the child is killed and the call raises ``TimeoutError``
naming the backend.
"""
from __future__ import annotations

import json
import os

from peclet.core.validation import PecletArgumentError

from .backends import ChildProcess, _call_factory, parse_backend_spec

__all__ = ["FamilyChild", "load_factory", "check_factory_spec"]


class FamilyChild(ChildProcess):
    """One child process serving :func:`peclet_verify.family_wire.serve`.

    ``cmd`` a non-empty list of program arguments; ``env`` (added to this process's
    environment), ``cwd``, ``timeout`` (seconds per answer, default
    :data:`~peclet_verify.backends.DEFAULT_TIMEOUT`).
    ``methods`` and ``declared`` hold what the child serves and declares.
    """

    def __init__(self, cmd, name=None, env=None, cwd=None, timeout=None):
        super().__init__(cmd, name=name, env=env, cwd=cwd, timeout=timeout)
        out = self.call("methods")
        self.methods = set(str(m) for m in out[0].reshape(-1) if str(m))
        self.declared = json.loads(str(out[1]))

    def _child_env(self, env):
        return dict(os.environ, **(env or {}))


def check_factory_spec(spec, option):
    """``(module, factory)`` of a ``module:factory`` spec given to ``option``, or None for
    ``"reference"`` / empty; :class:`PecletArgumentError` naming ``option`` otherwise.
    Cheap: nothing is imported."""
    try:
        return parse_backend_spec(spec)
    except PecletArgumentError:
        raise PecletArgumentError(option, "'module:factory' (dotted module, Python name) or "
                                  "'reference'", spec) from None


def load_factory(spec, option, default, check):
    """The backend ``factory()`` of ``spec`` returns, checked with ``check(backend)`` (which
    raises ``ValueError`` for an object that is no such backend); ``default()`` for
    ``"reference"``. Every failure is a ``ValueError`` naming ``option`` and the spec."""
    parsed = check_factory_spec(spec, option)
    if parsed is None:
        return default()
    backend = _call_factory(spec, parsed, option)
    try:
        return check(backend)
    except ValueError as exc:
        raise ValueError(f"{option} {spec!r}: {exc}") from None
