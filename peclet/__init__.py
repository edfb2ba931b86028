"""peclet: a reference engine for composed analytic particles.

Layers (dependencies point downward only):

- :mod:`peclet.packing` — packing elements, the pour protocol, pack analysis, figures, CLI
- :mod:`peclet.dem` — rigid-body DEM of composed particles (``Simulation``, ``scene_particle``)
- :mod:`peclet.core.geom` — CSG trees, certificate, evaluation, scene query, quadrature
"""
__version__ = "0.1.0"
