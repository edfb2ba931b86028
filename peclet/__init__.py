"""peclet: a reference engine for composed analytic particles.

Layers (dependencies point downward only):

- :mod:`peclet.packing` — packing elements, the pour protocol, pack analysis, figures, CLI
- :mod:`peclet.dem` — rigid-body DEM of composed particles (``Simulation``, ``scene_particle``)
- :mod:`peclet.core.geom` — CSG trees, certificate, evaluation, scene query, quadrature
"""
__version__ = "0.1.0"

# before any kernel loads from Numba's cache: drop compiled kernels whose callees' sources
# changed since (Numba would keep running the old callees; see peclet.core.jitcache)
from peclet.core.jitcache import purge_stale as _purge_stale  # noqa: E402

_purge_stale()
