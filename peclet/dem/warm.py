"""Compiling the DEM step's kernels ahead, beside other work (a cold first run's longest wait).

On a cold Numba cache the first ``Simulation.step`` compiles the broad phase, the narrow phase,
the solvers and the rotation (about a minute on one core). A run that first measures its
element by quadrature (itself a long compilation) can have the step's kernels compiled at the
same time in a child process on the other core: :func:`start_background` starts
``compile_step_kernels`` in a child when the kernels are not cached, :func:`finish` waits for
it before the first step, which then loads them from the cache. The child writes only Numba's
cache (the same entries the run would write itself); if it fails, the run compiles as before.
Kernel signatures do not depend on values, so a tiny simulation of the same kinds of objects
(a composed shape, a sphere, a wall, periodic axes) compiles exactly what a page run needs.
"""
from __future__ import annotations

import subprocess
import sys

import numpy as np

__all__ = ["compile_step_kernels", "start_background", "finish"]


def compile_step_kernels():
    """Step a tiny simulation (a composed box, a sphere, a floor wall, periodic x and z) so
    that every kernel of the impulse step is compiled into Numba's cache."""
    from peclet.core.geom import SceneBuilder
    from peclet.dem import Simulation

    b = SceneBuilder()
    box = b.add_leaf("box", [0.3, 0.2, 0.25])
    ni, nr, _, _ = b.encode()
    rng = np.random.default_rng(0)
    p = rng.normal(size=(200, 3))
    p = p / np.abs(p).max(axis=1)[:, None] * [0.3, 0.2, 0.25]
    f = SceneBuilder()
    floor = f.add_leaf("box", [5.0, 1.0, 5.0], translation=[0.0, -1.0, 0.0])
    fi, fr, _, _ = f.encode()
    sim = Simulation(4)
    sim.set_domain([-2.0, -1.0, -2.0], [2.0, 4.0, 2.0])
    sim.enable_periodicity(True, False, True)
    sim.set_gravity(0.0, -9.81, 0.0)
    sim.add_scene_shape(ni, nr, box, p, 0.45)
    sim.add_sphere_shape(0.2)
    sim.add_analytic_wall(fi, fr, floor, False, 0.2, 0.5)
    sim.set_positions(np.array([[0.0, 0.21, 0.0], [0.1, 0.7, 0.0], [0.9, 0.2, 0.3],
                                [-0.9, 0.6, 0.4]]))
    sim.set_shape_ids(np.array([0, 0, 1, 1]))
    for _ in range(3):
        sim.step(1e-3)


def start_background():
    """A child process compiling the step's kernels, or None when they are cached already (or
    the cache cannot be read)."""
    from peclet.dem.simulation import step_kernels_cached

    if step_kernels_cached() is not False:
        return None
    code = "from peclet.dem.warm import compile_step_kernels; compile_step_kernels()"
    return subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)


def finish(child):
    """Wait for :func:`start_background`'s child (None: nothing to wait for). Returns True if
    it compiled, False if it failed (the run then compiles the kernels itself)."""
    if child is None:
        return True
    return child.wait() == 0
