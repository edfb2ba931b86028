"""Rings at column scale, end to end: the page's Pall ring rained into a column, analysed and
exported, with the wall time of every part and ms/step on the settled bed at 1 and 2 threads.

    python benchmarks/bench_column.py [--count 1000] [--n 10] [--steps 40] [--out DIR]

Defaults: 1000 rings, column N = 10 (D_t = 10 D), mu = mu_wall = 0.5, e_n = 0.15 (the page's
material), rain of up to 10 rings every 10 steps, inserted 10 D above the bed at 10 D/time
(the insertion band clears faster: at 2 D/time it limited the rate, 6926 steps in all), settle
budget 1000 steps.
Writes benchmarks/results/column.json and prints a table. The issue's target: the whole chain
in at most 10 minutes on the 2-core machine.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

import numba

from peclet.core.files import write_json
from peclet.packing import Material, RainProtocol, pack
from peclet.packing.bed import api
from peclet.packing.output import report as bed_report

HERE = os.path.dirname(os.path.abspath(__file__))

RAIN = RainProtocol(batch=10, insert_every=10, drop=10.0, speed=10.0, settle_steps=1000)


def settled_ms_per_step(sim, threads, steps):
    """ms per step of ``steps`` further steps of the settled bed at ``threads`` threads."""
    numba.set_num_threads(threads)
    sim.step()                         # warm (a thread-count change may launch new workers)
    t = time.perf_counter()
    for _ in range(steps):
        sim.step()
    return 1e3 * (time.perf_counter() - t) / steps


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--count", type=int, default=1000)
    ap.add_argument("--n", type=float, default=10.0)
    ap.add_argument("--steps", type=int, default=40, help="steps timed on the settled bed")
    ap.add_argument("--out", default=None, help="keep the bed's files here (default: a temp "
                    "directory)")
    ap.add_argument("--json", default=os.path.join(HERE, "results", "column.json"))
    a = ap.parse_args(argv)
    cap = int(numba.config.NUMBA_NUM_THREADS)
    T0 = time.perf_counter()
    times = {}
    t = time.perf_counter()
    api.element_model(api.resolve_element("pall_ring"))
    times["build"] = time.perf_counter() - t
    t = time.perf_counter()
    res = pack("pall_ring", f"column:{a.n:g}", count=a.count, protocol=RAIN,
               material=Material(0.15, 0.0, 0.5), seed=1, threads=cap, progress=True)
    times["pack"] = time.perf_counter() - t
    with tempfile.TemporaryDirectory() as tmp:
        out = a.out or tmp
        os.makedirs(out, exist_ok=True)
        t = time.perf_counter()
        rep = bed_report.analyse(res, out, figures=True, exports=True)
        times["analyse_figures_export"] = time.perf_counter() - t
        sizes = {os.path.basename(p): os.path.getsize(p) for p in rep.get("files", {}).values()}
    times["total"] = time.perf_counter() - T0
    ms = {f"threads_{k}": settled_ms_per_step(res.sim, k, a.steps) for k in (1, 2) if k <= cap}
    doc = dict(count=a.count, column_n=a.n, protocol=RAIN.to_spec(), steps=res.steps,
               complete=res.complete, pack_ms_per_step=1e3 * res.seconds / max(res.steps, 1),
               seconds=times, settled_ms_per_step=ms,
               ms_per_ring_step={k: v / a.count for k, v in ms.items()},
               bulk_eps=rep["bulk"]["eps"], bulk_eps_se=rep["bulk"]["eps_se"],
               f_env=rep["bulk"]["f_env"], radial_features=rep["radial"]["features"],
               coordination=rep["coordination"], analysis_timing=rep["timing"],
               file_bytes=sizes, state_sha256=res.state_hash())
    write_json(a.json, doc)
    rows = [("rings, column", f"{a.count}, N = {a.n:g}"),
            ("element build (quadrature + shell)", f"{times['build']:.1f} s"),
            ("pack (rain + settle)", f"{times['pack']:.1f} s, {res.steps} steps "
                                     f"({doc['pack_ms_per_step']:.1f} ms/step)"),
            ("analysis + figures + exports", f"{times['analyse_figures_export']:.1f} s"),
            ("end to end", f"{times['total']:.1f} s (target <= 600 s)"),
            ("bulk eps, f_env", f"{doc['bulk_eps']:.4f} +- {doc['bulk_eps_se']:.4f}, "
                                f"{doc['f_env']:.4f}")]
    rows += [(f"settled bed, {k.replace('_', ' ')}", f"{v:.1f} ms/step "
              f"({v / a.count:.4f} ms per ring-step)") for k, v in ms.items()]
    w0 = max(len(r[0]) for r in rows)
    print("\n".join(f"{x:<{w0}}  {y}" for x, y in rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
