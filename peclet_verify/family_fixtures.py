"""Session fixtures and option checks of the DEM and mass-property families (registered by
:mod:`peclet_verify.plugin`). Importing this module imports pytest and the standard library
only.

``peclet_dem_backend``: ``--peclet-dem-backend module:factory`` if given, else what a
``pytest_peclet_make_dem_backend(config)`` hook returns, else peclet's own DEM engine.
``peclet_mass_backend``: the same with ``--peclet-mass-backend`` and
``pytest_peclet_make_mass_backend``. A backend that cannot be made stops the session with one
line naming the option or the hook.
"""
from __future__ import annotations

import importlib.util

import pytest

FAMILY_OPTIONS = ("--peclet-dem-backend", "--peclet-mass-backend")


def check_family_options(config):
    """Raise ``ValueError`` (one line naming the option) for a malformed spec or a module
    that cannot be found; nothing is imported."""
    for opt in FAMILY_OPTIONS:
        spec = config.getoption(opt)
        if spec is None:
            continue
        from peclet.core.validation import PecletArgumentError
        from .family_child import check_factory_spec
        try:
            parsed = check_factory_spec(spec, opt)
        except PecletArgumentError as exc:
            raise ValueError(str(exc)) from None
        if parsed is not None:
            check_module_found(opt, spec, parsed[0])


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


def _make(config, option, hook_name, load, default, check):
    spec = config.getoption(option)
    if spec:
        try:
            return load(spec)
        except ValueError as exc:
            pytest.exit(str(exc).splitlines()[0], returncode=4)
    try:
        backend = getattr(config.hook, hook_name)(config=config)
        return default() if backend is None else check(backend)
    except Exception as exc:  # whatever a downstream hook raises
        pytest.exit(f"{hook_name}: {type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}",
                    returncode=4)


def _session_backend(config, family, load, default, check):
    """The ``family`` ("dem", "mass") backend :func:`_make` makes from its option or hook,
    closed (if it has ``close``) when the session ends."""
    backend = _make(config, f"--peclet-{family}-backend", f"pytest_peclet_make_{family}_backend",
                    load, default, check)
    yield backend
    close = getattr(backend, "close", None)
    if callable(close):
        close()


@pytest.fixture(scope="session")
def peclet_dem_backend(pytestconfig):
    """The DEM engine under certification (see the module docstring)."""
    from . import dem_backends as D
    yield from _session_backend(pytestconfig, "dem", D.load_dem_backend, D.PecletDemBackend,
                                D.check_dem_backend)


@pytest.fixture(scope="session")
def peclet_mass_backend(pytestconfig):
    """The mass-property engine under certification (see the module docstring)."""
    from . import mass_backends as M
    yield from _session_backend(pytestconfig, "mass", M.load_mass_backend, M.PecletMassBackend,
                                M.check_mass_backend)


def backend_label(config, option, hook_name):
    """What a report should say certified: the option's spec, the hook, or the reference."""
    spec = config.getoption(option)
    if spec:
        return spec
    return f"{hook_name} hook" if getattr(config.hook, hook_name).get_hookimpls() \
        else "reference"
