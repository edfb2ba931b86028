"""Benchmark of peclet.dem on the page's Pall-ring pour.

Run:  python benchmarks/bench_dem.py [--quick]

Measures ms per step of (1) the page's pour (48 rings, ~1200 probes each, iterations (10, 8),
dt 2e-3) at 1 and 2 threads, timed on the settled bed after the page's 1400-step pour phase
(the expensive regime: every ring touching several others), and (2) a 1000-ring pour in a box
of the same column density, timed once its lower layers have reached the floor. Reports the
share of each phase (broad phase, narrow phase, solver = velocity solve + integration +
projection). Writes benchmarks/results/dem.json and prints a table.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time

import numba
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))

from test_dem_composed import page_pour, pall_ring_particle  # noqa: E402

from peclet.dem import Simulation  # noqa: E402

PAGE_ENGINE_MS = 421.0     # the page's engine, one-way detection, this 2-core machine (issue 4)


def timed(sim, steps, threads, dt=2e-3):
    numba.set_num_threads(threads)
    sim.step(dt)                                    # warm (JIT, caches)
    for k in sim.timings:
        sim.timings[k] = 0.0
    contacts = []
    t0 = time.perf_counter()
    for _ in range(steps):
        sim.step(dt)
        contacts.append(sim.num_contacts())
    wall = time.perf_counter() - t0
    ph = {k: 1e3 * v / steps for k, v in sim.timings.items()}
    return {"threads": threads, "steps": steps, "ms_per_step": 1e3 * wall / steps,
            "broad_ms": ph["broad"], "narrow_ms": ph["narrow"], "solver_ms": ph["solver"],
            "python_other_ms": 1e3 * wall / steps - ph["broad"] - ph["narrow"] - ph["solver"],
            "contacts_mean": float(np.mean(contacts))}


def big_pour(sp, n=1000, L=16.0):
    """The page's construction scaled to n rings at the page's column density."""
    rng = np.random.default_rng(5)
    pos, y = [], 1.2
    while len(pos) < n:
        c = np.array([rng.uniform(0, L), y, rng.uniform(0, L)])
        if all(np.linalg.norm((c - q)[[0, 2]]) > 1.55 or abs(c[1] - q[1]) > 1.55
               for q in pos[-60:]):
            pos.append(c)
        else:
            y += 0.15
    quat = rng.normal(size=(n, 4))
    quat /= np.linalg.norm(quat, axis=1)[:, None]
    sim = page_pour(sp, n=2)                        # same configuration, then resized
    sim.set_domain((0.0, -1.2, 0.0), (L, 400.0, L))
    sim.set_positions(np.asarray(pos))
    sim.set_shape_ids(np.zeros(n, np.int64))
    sim.set_quaternions(quat)
    sim.set_inv_mass(np.full(n, 1.0 / sp.mass))
    sim.set_inv_inertia(np.tile(sp.inv_inertia_unit, (n, 1)))
    return sim


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="fewer steps (smoke run)")
    args = ap.parse_args()
    pour_steps = 300 if args.quick else 1400
    n_timed = 20 if args.quick else 100
    sp = pall_ring_particle()
    rows = []

    sim = page_pour(sp)
    numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
    t0 = time.perf_counter()
    for _ in range(pour_steps):
        sim.step(2e-3)
    pour_s = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "bed.npz")
        sim.save(path)
        for threads in (1, 2):
            r = timed(Simulation.load(path), n_timed, threads)
            r.update(case="page pour, 48 rings (settled bed)", probes=len(sp.shell))
            rows.append(r)

    big = big_pour(sp)
    numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
    warm = 150 if args.quick else 600
    for _ in range(warm):
        big.step(2e-3)
    r = timed(big, 5 if args.quick else 20, min(2, numba.config.NUMBA_NUM_THREADS))
    r.update(case=f"1000-ring pour (steps {warm}+, lower layers landed)",
             probes=len(sp.shell))
    rows.append(r)

    print(f"\npeclet.dem benchmark  ({platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} cores, numba {numba.__version__}, "
          f"threading layer {numba.threading_layer()})")
    print(f"48-ring pour phase: {pour_steps} steps in {pour_s:.1f} s")
    hdr = (f"{'case':52s} {'thr':>3s} {'ms/step':>8s} {'broad':>7s} {'narrow':>7s} "
           f"{'solver':>7s} {'other':>7s} {'contacts':>8s}")
    print(hdr)
    print("-" * len(hdr))
    for r in rows:
        tot = r["ms_per_step"]
        print(f"{r['case']:52s} {r['threads']:3d} {tot:8.2f} "
              f"{100 * r['broad_ms'] / tot:6.1f}% {100 * r['narrow_ms'] / tot:6.1f}% "
              f"{100 * r['solver_ms'] / tot:6.1f}% {100 * r['python_other_ms'] / tot:6.1f}% "
              f"{r['contacts_mean']:8.0f}")
    print(f"\nthe page's engine: {PAGE_ENGINE_MS:.0f} ms/step (one-way detection). Targets: "
          f"<= 20 ms/step (48 rings, 2 threads, two-way), <= 400 ms/step (1000 rings).")
    print("""
Where the time goes. The narrow phase is the cost: for every candidate pair it maps each
ring's ~1200 probes into the other ring's frame, BOTH ways, and evaluates the 21-node tree at
those near contact. What keeps it bounded: a distance grid baked per shape at registration
gives a certified lower bound of phi for one array read (phi is 1-Lipschitz), tested at the
body, at super-clusters and clusters of probes (bounding spheres) and at each probe, so only
probes within the margin of the other surface (plus one grid cell) reach the exact tree; the
hits are identical to evaluating every probe. The manifold reduction keeps <= 16 points per
pair, so the serial PGS sweeps few contacts. The broad phase (cell list) and the solver are
small; "other" is the Python glue of the step (array bookkeeping, the warm-start match). On this
shared 2-core machine a parallel launch costs milliseconds when other jobs hold the cores, so the
2-thread figure can be no better than the 1-thread one; the results are bitwise identical.""")
    os.makedirs(os.path.join(HERE, "results"), exist_ok=True)
    out = os.path.join(HERE, "results", "dem.json")
    fd, tmp = tempfile.mkstemp(dir=os.path.dirname(out), suffix=".json")
    with os.fdopen(fd, "w") as f:
        json.dump({"rows": rows, "pour_steps": pour_steps, "pour_seconds": pour_s,
                   "page_engine_ms_per_step": PAGE_ENGINE_MS,
                   "numba": numba.__version__, "cores": os.cpu_count()}, f, indent=2)
    os.replace(tmp, out)
    print(f"\nwrote {out}")


if __name__ == "__main__":
    main()
