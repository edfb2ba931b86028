"""First-run honesty (issue 26, item 5): a line saying the kernels compile, a progress bar whose
rate and time left exclude the first step, and rates in the results that leave it out."""
import io
import os
import subprocess
import sys
import time

import pytest

from peclet.packing.bed.progress import Progress


def test_a_slow_first_step_neither_inflates_the_eta_nor_the_rate():
    s = io.StringIO()
    bar = Progress(200, "pack ", stream=s, log_interval=0.0,
                   note="compiling the DEM kernels (first run only)")
    time.sleep(1.0)                         # the first step: compilation on a cold cache
    bar.update(1, "pour")
    for _ in range(20):
        time.sleep(0.002)
        bar.update(1, "pour")
    fd = bar._bar.format_dict
    bar.close()
    text = s.getvalue()
    assert text.splitlines()[0] == "compiling the DEM kernels (first run only)"
    assert bar.first_seconds >= 1.0
    assert fd["elapsed"] < 0.5              # the clock restarted after the first step
    assert fd["n"] - fd["initial"] == 20    # rate counts the steps since then
    # the time left is that of ~180 fast steps, not 180 x 1 s
    rate = (fd["n"] - fd["initial"]) / fd["elapsed"]
    assert (200 - fd["n"]) / rate < 20.0


def test_no_note_and_no_output_when_disabled():
    s = io.StringIO()
    bar = Progress(5, "x", stream=s, enabled=False, note="compiling")
    bar.update(5)
    bar.close()
    assert s.getvalue() == "" and bar.first_seconds is not None


def test_resumed_bar_starts_at_its_step():
    s = io.StringIO()
    bar = Progress(100, "x", stream=s, log_interval=0.0, initial=40)
    bar.update(1)
    bar.close()
    assert bar.done == 41 and "41/100" in s.getvalue()


def test_cold_cache_is_detected_in_a_fresh_cache_dir(tmp_path):
    """With an empty NUMBA_CACHE_DIR the step's kernels are not cached: the note is printed."""
    code = ("from peclet.packing.bed.progress import compile_note\n"
            "from peclet.dem.simulation import step_kernels_cached\n"
            "print(step_kernels_cached()); print(compile_note() is not None)\n")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         timeout=300, check=True).stdout.split()
    assert out == ["False", "True"]


def test_warm_process_needs_no_note():
    import numpy as np

    from peclet.dem import Simulation
    from peclet.dem.simulation import step_kernels_cached
    from peclet.packing.bed.progress import compile_note

    sim = Simulation(2)
    sid = sim.add_sphere_shape(0.5)
    sim.set_positions(np.array([[0.0, 1.0, 0.0], [0.0, 2.2, 0.0]]))
    sim.set_shape_ids(np.full(2, sid, np.int32))
    sim.set_inv_mass(np.ones(2))
    sim.set_inv_inertia(np.ones((2, 3)))
    sim.set_gravity(0.0, -9.81, 0.0)
    sim.step(1e-3)                           # compiled (or loaded) in this process now
    assert step_kernels_cached() is True and compile_note() is None


@pytest.mark.parametrize("kw,name", [(dict(total=10, initial=-1), "initial"),
                                     (dict(total=10, initial=11), "initial")])
def test_bad_initial_is_named(kw, name):
    from peclet.core.validation import PecletArgumentError

    with pytest.raises(PecletArgumentError, match=f"^{name} must"):
        Progress(**kw)


def test_ms_per_step_leaves_out_the_first_step():
    from peclet.packing.bed.progress import ms_per_step

    assert ms_per_step(90.0, 85.0, 1001) == pytest.approx(5.0)     # 5 s over 1000 steps
    assert ms_per_step(2.0, 2.0, 1) == pytest.approx(2000.0)       # one step: its own time
    assert ms_per_step(0.0, 0.0, 0) == 0.0
