"""peclet.dem: rigid-body DEM of composed analytic particles.

``Simulation`` is the engine, a facade over named parts: ``bodies`` (per-particle state),
``shapes`` (shapes, walls and the flat ``Geometry`` the kernels read), ``domain``, ``contacts``
(detection and the warm-start cache; kernels in ``broadphase``/``narrowphase``, with
``distgrid`` bounds, ``reuse`` of probe lists between steps and the ``manifold`` reduction),
``materials``,
``solver``, ``rigid`` (the rotor step), ``guards`` and ``persistence`` (save/load).
``scene_particle`` turns a CSG tree into a registered particle (mass properties, principal
frame, shell probes). Both load lazily so that importing one layer
never drags in the other's compilation.
"""
import importlib

__all__ = ["Simulation", "scene_particle", "rigid"]


def __getattr__(name):
    if name == "Simulation":
        return importlib.import_module(".simulation", __name__).Simulation
    if name in ("scene_particle", "rigid"):
        return importlib.import_module("." + name, __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
