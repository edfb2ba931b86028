"""Per-block pruned CSG programs (peclet.core.geom.pruning) on the Pall ring, issue 17.

Run: python benchmarks/bench_pruning.py   (writes benchmarks/results/pruning.json; ~10 s)

The ring is the page's, in its home (principal) frame as the DEM registers it; the lattice is
peclet.dem.distgrid's (h = R / 32, R the bounding radius, origin -(32 + 2) h, 68 cells per
axis), cut into blocks of 1, 2 and 4 cells. For each: mean / max rows of the block programs
(the full program has 21), bytes, bake time, and ns per evaluation at points within 0.05 of the
surface (random order, 1 thread), full program vs lookup + pruned program, with a bitwise check.
"""
import sys
import time
from pathlib import Path

import numba
import numpy as np
from numba import njit

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from _report import best_of, table, write  # noqa: E402

from peclet.core.geom import kernels as K  # noqa: E402
from peclet.core.geom.program import compile_root  # noqa: E402
from peclet.core.geom.pruning import (bake_pruned, evaluate_full, evaluate_pruned,  # noqa: E402
                                      lookup_ranges, pruned_range)
from peclet.dem import distgrid  # noqa: E402

NEAR = 0.05
N_POINTS = 200_000


@njit(cache=True)
def _time_full(ops, lk, lr, b0, b1, pts):
    st = np.empty((K.MAX_STACK, K.STACK_COLS))
    acc = 0.0
    for i in range(pts.shape[0]):
        acc += K.eval_point(ops, lk, lr, b0, b1, pts[i, 0], pts[i, 1], pts[i, 2], st)[0]
    return acc


@njit(cache=True)
def _time_pruned(ops, lk, lr, block_range, ob, dims, f0, f1, pts):
    st = np.empty((K.MAX_STACK, K.STACK_COLS))
    acc = 0.0
    for i in range(pts.shape[0]):
        b0, b1 = pruned_range(block_range, 0, ob, dims, f0, f1, pts[i, 0], pts[i, 1], pts[i, 2])
        acc += K.eval_point(ops, lk, lr, b0, b1, pts[i, 0], pts[i, 1], pts[i, 2], st)[0]
    return acc


def _bits(a):
    return a.view(np.int64) if a.dtype == np.float64 else a


def ring_program():
    from test_dem_composed import pall_ring_particle
    sp = pall_ring_particle()
    return compile_root(sp.node_ints, sp.node_reals, sp.home_root), sp.bounding_radius


def near_surface_points(prog, radius, n, seed=0):
    g = np.random.default_rng(seed)
    out = []
    while sum(len(o) for o in out) < n:
        p = g.uniform(-radius, radius, (400_000, 3))
        phi = evaluate_full(prog, p)[0]
        out.append(p[np.abs(phi) < NEAR])
    return np.concatenate(out)[:n]


def main():
    numba.set_num_threads(1)
    prog, R = ring_program()
    h = R / distgrid.CELLS_PER_RADIUS
    cells = 2 * (distgrid.CELLS_PER_RADIUS + distgrid.PAD_CELLS)
    origin = np.full(3, -(distgrid.CELLS_PER_RADIUS + distgrid.PAD_CELLS) * h)
    pts = near_surface_points(prog, R, N_POINTS)
    ref = evaluate_full(prog, pts)
    bake_pruned(prog, origin, 4 * h, [cells // 4] * 3)          # compile
    f = best_of(lambda: _time_full(prog.ops, prog.leaf_kind, prog.leaf_reals, prog.op_begin,
                                   prog.op_end, pts))
    ns_full = f / len(pts) * 1e9
    rows, res = [], {"threads": 1, "radius": R, "h": h, "near": NEAR, "points": len(pts),
                     "full_rows": int(prog.op_end - prog.op_begin), "ns_full": ns_full,
                     "blocks": {}}
    rows.append(["full program", "-", "-", f"{prog.op_end - prog.op_begin}", "-", "-",
                 f"{ns_full:.1f}", "1.00", "-"])
    for c in (1, 2, 4):
        dims = [cells // c] * 3
        t0 = time.perf_counter()
        tab = bake_pruned(prog, origin, c * h, dims)
        t_bake = time.perf_counter() - t0
        t = best_of(lambda: _time_pruned(tab.ops, prog.leaf_kind, prog.leaf_reals,
                                         tab.block_range, tab.ob, tab.dims, tab.full_begin,
                                         tab.full_end, pts))
        ns = t / len(pts) * 1e9
        got = evaluate_pruned(tab, prog, pts)
        same = all(np.array_equal(_bits(a), _bits(b)) for a, b in zip(ref, got))
        used = tab.block_rows()
        near = lookup_ranges(tab, pts)
        rng = near[:, 1] - near[:, 0]
        res["blocks"][str(c)] = dict(block=c * h, dims=dims, mean_rows=float(used.mean()),
                                     max_rows=int(used.max()),
                                     mean_rows_near_surface=float(rng.mean()),
                                     ops_rows=len(tab.ops), bytes=tab.nbytes, bake_s=t_bake,
                                     ns_pruned=ns, speedup=ns_full / ns, bitwise_equal=same)
        rows.append([f"{c} cell(s) = {c * h:.4f}", f"{dims[0]}^3", f"{used.mean():.2f}",
                     f"{used.max()} (near {rng.mean():.2f})", f"{tab.nbytes / 1024:.0f} KiB",
                     f"{t_bake * 1e3:.0f} ms", f"{ns:.1f}", f"{ns_full / ns:.2f}",
                     "yes" if same else "NO"])
    print(f"Pall ring (home frame), R = {R:.4f}, h = R/32 = {h:.5f}, {len(pts)} points with "
          f"|phi| < {NEAR}, 1 thread")
    print(table(rows, ["block", "blocks", "mean rows", "max rows", "memory", "bake",
                       "ns/eval", "speed-up", "bitwise"]))
    print("written:", write("pruning", res))


if __name__ == "__main__":
    main()
