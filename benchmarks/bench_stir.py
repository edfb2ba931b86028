"""The stirred column at the page's size: Lacey curve, escapes, wall distance, ms/step.

1. The whole run (``peclet stir``'s protocol: the page's fill, 22,121 grains of radius 0.4,
   settle 2 time units, 5 impeller revolutions at omega 1.5) at the machine's threads: the
   Lacey index by revolution, grains escaped (must be 0), the minimum wall distance of a grain
   centre (must be > 0), the peak grain speed over the tip speed.
2. ms/step at 1 and 2 threads over the same ``--window`` stirring steps, started from the same
   saved state (the run's state after its first stirring revolution's first 100 steps), with
   the two end states' hashes (they must be equal).

Targets (issue 22): <= 10 ms/step at 2 threads; upstream's page: 3.7 ms/step on 8 threads.

Run:  python benchmarks/bench_stir.py [--grain-radius 0.4] [--revolutions 5] [--window 200]
Writes benchmarks/results/stir.json and prints a table.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time

import numba

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _report  # noqa: E402

from peclet.dem import Simulation  # noqa: E402
from peclet.packing.experiments.stir import StirSpec, StirredColumn, run_stir  # noqa: E402

TARGET_MS_2_THREADS = 10.0
UPSTREAM_MS_8_THREADS = 3.7


def timed_window(path, steps, threads):
    """(ms/step, end state hash, {phase: ms/step}) of ``steps`` steps from the saved state at
    ``path``; the phases are :attr:`Simulation.timings`' (broad and narrow phase, the solver
    with everything after detection)."""
    numba.set_num_threads(threads)
    sim = Simulation.load(path)
    sim.step()                                   # compiled already; the first step also warms
    before = dict(sim.timings)
    t0 = time.perf_counter()
    for _ in range(steps - 1):
        sim.step()
    ms = 1e3 * (time.perf_counter() - t0) / (steps - 1)
    phases = {k: 1e3 * (sim.timings[k] - before[k]) / (steps - 1) for k in ("broad", "narrow",
                                                                             "solver")}
    return ms, sim.state_hash(), phases


def window_timing(spec, window, cap):
    """{threads: (ms/step, hash)} over ``window`` stirring steps at 1 and 2 threads, from one
    saved state: a fresh column, settled and stirred for 100 steps."""
    col = StirredColumn(spec)
    sim = col.build()
    for _ in range(int(math.ceil(spec.settle / spec.dt))):
        sim.step()
    col.turn(spec.omega)
    for _ in range(100):
        sim.step()
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "window.npz")
        sim.save(path)
        timing = {t: timed_window(path, window, t) for t in sorted({1, min(2, cap)})}
    numba.set_num_threads(cap)
    return timing


def _timing_rows(timing, window):
    # one row per thread count: ms/step and its broad / narrow / solver split
    return [(f"ms/step, {t} thread(s), {window} steps",
             f"{ms:.1f} (broad {ph['broad']:.1f}, narrow {ph['narrow']:.1f}, "
             f"solver {ph['solver']:.1f})") for t, (ms, _, ph) in timing.items()]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grain-radius", type=float, default=0.4)
    ap.add_argument("--revolutions", type=float, default=5.0)
    ap.add_argument("--window", type=int, default=200)
    ap.add_argument("--window-only", action="store_true",
                    help="only the timing window (on a quiet machine), written into the "
                         "existing results of the whole run")
    a = ap.parse_args(argv)
    cap = int(numba.config.NUMBA_NUM_THREADS)
    spec = StirSpec(grain_radius=a.grain_radius, revolutions=a.revolutions, frames=0).checked()
    if a.window_only:
        timing = window_timing(spec, a.window, cap)
        payload = _report.read("stir")
        payload.update(ms_per_step={str(t): ms for t, (ms, _, _) in timing.items()},
                       phase_ms_per_step={str(t): ph for t, (_, _, ph) in timing.items()},
                       window_steps=a.window,
                       same_bits_1_vs_2=len({h for _, h, _ in timing.values()}) == 1)
        _report.write("stir", payload)
        print(_report.table(_timing_rows(timing, a.window)
                            + [("same bits at 1 and 2 threads", payload["same_bits_1_vs_2"])],
                            ["stirred column, timing window", "value"]))
        return
    res = run_stir(spec, out=None, progress=True, figures=False)
    timing = window_timing(spec, a.window, cap)
    s = res["samples"]
    curve = [dict(revolution=r, lacey=min(s, key=lambda x: abs(x["revolutions"] - r))["lacey"])
             for r in range(int(spec.revolutions) + 1)]
    hashes = {t: h for t, (_, h, _) in timing.items()}
    payload = dict(grains=res["grains"], revolutions=spec.revolutions, steps=res["steps"],
                   run_seconds=res["seconds"], run_ms_per_step=res["ms_per_step"],
                   lacey=curve, escaped_max=res["escaped_max"],
                   min_wall_sdf=res["min_wall_sdf"], min_clearance=res["min_clearance"],
                   peak_speed_over_tip=res["peak_speed_over_tip"],
                   ms_per_step={str(t): ms for t, (ms, _, _) in timing.items()},
                   phase_ms_per_step={str(t): ph for t, (_, _, ph) in timing.items()},
                   window_steps=a.window, same_bits_1_vs_2=len(set(hashes.values())) == 1,
                   target_ms_2_threads=TARGET_MS_2_THREADS,
                   upstream_ms_8_threads=UPSTREAM_MS_8_THREADS)
    _report.write("stir", payload)
    rows = [("grains", res["grains"]),
            ("Lacey by revolution", ", ".join(f"{c['revolution']}: {c['lacey']:.3f}"
                                               for c in curve)),
            ("escaped (max)", res["escaped_max"]),
            ("min wall distance of a centre", f"{res['min_wall_sdf']:.4f}"),
            ("min clearance", f"{res['min_clearance']:.4f}"),
            ("peak speed / tip speed", f"{res['peak_speed_over_tip']:.3f}"),
            ("whole run", f"{res['seconds']:.0f} s, {res['ms_per_step']:.1f} ms/step")]
    rows += _timing_rows(timing, a.window)
    rows += [("same bits at 1 and 2 threads", payload["same_bits_1_vs_2"]),
             ("target at 2 threads / upstream at 8", f"{TARGET_MS_2_THREADS} / "
              f"{UPSTREAM_MS_8_THREADS} ms/step")]
    print(_report.table(rows, ["stirred column", "value"]))


if __name__ == "__main__":
    main()
