"""The octree refinement driver: top cells, passes of parallel cell integrations, splitting.

The box is split into n^3 top cells, each integrated once by :func:`integrate_cells` (parallel
over cells, each writing its own row). While the cells' error estimates, measured against the
solid's own scale, add up to more than ``tol``, the worst cells are split into 8 (down to
MAX_DEPTH levels) and their children integrated in the next pass. Rows are summed in a fixed
order, so the result is bitwise identical at any thread count.
"""
import math

import numpy as np
from numba import njit

from ...shares import run_shares
from .. import kernels as K
from .cell_rule import cell_bound, integrate_cell
from .constants import EPS, MAX_BREAKS, MAX_CELLS, MAX_DEPTH, ROUND_ULPS, SCRATCH_ROWS, SEEDS


def integrate_cells(ops, lk, lr, ob, oe, cells, lip, g5x, g5w, g7x, g7w, cen, kinv=1.0):
    """Integrate every cell of ``cells`` (N, 6: lo, hi) on its own; ``kinv`` is 1 / L, L the
    tree's Lipschitz constant (the line search proves on phi / L).

    Returns the raw moments (N, 10: 1, x, y, z, x^2, y^2, z^2, xy, xz, yz, relative to cen)
    by the 7-point rules, their error estimates (N, 10) and a code per cell: 0 integrated;
    1 the surface was found in the cell by projection but not by its rule (the estimate is
    then the bound of the whole cell: split it); -1 an overflow (too many breakpoints).

    A cell's estimate is |I7 - I5| per moment, plus ROUND_ULPS ulps of the cell's moment
    bound where the two rules differ at all (each root is exact only to a few ulps of its
    coordinates, so the estimate still bounds the error once the rule error is below
    round-off). Cells are independent and dealt to the threads one at a time as each becomes
    free (:func:`peclet.core.shares.run_shares`, ``dynamic``: a few cells of a pass can take
    hundreds of times the median, 0.8 s against 3 ms in the Pall ring of wall 0.16 D, and a
    fixed deal put them all in one share); the results do not depend on the thread count."""
    n = cells.shape[0]
    mom = np.zeros((n, 10))
    err = np.zeros((n, 10))
    code = np.zeros(n, dtype=np.int64)
    run_shares(_integrate_share, n, (ops, lk, lr, ob, oe, float(kinv)), (g5x, g5w, g7x, g7w),
               cells, lip, cen, mom, err, code, dynamic=True)
    return mom, err, code


@njit(cache=True, nogil=True)
def _integrate_share(first, step, P, G, cells, lip, cen, mom, err, code):
    """The cells ``first``, ``first + step``, ... of :func:`integrate_cells`, into their rows
    of ``mom``, ``err`` and ``code``: ``P`` the program tuple (ops, lk, lr, ob, oe), ``G`` the
    rules' nodes and weights on [0, 1] (g5x, g5w, g7x, g7w), the rest as there."""
    st = np.empty((K.MAX_STACK, K.STACK_COLS))
    S = np.empty((SCRATCH_ROWS, MAX_BREAKS))
    seeds = np.empty((MAX_BREAKS, SEEDS))
    nseed = np.empty(MAX_BREAKS, dtype=np.int64)
    a5 = np.empty(10)                            # zeroed by integrate_cell
    for c in range(first, cells.shape[0], step):
        nseed[:] = 0
        clo = cells[c, 0:3].copy()
        chi = cells[c, 3:6].copy()
        est = integrate_cell(P, clo, chi, lip, G, cen, st, S, seeds, nseed, a5, mom[c])
        if est < 0.0:
            code[c] = -1
        elif est == math.inf:
            code[c] = 1
            cell_bound(err[c], clo, chi, cen, 1.0)
        else:
            rounded = False
            for m in range(10):
                err[c, m] = abs(mom[c, m] - a5[m])
                rounded = rounded or mom[c, m] != a5[m]
            if rounded:
                cell_bound(err[c], clo, chi, cen, ROUND_ULPS * EPS)


def kernels_cached():
    """Whether the cell integration's kernel is in Numba's on-disk cache (or compiled in this
    process): True, False, or None when that cannot be told
    (:func:`peclet.core.jitcache.is_cached`). A process started while it is False compiles
    the whole chain again, about half a minute of one core."""
    from ...jitcache import is_cached

    return is_cached(_integrate_share)


def arrays_key(arrays):
    """A dict key made of the bytes of ``arrays`` (a program's, a box's)."""
    return tuple(np.ascontiguousarray(a).tobytes() for a in arrays)


def cached_cells(cache, P, cells, lip, cen):
    """:func:`integrate_cells` of ``cells`` through ``cache`` (a dict the caller keeps): rows of
    cells integrated before for the same program, ``lip`` and ``cen`` are copied from it, the
    others integrated in one call and stored. A cell's row depends on nothing else (cells are
    independent), so the result is bitwise what :func:`integrate_cells` gives; the tolerance
    levels of one solid in one box share most of their cells (the top cells at least)."""
    tag = (lip, cen.tobytes()) + arrays_key(P)
    rows = cache.setdefault(tag, {})
    keys = [c.tobytes() for c in cells]
    missing = [i for i, k in enumerate(keys) if k not in rows]
    if missing:
        m, e, c = integrate_cells(*P[:5], np.ascontiguousarray(cells[missing]), lip, *_G5,
                                  *_G7, cen, kinv=P[5])
        for j, i in enumerate(missing):
            rows[keys[i]] = (m[j], e[j], c[j])
    got = [rows[k] for k in keys]
    return (np.array([g[0] for g in got]).reshape(-1, 10),
            np.array([g[1] for g in got]).reshape(-1, 10),
            np.array([g[2] for g in got], dtype=np.int64))


def _children(cells):
    """The 8 children of each cell of ``cells`` (N, 6), in a fixed order: (8 N, 6)."""
    lo, hi = cells[:, 0:3], cells[:, 3:6]
    mid = 0.5 * (lo + hi)
    out = np.empty((cells.shape[0], 8, 6))
    for c in range(8):
        bits = np.array([(c >> d) & 1 for d in range(3)], dtype=bool)
        out[:, c, 0:3] = np.where(bits, mid, lo)
        out[:, c, 3:6] = np.where(bits, hi, mid)
    return out.reshape(-1, 6)


def integrate_body(prog, lo, hi, n, lip, tol, cache=None, kinv=1.0):
    """Raw moments (10,) of the solid relative to the box centre, their error estimates (10,)
    and diagnostics (cells integrated, deepest level, cells left unconverged at MAX_DEPTH,
    overflow flag), by global adaptive refinement.

    The box is split into n^3 top-level cells, each integrated once. Each cell's error is
    measured against the solid's own scale (volume V, raw second-moment trace T: a moment's
    error over V, V^1/2 T^1/2 or T), and while the sum over cells exceeds ``tol``, the cells
    with the largest errors are split until the rest add up to at most tol / 2 (cells where
    the surface was seen but not integrated are always split), down to MAX_DEPTH levels. So
    ``tol`` is the relative accuracy of the solid's moments, spent where the error is.

    ``kinv``: 1 / L, L the tree's Lipschitz constant (1.0 for a 1-Lipschitz tree).
    ``cache`` (optional dict, see :func:`cached_cells`) shares integrated cells between calls:
    the result is bitwise the same with or without it."""
    P = (prog.ops, prog.leaf_kind, prog.leaf_reals, prog.op_begin, prog.op_end, float(kinv))
    cen = 0.5 * (lo + hi)
    edges = [np.linspace(lo[d], hi[d], n + 1) for d in range(3)]
    for d in range(3):
        edges[d][-1] = hi[d]
    k, j, i = np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing="ij")
    i, j, k = i.ravel(), j.ravel(), k.ravel()              # x fastest
    new = np.column_stack([edges[0][i], edges[1][j], edges[2][k],
                           edges[0][i + 1], edges[1][j + 1], edges[2][k + 1]])
    new_depth = np.zeros(len(new), dtype=np.int64)
    cells = np.empty((0, 6))
    depth = np.empty(0, dtype=np.int64)
    mom = np.empty((0, 10))
    err = np.empty((0, 10))
    code = np.empty(0, dtype=np.int64)
    visited = 0
    unconverged = 0
    while len(new):
        if visited + len(new) > MAX_CELLS:
            raise ValueError(
                f"quadrature budget: refining to tol={tol:g} needs more than {MAX_CELLS} cells "
                f"({visited} integrated down to level {int(depth.max(initial=0))}, "
                f"{len(new)} more asked for): the solid is far thinner than its box [lo, hi] "
                "or tol is out of reach; give a box closer to the solid, or a looser tol")
        if cache is None:
            m_new, e_new, c_new = integrate_cells(*P[:5], new, lip, *_G5, *_G7, cen,
                                                  kinv=P[5])
        else:
            m_new, e_new, c_new = cached_cells(cache, P, new, lip, cen)
        visited += len(new)
        if np.any(c_new < 0):
            return np.zeros(10), np.zeros(10), np.array([visited, 0, 0, 1.0])
        cells = np.concatenate([cells, new])
        depth = np.concatenate([depth, new_depth])
        mom = np.concatenate([mom, m_new])
        err = np.concatenate([err, e_new])
        code = np.concatenate([code, c_new])
        vol = mom[:, 0].sum()
        trace = mom[:, 4:7].sum()
        if not (vol > 0.0 and trace > 0.0):
            # nothing seen yet: measure against the box
            vol = float(np.prod(hi - lo))
            trace = vol * float(np.sum((hi - lo) ** 2)) / 12.0
        w = np.r_[1.0 / vol, np.full(3, 1.0 / math.sqrt(vol * trace)), np.full(6, 1.0 / trace)]
        e = (err * w).max(axis=1)
        can = depth < MAX_DEPTH
        split = (code == 1) & can
        rest = float(e[~split].sum())
        if rest > tol:
            # the largest first (ties by position: deterministic), until the rest is tol / 2
            order = np.argsort(-e, kind="stable")
            order = order[can[order] & ~split[order] & (e[order] > 0.0)]
            drop = np.cumsum(e[order])
            take = int(np.searchsorted(drop, rest - 0.5 * tol, side="left")) + 1
            split[order[:take]] = True
        if not split.any():
            if rest > tol:      # what is left over tol sits at MAX_DEPTH
                unconverged = int(np.count_nonzero(~can & (e > 0.0)))
            break
        keep = ~split
        new = _children(cells[split])
        new_depth = np.repeat(depth[split] + 1, 8)
        cells, depth, mom, err, code = cells[keep], depth[keep], mom[keep], err[keep], code[keep]
    diag = np.array([visited, depth.max(initial=0), unconverged, 0.0], dtype=float)
    return _ordered_sum(mom), _ordered_sum(err), diag


def _ordered_sum(rows):
    """Column sums in row order (a plain loop: the same bits for the same rows)."""
    out = np.zeros(rows.shape[1])
    for r in rows:
        out += r
    return out


def _gauss01(q):
    x, w = np.polynomial.legendre.leggauss(q)
    return np.ascontiguousarray(0.5 * (x + 1.0)), np.ascontiguousarray(0.5 * w)


_G5 = _gauss01(5)
_G7 = _gauss01(7)
