"""The cost of a grid leaf against the analytic tree it samples: the page's Pall ring (issue 41).

Run: python benchmarks/bench_grid_leaf.py [--spacing 0.02]   (writes results/grid_leaf.json)

The ring of the page (analytic CSG, 13 leaves) and the same ring as one grid leaf sampled from
it (``grids.grid_from_callable`` at ``spacing`` D, default 0.02: 6 cells across its 0.12 D
wall) are evaluated at the same 1,000,000 points of the ring's box, value and gradient, at 1
and 2 threads (best of 5). Reported: microseconds per probe (one phi + gradient evaluation:
what the narrow phase pays per contact probe), the ratio grid / analytic, the grid's samples
and memory, and how far apart the two fields are on the points within 0.05 D of the surface.
Timings are only comparable within one run on a quiet machine.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numba
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from _report import best_of, table, write  # noqa: E402


def main(argv=None):
    from peclet.core.geom import grids
    from peclet.packing.bed.elements import pall_ring
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--spacing", type=float, default=0.02)
    ap.add_argument("--points", type=int, default=1_000_000)
    a = ap.parse_args(argv)
    el = pall_ring()
    b, ring = el.builder, el.root
    lo, hi = (np.asarray(v, float) for v in el.bounds)
    grid = grids.grid_from_callable(b, lambda p: b.eval_root(ring, p), lo, hi, a.spacing)
    dims = b.node(grid)[3][1:4].astype(int)
    pts = np.random.default_rng(0).uniform(lo, hi, (a.points, 3))
    for r in (ring, grid):
        b.eval_root_grad(r, pts[:100])                       # compile / load
    res = {"spacing_D": a.spacing, "samples": int(np.prod(dims)),
           "grid_MiB": float(np.prod(dims)) * 8 / 2 ** 20, "points": a.points}
    rows = []
    for t in [t for t in (1, 2) if t <= numba.config.NUMBA_NUM_THREADS]:
        numba.set_num_threads(t)
        ta = best_of(lambda: b.eval_root_grad(ring, pts))
        tg = best_of(lambda: b.eval_root_grad(grid, pts))
        res[f"analytic_us_per_probe_{t}t"] = ta / a.points * 1e6
        res[f"grid_us_per_probe_{t}t"] = tg / a.points * 1e6
        res[f"grid_over_analytic_{t}t"] = tg / ta
        rows.append([f"{t}", f"{ta / a.points * 1e6:.4f}", f"{tg / a.points * 1e6:.4f}",
                     f"{tg / ta:.2f}"])
    fa = b.eval_root(ring, pts)
    fg = b.eval_root(grid, pts)
    near = np.abs(fa) < 0.05
    res["max_abs_difference_near_surface_D"] = float(np.abs(fg - fa)[near].max())
    res["sign_disagreement_near_surface"] = float(np.mean((fa < 0) != (fg < 0)))
    print(table(rows, ["threads", "analytic us/probe", "grid us/probe", "grid / analytic"]))
    print(f"grid: {dims.tolist()} samples ({res['grid_MiB']:.1f} MiB) at h = {a.spacing} D; "
          f"|phi_grid - phi_ring| <= {res['max_abs_difference_near_surface_D']:.2e} D within "
          f"0.05 D of the surface ({res['sign_disagreement_near_surface']:.2%} of those points "
          "differ in sign)")
    write("grid_leaf", res)
    return res


if __name__ == "__main__":
    main()
