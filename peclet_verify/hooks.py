"""Hook specifications of the peclet pytest plugin (registered with ``pytest_addhooks``).

A downstream project certifies its own engine with one function in its ``conftest.py``::

    def pytest_peclet_make_backend(config):
        from my_engine import MyEngine
        return MyEngine()          # evaluate(node_ints, node_reals, root, points) -> phi

and one test module that imports the certificates: ``from peclet_verify.geometry.suite import *``.
"""
import pytest


@pytest.hookspec(firstresult=True)
def pytest_peclet_make_backend(config):
    """Return the engine under certification (an object with ``evaluate``, optionally
    ``evaluate_grad``, ``bound``, ``close`` and ``name``; see :mod:`peclet_verify.geometry.backend`),
    or None to leave the choice to another plugin. Called once per session (per xdist
    worker), only when a certificate needs the backend and ``--peclet-backend`` is not given
    (the command line wins)."""


@pytest.hookspec(firstresult=True)
def pytest_peclet_make_dem_backend(config):
    """Return the DEM engine under certification (an object with ``run(scenario, threads)``,
    optionally ``thread_counts``, ``thread_determinism``, ``close`` and ``name``; see
    :mod:`peclet_verify.dem.backend`), or None. Called once per session (per xdist worker),
    only when a DEM certificate needs it and ``--peclet-dem-backend`` is not given; without
    either, peclet's own engine is certified."""


@pytest.hookspec(firstresult=True)
def pytest_peclet_make_mass_backend(config):
    """Return the mass-property engine under certification (an object with
    ``mass_properties(node_ints, node_reals, root, lo, hi, resolution_or_tol)``,
    ``resolutions`` and ``order``; see :mod:`peclet_verify.mass.backend`), or None. Called
    once per session (per xdist worker) when ``--peclet-mass-backend`` is not given; without
    either, peclet's quadrature is certified."""


@pytest.hookspec(firstresult=True)
def pytest_peclet_make_impact_backend(config):
    """Return the impact engine under certification (an object with ``impact(case)``,
    ``model`` and ``capabilities``; see :mod:`peclet_verify.impact.backend`), or None. Called
    once per session (per xdist worker) when ``--peclet-impact-backend`` is not given; without
    either, peclet.dem's Hertz law is certified."""
