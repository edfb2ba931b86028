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
        if parsed is None:
            continue
        try:
            found = importlib.util.find_spec(parsed[0])
        except (ImportError, ValueError) as exc:
            found, why = None, f"{type(exc).__name__}: {exc}"
        else:
            why = "no such module"
        if found is None:
            raise ValueError(f"{opt} {spec!r}: cannot import module {parsed[0]!r} ({why})")


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


def _closing(backend):
    close = getattr(backend, "close", None)
    if callable(close):
        close()


@pytest.fixture(scope="session")
def peclet_dem_backend(pytestconfig):
    """The DEM engine under certification (see the module docstring)."""
    from .dem_backends import PecletDemBackend, check_dem_backend, load_dem_backend
    backend = _make(pytestconfig, "--peclet-dem-backend", "pytest_peclet_make_dem_backend",
                    load_dem_backend, PecletDemBackend, check_dem_backend)
    yield backend
    _closing(backend)


@pytest.fixture(scope="session")
def peclet_mass_backend(pytestconfig):
    """The mass-property engine under certification (see the module docstring)."""
    from .mass_backends import PecletMassBackend, check_mass_backend, load_mass_backend
    backend = _make(pytestconfig, "--peclet-mass-backend", "pytest_peclet_make_mass_backend",
                    load_mass_backend, PecletMassBackend, check_mass_backend)
    yield backend
    _closing(backend)


def backend_label(config, option, hook_name):
    """What a report should say certified: the option's spec, the hook, or the reference."""
    spec = config.getoption(option)
    if spec:
        return spec
    return f"{hook_name} hook" if getattr(config.hook, hook_name).get_hookimpls() \
        else "reference"
