"""Compiling the step ahead (peclet.dem.warm): the tail child's stand-in detection must give every
kernel it reaches the signature a real step gives it, or the run would compile those kernels
again after waiting for the children (a cold first run's time, not its bits)."""
import numpy as np
import pytest
from numba.core.registry import CPUDispatcher

from peclet.dem import warm
from peclet.dem import broadphase, contacts, guards, hertz, narrowphase, rigid, solver
from peclet.dem import solver_colored, solver_position, solver_rows, solver_velocity


def _dispatchers():
    mods = (broadphase, contacts, guards, hertz, narrowphase, rigid, solver, solver_colored,
            solver_position, solver_rows, solver_velocity)
    return {f"{m.__name__}.{k}": v for m in mods for k, v in vars(m).items()
            if isinstance(v, CPUDispatcher)}


def test_the_tail_compile_adds_no_signature_a_real_step_does_not_have():
    warm.compile_step_kernels("all")                 # real detection: the real signatures
    before = {k: set(d.signatures) for k, d in _dispatchers().items()}
    sim = warm.compile_step_kernels("tail")
    assert sim.world.num_contacts == 2                    # the solvers saw the stand-in contacts
    after = {k: set(d.signatures) for k, d in _dispatchers().items()}
    new = {k: after[k] - before.get(k, set()) for k in after if after[k] - before.get(k, set())}
    assert not new, f"the stand-in detection compiled signatures a real step does not use: {new}"


@pytest.mark.heavy
def test_the_hertz_compile_adds_no_signature_a_real_hertz_step_does_not_have():
    # the same two pairs touching under the real detection: box 1 resting on box 0, the
    # sphere on the floor
    sim = warm._tiny_simulation()
    sim.set_positions(np.array([[0.0, 0.2, 0.0], [0.0, 0.599, 0.0], [0.9, 0.199, 0.3],
                                [-0.9, 0.6, 0.4]]))
    sim.set_hertz_material(0, 1e7, 0.3)
    sim.set_rolling_friction(0.05)
    sim.step_hertz(3, 1e-5)
    real = sim.hertz_contacts()
    pairs = set(zip(real["body_a"].tolist(), real["body_b"].tolist()))
    assert (2, -1) in pairs and {(0, 1), (1, 0)} & pairs
    before = {k: set(d.signatures) for k, d in _dispatchers().items()}
    warm.compile_step_kernels("hertz")
    after = {k: set(d.signatures) for k, d in _dispatchers().items()}
    new = {k: after[k] - before.get(k, set()) for k in after if after[k] - before.get(k, set())}
    assert not new, f"the stand-in detection compiled Hertz signatures a real step does not use: {new}"


@pytest.mark.heavy
def test_the_colored_compile_solves_colour_by_colour_and_restores_the_threshold():
    threshold = solver.COLORED_MIN_CONTACTS
    sim = warm.compile_step_kernels("colored")
    assert sim.world.num_contacts >= 1
    assert solver.solve_velocities_colored.signatures       # the coloured path ran
    assert solver.COLORED_MIN_CONTACTS == threshold == 20000


def test_the_stand_in_contacts_are_laid_out_as_gather_lays_them_out():
    c = warm.stand_in_contacts()
    for name in c._fields:
        arr = getattr(c, name)
        assert arr.flags.c_contiguous, name
        assert arr.dtype == (np.int64 if name in ("a", "b", "feat") else np.float64), name
    assert c.shift.shape == c.point.shape == c.normal.shape == (2, 3)


@pytest.mark.heavy
def test_peclet_warm_compiles_every_part_and_says_so():
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-m", "peclet.cli", "warm"], capture_output=True,
                          text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "Hertz substep and coloured solve" in done.stdout
    assert "cached now: True" in done.stdout
    # on disk (the index jitcache.is_cached reads; not this process's own compilations)
    for kernel in (hertz.forces_loops.serial, hertz.rolling_loops.serial,
                   solver.solve_velocities_colored):
        assert len(kernel._cache._cache_file._load_index()) > 0, kernel


def test_an_unknown_part_is_refused():
    with pytest.raises(ValueError, match="part must be one of"):
        warm.compile_step_kernels("narrow")


def test_the_tail_child_compiles_the_broad_phase_and_no_composed_shape_kernels():
    # what a cold first run's children split between them: the detection child bakes the
    # composed shape (lattice, pruning) on its way to the narrow phase; the tail child must
    # not compile those kernels a second time, and compiles the broad phase first, for the
    # detection child to load. A fresh process: its dispatchers list what it compiled or loaded.
    import subprocess
    import sys

    code = ("from peclet.dem.warm import compile_step_kernels; compile_step_kernels('tail'); "
            "from peclet.core.geom import kernels, pruning; from peclet.dem import broadphase; "
            "print(len(kernels.bake_lattice.signatures), len(pruning._bake.signatures), "
            "len(broadphase.find_pairs.signatures), len(broadphase.task_list.signatures))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    bake, prune, pairs, tasks = map(int, done.stdout.split())
    assert (bake, prune) == (0, 0)
    assert pairs == 1 and tasks == 1
