"""Our page pour against the Bullet anchor, back to back in one invocation (issue 17).

Run:  python benchmarks/bench_vs_bullet.py [--quick] [--big] [--bullet-python PATH]

1. The page's 48-ring pour (its protocol: pour 1400 steps, 2 taps of +0.8 D/time x 400 steps,
   relax 600, quench 900 with velocities x0.96; dt 2e-3, mu 0.5, e 0.15) with peclet at ONE
   thread: set-up seconds (ring registration: probes, clusters, distance grid) and ms/step over
   the whole protocol, max overlap / wall thickness at the end.
2. Right after, the same protocol with Bullet (../shared/anchors/pall_ring_bullet.py, V-HACD
   hulls, one thread) in its own venv; skipped with a message when that interpreter or
   pybullet is missing (make it with ``python -m venv /tmp/bullet-venv &&
   /tmp/bullet-venv/bin/pip install pybullet numpy scipy scikit-image trimesh``).
   Prints the ratio Bullet ms/step / ours (> 1: we are faster).
3. A 300-ring bed in a 10 D periodic box (the page's construction), poured 1000 steps, then
   timed from the same saved state at 1 and at 2 threads; the two final states must be
   bitwise identical (checked, reported).
4. With --big: 1000 rings in a 9.7 D periodic box (the page's construction), the whole page
   protocol at 2 threads (pour, taps, relax, quench: a settled bed), then timed from that saved
   state at 1 and 2 threads, beside Bullet's 201 ms/step over the last 500 steps of the same
   protocol for 1000 rings in a 9.7 D walled box (issue 17); then again with sleeping on
   (``SLEEP``, after SLEEP_WARM steps that let the bed fall asleep).

Writes benchmarks/results/vs_bullet.json and prints a table. --quick: 1/10 of the protocol
and shorter timings (a smoke run; its ratios are not the figures to quote).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time

import numba
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))
sys.path.insert(0, HERE)

from test_dem_composed import page_pour, pall_ring_particle  # noqa: E402

from peclet.core.files import atomic_write  # noqa: E402
from peclet.dem import Simulation  # noqa: E402
from peclet.packing.bed.protocols import PageProtocol  # noqa: E402

ANCHOR = os.path.normpath(os.path.join(HERE, "..", "..", "shared", "anchors",
                                       "pall_ring_bullet.py"))
BULLET_PY = "/tmp/bullet-venv/bin/python"
BULLET_1000_MS = 201.0      # issue 17: Bullet's 1000-ring pour, last 500 steps
WALL = 0.12                 # the ring's wall thickness (D)


def run_protocol(sim, proto):
    """The page protocol on ``sim``; returns the number of steps."""
    kicks = {proto.pour_steps + k * proto.tap_steps for k in range(proto.taps)}
    quench0 = proto.pour_steps + proto.taps * proto.tap_steps + proto.relax_steps
    n = proto.total_steps
    for s in range(n):
        if s in kicks:
            v = np.array(sim.get_velocities(), dtype=np.float64)
            v[:, 1] += proto.tap_speed
            sim.set_velocities(v)
        sim.step(proto.dt)
        if s >= quench0:
            sim.set_velocities(np.asarray(sim.get_velocities()) * proto.damp)
            sim.set_angular_velocities(np.asarray(sim.get_angular_velocities()) * proto.damp)
    return n


def ours_page(proto):
    numba.set_num_threads(1)
    t0 = time.perf_counter()
    sp = pall_ring_particle()           # quadrature, reframing, shell probes (not cached yet)
    sim = page_pour(sp)
    sim.step(proto.dt)                  # registration and the first step (JIT warm)
    setup = time.perf_counter() - t0
    sim = page_pour(sp)                 # a fresh bed: the timed run is the whole protocol
    t0 = time.perf_counter()
    n = run_protocol(sim, proto)
    wall = time.perf_counter() - t0
    return dict(engine="peclet (exact tree, two-way probes, 1 thread)", steps=n,
                ms_per_step=1e3 * wall / n, t_setup_s=setup,
                narrow_ms=1e3 * sim.timings["narrow"] / n,
                max_overlap_over_wall=float(sim.compute_overlaps()) / WALL)


def bullet_page(python, quick):
    if not os.path.exists(python):
        return None, f"Bullet skipped: no interpreter {python} (see the docstring)"
    if not os.path.exists(ANCHOR):
        return None, f"Bullet skipped: anchor {ANCHOR} not found"
    with tempfile.TemporaryDirectory() as d:
        cmd = [python, ANCHOR, "--workdir", d, "--no-measure"] + (["--quick"] if quick else [])
        r = subprocess.run(cmd, capture_output=True, text=True)
    lines = [ln for ln in r.stdout.splitlines() if ln.startswith("JSON ")]
    if r.returncode != 0 or not lines:
        tail = (r.stderr.strip().splitlines() or ["(no output)"])[-1]
        return None, f"Bullet skipped: the anchor failed ({tail})"
    return json.loads(lines[-1][5:]), ""


#: Sleeping for the settled bed's second timing: surface speed below 0.05 D/time for 25 steps
#: (Bullet deactivates bodies at rest by default too); 60 steps to let the bed fall asleep.
SLEEP = (0.05, 25)
SLEEP_WARM = 60


def timed(path, steps, threads, dt=2e-3, sleep=None):
    numba.set_num_threads(threads)
    sim = Simulation.load(path)
    sim.step(dt)                        # warm (JIT, caches)
    if sleep is not None:
        sim.set_sleeping(*sleep)
        for _ in range(SLEEP_WARM):
            sim.step(dt)
    for k in sim.timings:
        sim.timings[k] = 0.0
    t0 = time.perf_counter()
    for _ in range(steps):
        sim.step(dt)
    wall = time.perf_counter() - t0
    return dict(threads=threads, steps=steps, ms_per_step=1e3 * wall / steps,
                narrow_ms=1e3 * sim.timings["narrow"] / steps, contacts=sim.num_contacts(),
                asleep=float(sim.get_sleeping().mean()), sha256=sim.state_hash())


def bed_1_vs_2(sim, warm, steps, sleeping=False):
    """Run ``warm`` (a number of pour steps, or a protocol), then time ``steps`` from the same
    saved state at 1 and 2 threads (and, with ``sleeping``, again with :data:`SLEEP` on)."""
    numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
    if isinstance(warm, PageProtocol):
        warm = run_protocol(sim, warm)
    else:
        for _ in range(warm):
            sim.step(2e-3)
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "bed.npz")
        sim.save(path)
        r1 = timed(path, steps, 1)
        r2 = timed(path, steps, 2)
        out = dict(warm_steps=warm, one=r1, two=r2,
                   speedup=r1["ms_per_step"] / r2["ms_per_step"],
                   bitwise_identical=r1["sha256"] == r2["sha256"])
        if sleeping:
            s1 = timed(path, steps, 1, sleep=SLEEP)
            s2 = timed(path, steps, 2, sleep=SLEEP)
            out["sleeping"] = dict(speed=SLEEP[0], still_steps=SLEEP[1], one=s1, two=s2,
                                   bitwise_identical=s1["sha256"] == s2["sha256"])
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="1/10 of the protocol (smoke run)")
    ap.add_argument("--big", action="store_true", help="also the 1000-ring bed")
    ap.add_argument("--bullet-python", default=BULLET_PY)
    args = ap.parse_args()
    proto = PageProtocol().scaled(0.1) if args.quick else PageProtocol()
    res = dict(quick=args.quick, numba=numba.__version__, cores=os.cpu_count(),
               machine=platform.processor() or platform.machine())

    res["ours_page"] = ours_page(proto)         # first: its set-up includes the ring's build
    sp = pall_ring_particle()
    bullet, msg = bullet_page(args.bullet_python, args.quick)
    res["bullet_page"] = bullet
    if bullet is None:
        print(msg)
    else:
        res["bullet_over_ours"] = bullet["ms_per_step"] / res["ours_page"]["ms_per_step"]

    res["bed300"] = bed_1_vs_2(page_pour(sp, n=300, L=10.0), 100 if args.quick else 1000,
                               10 if args.quick else 60)
    if args.big:
        res["bed1000"] = bed_1_vs_2(page_pour(sp, n=1000, L=9.7, capacity=1008), proto,
                                    5 if args.quick else 100, sleeping=True)

    o = res["ours_page"]
    print(f"\npeclet vs Bullet ({res['machine']}, {res['cores']} cores, numba {numba.__version__})"
          f"{'  [--quick: smoke run]' if args.quick else ''}")
    print(f"{'page pour, 48 rings':34s} {'ms/step':>8s} {'set-up s':>9s}")
    print(f"{'  peclet, 1 thread':34s} {o['ms_per_step']:8.2f} {o['t_setup_s']:9.1f}"
          f"   (narrow {o['narrow_ms']:.2f} ms, max overlap {100 * o['max_overlap_over_wall']:.2f}"
          f"% of the wall)")
    if bullet is not None:
        print(f"{'  Bullet, V-HACD, 1 thread':34s} {bullet['ms_per_step']:8.2f} "
              f"{bullet.get('t_setup_s', float('nan')):9.1f}   ({bullet.get('n_hulls')} hulls)")
        print(f"  Bullet ms/step / ours = {res['bullet_over_ours']:.2f}  (> 1: we are faster)")
    for key, label in (("bed300", "300 rings, 10 D periodic"),
                       ("bed1000", "1000 rings settled, 9.7 D")):
        if key in res:
            r = res[key]
            print(f"{label:34s} 1 thread {r['one']['ms_per_step']:8.2f} ms/step, 2 threads "
                  f"{r['two']['ms_per_step']:8.2f}: x{r['speedup']:.2f}; "
                  f"{r['one']['contacts']} contacts; bitwise identical: {r['bitwise_identical']}")
    if "bed1000" in res:
        r = res["bed1000"]
        print(f"  Bullet's 1000-ring pour, last 500 steps (issue 17): {BULLET_1000_MS:.0f} ms/step"
              f" = x{BULLET_1000_MS / r['one']['ms_per_step']:.1f} ours at 1 thread, "
              f"x{BULLET_1000_MS / r['two']['ms_per_step']:.1f} at 2")
        z = r["sleeping"]
        print(f"  with sleeping (speed {z['speed']}, {z['still_steps']} steps): "
              f"{z['one']['ms_per_step']:.2f} ms/step at 1 thread "
              f"(x{BULLET_1000_MS / z['one']['ms_per_step']:.1f} Bullet), "
              f"{z['two']['ms_per_step']:.2f} at 2; {100 * z['one']['asleep']:.0f} % asleep; "
              f"bitwise identical: {z['bitwise_identical']}")
    out = os.path.join(HERE, "results", "vs_bullet.json")

    def write(path):
        with open(path, "w") as f:
            json.dump(res, f, indent=2)
    atomic_write(out, write)
    print(f"\nwrote {out}")


if __name__ == "__main__":
    main()
