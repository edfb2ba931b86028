"""Compiling the DEM step's kernels ahead, beside other work (a cold first run's longest wait).

On a cold Numba cache the first ``Simulation.step`` compiles the broad phase, the narrow phase,
the solvers and the rotation (about a minute of one core). A run that first measures its element
by quadrature (itself a long compilation) can have the step's kernels compiled at the same time
in child processes: :func:`start_background` starts two children when the kernels are not
cached, one compiling the detection (the composed shape's lattice and pruning, then the narrow
phase, most of the time) and one the rest of the step (the broad phase first, then velocity and
position solves, rotation, guards, by stepping spheres with a stand-in detection), so that both
groups compile at once instead of one after the other, and no kernel in both. :func:`finish`
waits for them before the first step, which then loads every kernel from the cache. The
children write only Numba's cache (the same entries the run would write itself); if one fails,
the run compiles what is missing as before. Kernel signatures do not depend on values, so a tiny
simulation of the same kinds of objects (a composed shape, a sphere, a wall, periodic axes)
compiles exactly what a page run needs (``tests/test_dem_warm.py`` checks that the stand-in
detection gives each kernel the signature the real one does).
"""
from __future__ import annotations

import subprocess
import sys

import numpy as np

__all__ = ["compile_step_kernels", "start_background", "running", "finish", "stop", "PARTS"]

#: what a child compiles: "all" (a whole step: detection first, then the rest, which it loads
#: from the cache when the "tail" child has written it by then) or "tail" (the step after
#: detection, stepped with a stand-in detection). ``peclet warm`` also compiles what a page run
#: does not reach: "hertz" (Hertz–Mindlin substeps with rolling resistance, after the stand-in
#: detection) and "colored" (whole steps with the colour-by-colour solve of large contact sets
#: forced on the tiny simulation's few contacts; it reaches the detection, so run it after "all")
PARTS = ("all", "tail", "hertz", "colored")


def _tiny_simulation(composed=True):
    # a composed box, a sphere, a floor wall, periodic x and z: every kind a page run steps.
    # composed=False: a second sphere in the box's place, for the tail child, whose kernels
    # see arrays whose types do not depend on the shapes' kinds; it then does not compile the
    # composed shape's lattice and pruning kernels, which the detection child compiles at
    # the same moment (13 s of one core, twice, on a cold cache)
    from peclet.core.geom import SceneBuilder
    from peclet.dem import Simulation

    f = SceneBuilder()
    floor = f.add_leaf("box", [5.0, 1.0, 5.0], translation=[0.0, -1.0, 0.0])
    fi, fr, _, _ = f.encode()
    sim = Simulation(4)
    sim.set_domain([-2.0, -1.0, -2.0], [2.0, 4.0, 2.0])
    sim.enable_periodicity(True, False, True)
    sim.set_gravity(0.0, -9.81, 0.0)
    if composed:
        b = SceneBuilder()
        box = b.add_leaf("box", [0.3, 0.2, 0.25])
        ni, nr, _, _ = b.encode()
        p = np.random.default_rng(0).normal(size=(200, 3))
        p = p / np.abs(p).max(axis=1)[:, None] * [0.3, 0.2, 0.25]
        sim.add_scene_shape(ni, nr, box, p, 0.45)
    else:
        sim.add_sphere_shape(0.45)
    sim.add_sphere_shape(0.2)
    sim.add_analytic_wall(fi, fr, floor, False, 0.2, 0.5)
    sim.set_positions(np.array([[0.0, 0.21, 0.0], [0.1, 0.7, 0.0], [0.9, 0.2, 0.3],
                                [-0.9, 0.6, 0.4]]))
    sim.set_shape_ids(np.array([0, 0, 1, 1]))
    return sim


def _stand_in_detection(sim):
    """A detection for ``sim.world.detect`` that runs the real broad phase on the arguments the
    step passes (so with its signatures) and returns :func:`stand_in_contacts`. The tail child
    steps with it: the broad phase compiles there first, and the detection child, which
    reaches it only after compiling the composed shape's kernels, loads it from the cache and
    goes on to the narrow phase, the longest compilation."""
    def detect(pos, rot, margin, reach=None, wall_reach=None, frozen=None, wall_static=None):
        sim.world.detector.candidates(sim.world.geometry(), sim.world.shape_table()[1], pos, margin,
                                 sim.world.domain, reach, wall_reach, frozen, wall_static)
        return stand_in_contacts()
    return detect


def stand_in_contacts():
    """Two contacts laid out as ``narrowphase.gather`` lays them out (the same dtypes, shapes
    and contiguity): body 2 on the floor wall and body 1 on body 0. What the tail compile
    steps with instead of a detection."""
    from peclet.dem.contacts import Contacts

    return Contacts(a=np.array([2, 1], np.int64), b=np.array([-1, 0], np.int64),
                    shift=np.zeros((2, 3)),
                    point=np.array([[0.9, 0.0, 0.3], [0.05, 0.45, 0.0]]),
                    normal=np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 0.0]]),
                    gap=np.array([0.0, 0.01]), feat=np.zeros(2, np.int64))


def compile_step_kernels(part="all"):
    """Step a tiny simulation so that the kernels of the impulse step's ``part`` (one of
    :data:`PARTS`) are compiled into Numba's cache. Returns the simulation stepped."""
    if part not in PARTS:
        raise ValueError(f"part must be one of {PARTS}, got {part!r}")
    from peclet.dem import solver

    sim = _tiny_simulation(composed=part != "tail")
    if part == "tail":
        sim.world.detect = _stand_in_detection(sim)
    elif part == "hertz":
        sim.world.detect = lambda *args, **kwargs: stand_in_contacts()
    if part == "hertz":
        sim.set_hertz_material(0, 1e7, 0.3)
        sim.set_rolling_friction(0.05)
        sim.step_hertz(3, 1e-5)
        return sim
    threshold = solver.COLORED_MIN_CONTACTS
    if part == "colored":
        solver.COLORED_MIN_CONTACTS = 0         # a module setting, read at each step's solve
    try:
        for _ in range(3):
            sim.step(1e-3)
    finally:
        solver.COLORED_MIN_CONTACTS = threshold
    return sim


#: the children this process started (None: none yet, or they were collected)
_started = None


def start_background():
    """Children compiling the step's kernels (the detection in one, the rest in the other),
    or None when they are cached already (or the cache cannot be read). A second call while
    this process's children are still running returns the same children (a command can start
    them before its own checks, and the run it then calls finds them started)."""
    global _started
    if _started is not None and running(_started):
        return _started
    from peclet.dem.simulation import step_kernels_cached

    if step_kernels_cached() is not False:
        return None
    # the tail first: it is short, and it compiles the broad phase before the detection child
    # gets there (a lower priority for the tail child, tried, starved it: the detection
    # child then compiled the broad phase and the position solve itself)
    _started = [subprocess.Popen([sys.executable, "-c",
                                  "from peclet.dem.warm import compile_step_kernels; "
                                  f"compile_step_kernels({part!r})"],
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                for part in ("tail", "all")]
    return _started


def stop(children):
    """Kill :func:`start_background`'s children (a command that refuses its input does not
    leave them compiling); None: nothing to do."""
    for child in children or ():
        if child.poll() is None:
            child.kill()
        child.wait()


def running(children):
    """Whether any of :func:`start_background`'s children (None: none) is still compiling."""
    return children is not None and any(child.poll() is None for child in children)


def finish(children):
    """Wait for :func:`start_background`'s children (None: nothing to wait for). Returns True
    if they all compiled, False if one failed (the run then compiles what is missing itself)."""
    if children is None:
        return True
    return all([child.wait() == 0 for child in children])
