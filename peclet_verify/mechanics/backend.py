"""The engine the mechanics family certifies: a DEM engine, under the DEM family's protocol
(:class:`peclet_verify.dem.backend.DemBackend`, reached the same way: ``--peclet-dem-backend``,
the ``pytest_peclet_make_dem_backend`` hook, else peclet.dem). A mechanics case is a
:class:`~peclet_verify.scenario.Scenario` the engine runs; its trajectory is judged against a
closed form. The names below are the DEM family's, published here so that every family's
``backend`` module offers the same three functions (:class:`peclet_verify.registry.Family`).
"""
from ..dem.backend import DemBackend, PecletDemBackend, check_backend, default_backend, load_backend

__all__ = ["DemBackend", "PecletDemBackend", "check_backend", "default_backend", "load_backend"]
