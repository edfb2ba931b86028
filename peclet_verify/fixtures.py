"""The session fixtures of the engines under certification, one per family record of
:mod:`peclet_verify.registry` (registered by :mod:`peclet_verify.plugin`), and the check of the
families' options. Importing this module imports pytest and the standard library only.

Each fixture (``peclet_backend``, ``peclet_mass_backend``, ``peclet_dem_backend``) gives the
engine its family's option names (``module:factory``), else what the family's hook in a
``conftest.py`` returns, else peclet's own engine. A backend that cannot be made stops the
session with one line naming the option or the hook. An engine running in this process gets a
deadline on every call (:class:`peclet_verify.processes.DeadlineBackend`, ``--peclet-deadline``
seconds); the engine is closed (if it has ``close``) when the session ends.
"""
from __future__ import annotations

import importlib
import math

import pytest

from . import registry as REG

__all__ = ["ENGINES", "DEADLINE_OPTION", "check_backend_options", "deadline", "make_backend",
           "backend_label", "session_fixture"]

#: One family per engine fixture (families sharing an engine share its option, hook, fixture).
ENGINES = tuple({f.fixture: f for f in reversed(REG.FAMILIES)}[name]
                for name in dict.fromkeys(f.fixture for f in REG.FAMILIES))
#: The option that sets the deadline of each call of an in-process engine.
DEADLINE_OPTION = "--peclet-deadline"


def check_backend_options(config):
    """Raise ``ValueError`` (one line naming the option) for a malformed spec, a module that
    cannot be found, or a deadline that is not a number of seconds > 0; nothing is imported
    but peclet's argument check."""
    from peclet.core.validation import PecletArgumentError

    from .loading import check_factory_spec, check_module_found
    for fam in ENGINES:
        spec = config.getoption(fam.option)
        if spec is None:
            continue
        try:
            parsed = check_factory_spec(spec, fam.option)
        except PecletArgumentError as exc:
            raise ValueError(str(exc)) from None
        if parsed is not None:
            check_module_found(fam.option, spec, parsed[0])
    deadline(config)


def deadline(config) -> float:
    """Seconds each call of an in-process engine may take: ``--peclet-deadline``, else
    :data:`peclet_verify.processes.DEFAULT_DEADLINE`; ``ValueError`` naming the option for
    anything but a finite number > 0."""
    given = config.getoption(DEADLINE_OPTION)
    if given is None:
        from .processes import DEFAULT_DEADLINE
        return DEFAULT_DEADLINE
    try:
        seconds = float(given)
    except ValueError:
        seconds = math.nan
    if not (math.isfinite(seconds) and seconds > 0):
        raise ValueError(f"{DEADLINE_OPTION} {given}: not a number of seconds > 0")
    return seconds


def make_backend(config, fam: REG.Family):
    """The engine of family ``fam``: from its option, its hook, or its default; behind a
    deadline when it runs in this process. Stops the session (``pytest.exit``, one line naming
    the option or the hook) when it cannot be made."""
    from .processes import with_deadline
    module = importlib.import_module(fam.backend)
    spec = config.getoption(fam.option)
    if spec:
        try:
            backend = module.load_backend(spec, fam.option)
        except ValueError as exc:
            pytest.exit(str(exc).splitlines()[0], returncode=4)
    else:
        try:
            backend = getattr(config.hook, fam.hook)(config=config)
            backend = module.default_backend() if backend is None else \
                module.check_backend(backend)
        except Exception as exc:  # whatever a downstream hook raises
            first = str(exc).splitlines()[0] if str(exc) else ""
            pytest.exit(f"{fam.hook}: {type(exc).__name__}: {first}", returncode=4)
    return with_deadline(backend, deadline(config), DEADLINE_OPTION,
                         factory=spec if spec and spec != "reference" else None)


def session_fixture(fam: REG.Family):
    """The session fixture named ``fam.fixture`` (see the module docstring)."""
    def engine(pytestconfig):
        backend = make_backend(pytestconfig, fam)
        yield backend
        close = getattr(backend, "close", None)
        if callable(close):
            close()
    engine.__name__ = fam.fixture
    engine.__doc__ = (f"The {fam.name} engine under certification: {fam.option}, else the "
                      f"{fam.hook} hook, else peclet's own ({fam.engine}).")
    return pytest.fixture(scope="session", name=fam.fixture)(engine)


def backend_label(config, fam: REG.Family) -> str:
    """What a report should say certified: the option's spec, the hook, or the reference."""
    spec = config.getoption(fam.option)
    if spec:
        return spec
    return f"{fam.hook} hook" if getattr(config.hook, fam.hook).get_hookimpls() \
        else "reference"
