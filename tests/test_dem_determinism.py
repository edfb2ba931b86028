"""The page's 48-ring pour is bitwise reproducible: at 1 and 2 threads, run twice, and across
a save at step 250, a load and a resume."""
import numba
import numpy as np

from peclet.dem import Simulation

from test_dem_composed import page_pour, pall_ring_particle

STEPS, SAVE_AT, DT = 500, 250, 2e-3


def _state(sim):
    return [sim.get_positions(), sim.get_quaternions(), sim.get_velocities(),
            sim.get_angular_velocities()]


def _run(threads, steps, sim=None):
    prev = numba.get_num_threads()
    numba.set_num_threads(threads)
    try:
        if sim is None:
            sim = page_pour(pall_ring_particle())
        for _ in range(steps):
            sim.step(DT)
    finally:
        numba.set_num_threads(prev)
    return sim


def test_48_ring_pour_is_bitwise_identical_across_threads_runs_and_resume(tmp_path):
    threads = min(2, numba.config.NUMBA_NUM_THREADS)
    ref = _run(1, STEPS)
    assert ref.num_contacts() > 0                   # the pour has reached the floor
    again = _run(1, STEPS)
    par = _run(threads, STEPS)
    half = _run(threads, SAVE_AT)
    path = tmp_path / "pour.npz"
    half.save(path)
    resumed = _run(1, STEPS - SAVE_AT, Simulation.load(path))
    for other in (again, par, resumed):
        for x, y in zip(_state(ref), _state(other)):
            assert x.dtype == np.float64
            assert np.array_equal(x, y)
    assert resumed.step_count == STEPS
    print(f"48 rings, {STEPS} steps: contacts at the end {ref.num_contacts()}, "
          f"threads compared 1 and {threads}")
