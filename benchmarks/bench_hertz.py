"""Benchmark of the Hertz–Mindlin engine beside the impulse engine on one ~20k-sphere bed.

Run:  python benchmarks/bench_hertz.py [--quick]

The bed: 27 x 27 x 27 = 19683 spheres (r 5 mm, rho 2500 kg/m^3, E 1e7 Pa, nu 0.3, e 0.5,
mu 0.5, walls e 0.5, mu 0.5) in a flat-bottomed box (a silo without its orifice: a floor and
four side walls), on a square lattice of pitch 1.998 r so that every sphere starts pressed
against its neighbours (~6 contacts each: the dense regime of a settled silo), then 200
Hertz substeps under gravity to let the lattice load. On that same state we time:

- Hertz: ``step_hertz(10, dt)`` (ten substeps per call: the candidate list is reused across
  them, skin 0.1 r) with dt = 0.2 x the Rayleigh time (the engine allows 0.3),
- impulse: ``step(dt)`` with dt = 1e-3 s and the default iterations (10, 8),

each at 1 and 2 Numba threads (``numba.set_num_threads``), the best of a few timed blocks.
Reported: ms per step, particle-steps per second (N x steps / wall second; per thread it is
the Cundall number), contacts, and simulated seconds per wall second (the engines' steps are
not the same length: the Hertz step is limited by the Rayleigh time).

Writes benchmarks/results/hertz.json and prints a table. Timings taken on a shared 2-core
machine are indicative only.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time

import numba
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import _report  # noqa: E402

from peclet.core import geom  # noqa: E402
from peclet.dem import Simulation, hertz  # noqa: E402

R, RHO, E, NU = 0.005, 2500.0, 1e7, 0.3


def _box(sim, half, centre):
    b = geom.SceneBuilder()
    root = b.add_leaf("box", list(half), translation=list(centre))
    ni, nr, _, _ = b.encode()
    sim.add_analytic_wall(ni, nr, root, False, 0.5, 0.5)


def bed(side):
    """The lattice bed in its box (side^3 spheres)."""
    pitch = 1.998 * R
    g = np.stack(np.meshgrid(*(np.arange(side),) * 3, indexing="ij"), -1).reshape(-1, 3)
    pos = (g * pitch + R).astype(np.float64)
    n = len(pos)
    sim = Simulation(n)
    sim.add_sphere_shape(R)
    sim.set_positions(pos)
    sim.set_shape_ids(np.zeros(n, np.int64))
    sim.set_inv_mass(np.full(n, 1.0 / (RHO * 4.0 / 3.0 * math.pi * R ** 3)))
    sim.set_gravity(0.0, -9.81, 0.0)
    sim.set_material_params(0.5, 0.0, 0.5)
    sim.set_hertz_material(0, E, NU)
    w = side * pitch                                 # inner width of the box
    t = 0.05
    _box(sim, (w + 2 * t, t, w + 2 * t), (w / 2, -t, w / 2))                 # floor
    _box(sim, (t, 4 * w, w + 2 * t), (-t, 2 * w, w / 2))                     # x walls
    _box(sim, (t, 4 * w, w + 2 * t), (w + t, 2 * w, w / 2))
    _box(sim, (w + 2 * t, 4 * w, t), (w / 2, 2 * w, -t))                     # z walls
    _box(sim, (w + 2 * t, 4 * w, t), (w / 2, 2 * w, w + t))
    sim.set_domain([-0.2, -0.2, -0.2], [w + 0.2, 5 * w, w + 0.2])
    return sim


def hertz_dt():
    g = E / (2 * (1 + NU))
    tr = math.pi * R * math.sqrt(RHO / g) / (0.1631 * NU + 0.8766)
    return 0.2 * tr


def timed(run, calls, per_call, threads, repeats):
    """Seconds per step: the best of ``repeats`` blocks of ``calls`` calls of ``run``, each
    advancing ``per_call`` steps."""
    numba.set_num_threads(threads)
    run()                                            # warm: compilation, caches
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(calls):
            run()
        best = min(best, time.perf_counter() - t0)
    return best / (calls * per_call)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a 12^3 bed, fewer steps")
    a = ap.parse_args(argv)
    side = 12 if a.quick else 27
    steps, repeats = (10, 2) if a.quick else (20, 3)
    threads = [1] + ([2] if numba.config.NUMBA_NUM_THREADS >= 2 else [])
    dt_h, dt_i = hertz_dt(), 1e-3
    sim = bed(side)
    n = sim.num_particles()
    numba.set_num_threads(max(threads))
    print(f"{n} spheres; loading the bed with 200 Hertz substeps (dt {dt_h:.3g} s)...",
          file=sys.stderr)
    sim.step_hertz(200, dt_h)
    state = os.path.join(_report.RESULTS, "_hertz_bed.npz")
    sim.save(state)
    rows, out = [], []
    for engine, dt in (("hertz", dt_h), ("impulse", dt_i)):
        for th in threads:
            s = Simulation.load(state)                        # the same bed every time
            per_call = 10 if engine == "hertz" else 1
            run = (lambda s=s: s.step_hertz(per_call, dt)) if engine == "hertz" \
                else (lambda s=s: s.step(dt))
            sec = timed(run, max(1, steps // per_call) if engine == "hertz" else steps,
                        per_call, th, repeats)
            rec = {"engine": engine, "threads": th, "dt": dt, "ms_per_step": 1e3 * sec,
                   "particle_steps_per_s": n / sec, "cundall_per_thread": n / sec / th,
                   "contacts": s.num_contacts(), "sim_s_per_wall_s": dt / sec}
            out.append(rec)
            rows.append([engine, th, f"{dt:.3g}", f"{1e3 * sec:.1f}", f"{n / sec:.3g}",
                         f"{n / sec / th:.3g}", rec["contacts"], f"{dt / sec:.3g}"])
    os.remove(state)
    print(_report.table(rows, ["engine", "threads", "dt (s)", "ms/step", "particle-steps/s",
                               "per thread", "contacts", "sim s / wall s"]))
    print("(a shared 2-core machine: indicative timings only)")
    path = _report.write("hertz", {"n_spheres": n, "radius": R, "youngs": E, "poisson": NU,
                                   "density": RHO, "rayleigh_fraction_used": 0.2,
                                   "rayleigh_fraction_limit": hertz.RAYLEIGH_FRACTION,
                                   "steps": steps, "repeats": repeats, "results": out,
                                   "note": "shared machine, indicative"})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
