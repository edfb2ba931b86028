"""Broad phase: candidate body pairs from a cell list over bounding spheres.

A pair (i, j), i < j, is a candidate when the minimum-image distance of the two centres is
below ``r_i + r_j + margin``. On periodic axes the displacement is wrapped into
``[-L/2, L/2)`` (one image per pair; the caller guarantees ``L > 2 * cutoff`` so that no pair can
interact through two images). Non-periodic axes need no domain: the grid spans the particles.

Count pass, then fill pass into exactly-sized arrays; within a body's row the partners are
sorted by index, so the list is ordered by (i, j). Rows are independent: a large bed deals them
to parallel workers (:func:`pairs`), which find and write their rows in one pass into buffers
of their own and then copy them into place; a small one stays serial (a parallel launch costs
more than a few hundred rows); both give the same arrays.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from peclet.dem.sorting import counting_sort

#: From this many bodies the rows are found in parallel (below, a parallel launch costs more
#: than the rows); either way the same arrays.
PARALLEL_BODIES = 4000
#: Row workers of the parallel path (rows interleaved among them: loads even out).
ROW_WORKERS = 32
#: Partner slots per row that a worker of the parallel path reserves at first (it finds and
#: writes its rows in one pass; when one runs out the pass starts again with twice as many).
ROW_SLOTS = 16


@njit(cache=True)
def build_cells(pos, lo, cell, dims):
    """Counting sort of bodies into cells. Returns (cell_start (ncell + 1,), items (N,),
    coords (N, 3)). Coordinates outside the grid are clamped into it (monotone, so bodies in
    non-adjacent cells are never closer than one cell width)."""
    n = pos.shape[0]
    coords = np.empty((n, 3), np.int64)
    ncell = dims[0] * dims[1] * dims[2]
    cid = np.empty(n, np.int64)
    for i in range(n):
        for a in range(3):
            c = int(math.floor((pos[i, a] - lo[a]) / cell[a]))
            if c < 0:
                c = 0
            if c >= dims[a]:
                c = dims[a] - 1
            coords[i, a] = c
        cid[i] = (coords[i, 2] * dims[1] + coords[i, 1]) * dims[0] + coords[i, 0]
    counts, items = counting_sort(cid, ncell)
    return counts, items, coords


@njit(cache=True)
def _axis_cells(c, dim, periodic, out):
    """Absolute neighbour cell indices along one axis, without duplicates."""
    if periodic and dim < 3:
        for k in range(dim):
            out[k] = k
        return dim
    m = 0
    for d in range(-1, 2):
        k = c + d
        if periodic:
            k = k % dim
        elif k < 0 or k >= dim:
            continue
        out[m] = k
        m += 1
    return m


@njit(cache=True, inline="always")
def _nearest(v, length, periodic):
    """The offset ``v`` along an axis to the nearest periodic image (``v`` itself when the
    axis is not periodic)."""
    if periodic:
        return v - length * math.floor(v / length + 0.5)
    return v


@njit(cache=True)
def image_shifts(pa, pb, pos, box, periodic):
    """(P, 3) the shift of each pair's b to its image nearest to a, computed as
    :func:`find_pairs` computes it (the same bits): what a kept pair list needs when the
    bodies have moved (and wrapped) since it was built."""
    shift = np.empty((pa.shape[0], 3))
    for u in range(pa.shape[0]):
        for e in range(3):
            v = pos[pb[u], e] - pos[pa[u], e]
            shift[u, e] = _nearest(v, box[e], periodic[e]) - v
    return shift


# _scan_body's ``write`` flag as a numpy bool, not a literal: a literal True / False compiled
# the scan twice (about a second of a cold first run)
_COUNT = np.bool_(False)
_STORE = np.bool_(True)


class CellList(NamedTuple):
    """The bodies binned in the cell grid, as a row scan reads them: centres ``pos`` (N, 3),
    bounding ``radius`` (N,), the pairs' ``margin`` (length), ``box`` (3,) the periodic
    lengths, ``periodic`` (3,) bool, ``dims`` (3,) cells per axis, ``cell_start`` (ncell + 1,)
    and ``items`` (N,) the bodies by cell and ``coords`` (N, 3) each body's cell
    (:func:`build_cells`), and ``cpos`` (N, 3), ``crad`` (N,) the positions and radii in cell
    order (:func:`_cell_sorted`). Built once per call of :func:`find_pairs`
    (:func:`find_pairs_parallel`)."""
    pos: np.ndarray
    radius: np.ndarray
    margin: float
    box: np.ndarray
    periodic: np.ndarray
    dims: np.ndarray
    cell_start: np.ndarray
    items: np.ndarray
    coords: np.ndarray
    cpos: np.ndarray
    crad: np.ndarray


@njit(cache=True)
def _row_scratch():
    """A row scan's scratch: the neighbour cells along x, y, z ((3,) int64 each) and the
    displacement (3,). Allocated once per call of a row loop: an allocation per body cost a
    third of the phase."""
    return (np.empty(3, np.int64), np.empty(3, np.int64), np.empty(3, np.int64),
            np.empty(3))


@njit(cache=True)
def _scan_body(i, cells, out_j, out_shift, write, base, scratch):
    """Visit body i's partners j > i in the :class:`CellList` ``cells``; count them, and if
    ``write`` store them from ``base`` (those that fit below ``len(out_j)``: the count says
    whether all did). ``scratch``: :func:`_row_scratch`. The candidates are read in cell order
    (``cells.cpos``, ``cells.crad``), so that a cell's are consecutive rows; a cell's items
    ascend, so it is read from its last down to the first j <= i."""
    pos, radius, margin, box, periodic, dims = (cells.pos, cells.radius, cells.margin,
                                                cells.box, cells.periodic, cells.dims)
    cell_start, items, coords = cells.cell_start, cells.items, cells.coords
    cpos, crad = cells.cpos, cells.crad
    ax, ay, az, d = scratch
    limit = out_j.shape[0]
    nx = _axis_cells(coords[i, 0], dims[0], periodic[0], ax)
    ny = _axis_cells(coords[i, 1], dims[1], periodic[1], ay)
    nz = _axis_cells(coords[i, 2], dims[2], periodic[2], az)
    cnt = 0
    for a in range(nx):
        for b in range(ny):
            for c in range(nz):
                k = (az[c] * dims[1] + ay[b]) * dims[0] + ax[a]
                for s in range(cell_start[k + 1] - 1, cell_start[k] - 1, -1):
                    j = items[s]
                    if j <= i:
                        break
                    r2 = 0.0
                    for e in range(3):
                        v = _nearest(cpos[s, e] - pos[i, e], box[e], periodic[e])
                        d[e] = v
                        r2 += v * v
                    cut = radius[i] + crad[s] + margin
                    if r2 < cut * cut:
                        if write and base + cnt < limit:
                            out_j[base + cnt] = j
                            for e in range(3):
                                out_shift[base + cnt, e] = d[e] - (cpos[s, e] - pos[i, e])
                        cnt += 1
    return cnt


@njit(cache=True)
def _cell_sorted(pos, radius, items):
    """Positions and radii in cell order: row s is body items[s]'s."""
    n = items.shape[0]
    cpos = np.empty((n, 3))
    crad = np.empty(n)
    for s in range(n):
        j = items[s]
        crad[s] = radius[j]
        for e in range(3):
            cpos[s, e] = pos[j, e]
    return cpos, crad


@njit(cache=True)
def _count_rows(k, nw, cells, counts):
    """counts[i] for the rows i = k, k + nw, ... (each row only written by its owner)."""
    scratch = _row_scratch()
    dummy_j = np.empty(0, np.int64)
    dummy_s = np.empty((0, 3))
    zero = np.int64(0)
    for i in range(k, cells.pos.shape[0], nw):
        counts[i] = _scan_body(i, cells, dummy_j, dummy_s, _COUNT, zero, scratch)


@njit(cache=True)
def _fill_rows(k, nw, cells, offs, pb, shift):
    """Rows i = k, k + nw, ...: partners and shifts from offs[i], sorted by partner index (a
    fixed order, independent of the cell layout)."""
    scratch = _row_scratch()
    for i in range(k, cells.pos.shape[0], nw):
        _scan_body(i, cells, pb, shift, _STORE, offs[i], scratch)
        _sort_row(pb, shift, offs[i], offs[i + 1])


@njit(cache=True)
def _sort_row(pb, shift, lo, hi):
    """Insertion sort of the partners pb[lo:hi] (with their shifts) by index."""
    for u in range(lo + 1, hi):
        j = pb[u]
        s0 = shift[u, 0]
        s1 = shift[u, 1]
        s2 = shift[u, 2]
        w = u - 1
        while w >= lo and pb[w] > j:
            pb[w + 1] = pb[w]
            shift[w + 1, 0] = shift[w, 0]
            shift[w + 1, 1] = shift[w, 1]
            shift[w + 1, 2] = shift[w, 2]
            w -= 1
        pb[w + 1] = j
        shift[w + 1, 0] = s0
        shift[w + 1, 1] = s1
        shift[w + 1, 2] = s2


@njit(cache=True)
def _rows(counts):
    """(offs (n + 1,), pb, shift, pa) sized for the row counts; pa filled."""
    n = counts.shape[0]
    offs = np.zeros(n + 1, np.int64)
    for i in range(n):
        offs[i + 1] = offs[i] + counts[i]
    total = offs[n]
    pa = np.empty(total, np.int64)
    for i in range(n):
        for u in range(offs[i], offs[i + 1]):
            pa[u] = i
    return offs, np.empty(total, np.int64), np.empty((total, 3)), pa


@njit(cache=True)
def find_pairs(pos, radius, margin, lo, cell, dims, box, periodic):
    """Candidate pairs. Returns (a (P,), b (P,), shift (P, 3)) with a < b, sorted by (a, b);
    ``pos[b] + shift`` is the image of b nearest to a."""
    cell_start, items, coords = build_cells(pos, lo, cell, dims)
    cpos, crad = _cell_sorted(pos, radius, items)
    cells = CellList(pos, radius, margin, box, periodic, dims, cell_start, items, coords, cpos,
                     crad)
    counts = np.zeros(pos.shape[0], np.int64)
    one = np.int64(1)
    zero = np.int64(0)
    _count_rows(zero, one, cells, counts)
    offs, pb, shift, pa = _rows(counts)
    _fill_rows(zero, one, cells, offs, pb, shift)
    return pa, pb, shift


@njit(cache=True)
def _scan_rows(k, nw, cells, counts, rowpos, buf_j, buf_s):
    """Rows i = k, k + nw, ... in one pass: each row's partners, sorted by index, with their
    shifts into this worker's buffers ``buf_j``/``buf_s`` from ``rowpos[i]``, ``counts[i]``
    their number. Returns the slots used, or -1 when the buffers are too small."""
    scratch = _row_scratch()
    cap = buf_j.shape[0]
    used = np.int64(0)
    for i in range(k, cells.pos.shape[0], nw):
        cnt = _scan_body(i, cells, buf_j, buf_s, _STORE, used, scratch)
        if used + cnt > cap:
            return np.int64(-1)
        _sort_row(buf_j, buf_s, used, used + cnt)
        counts[i] = cnt
        rowpos[i] = used
        used += cnt
    return used


@njit(cache=True)
def _copy_rows(k, nw, counts, rowpos, buf_j, buf_s, offs, pb, shift):
    """Rows i = k, k + nw, ... from this worker's buffers to their place in the list."""
    for i in range(k, counts.shape[0], nw):
        for u in range(counts[i]):
            pb[offs[i] + u] = buf_j[rowpos[i] + u]
            for e in range(3):
                shift[offs[i] + u, e] = buf_s[rowpos[i] + u, e]


@njit(cache=True, parallel=True)
def find_pairs_parallel(pos, radius, margin, lo, cell, dims, box, periodic, slots):
    """:func:`find_pairs` with the rows dealt to ROW_WORKERS parallel workers (interleaved),
    in one pass: each worker writes its rows, sorted, into its own buffer of ``slots`` pairs,
    and the rows are then copied to their places. Every row is written by its owner alone, so
    the result is the same arrays, bit for bit. Returns (a, b, shift, ok): ok False (and empty
    arrays) when a worker's buffer was too small."""
    cell_start, items, coords = build_cells(pos, lo, cell, dims)
    cpos, crad = _cell_sorted(pos, radius, items)
    # built here, not returned by a helper: the parallel loop below rebuilds the bundle by the
    # name of the class it was constructed with
    cells = CellList(pos, radius, margin, box, periodic, dims, cell_start, items, coords, cpos,
                     crad)
    n = pos.shape[0]
    counts = np.zeros(n, np.int64)
    rowpos = np.zeros(n, np.int64)
    buf_j = np.empty((ROW_WORKERS, slots), np.int64)
    buf_s = np.empty((ROW_WORKERS, slots, 3))
    used = np.empty(ROW_WORKERS, np.int64)
    nw = np.int64(ROW_WORKERS)
    for k in prange(ROW_WORKERS):
        used[k] = _scan_rows(np.int64(k), nw, cells, counts, rowpos, buf_j[k], buf_s[k])
    for k in range(ROW_WORKERS):
        if used[k] < 0:
            return (np.empty(0, np.int64), np.empty(0, np.int64), np.empty((0, 3)), False)
    offs, pb, shift, pa = _rows(counts)
    for k in prange(ROW_WORKERS):
        _copy_rows(np.int64(k), nw, counts, rowpos, buf_j[k], buf_s[k], offs, pb, shift)
    return pa, pb, shift, True


def pairs(pos, radius, margin, lo, cell, dims, box, periodic):
    """Candidate pairs (see :func:`find_pairs`), in parallel from PARALLEL_BODIES bodies."""
    if len(pos) < PARALLEL_BODIES:
        return find_pairs(pos, radius, margin, lo, cell, dims, box, periodic)
    slots = ROW_SLOTS * (len(pos) // ROW_WORKERS + 1)
    while True:
        pa, pb, shift, ok = find_pairs_parallel(pos, radius, margin, lo, cell, dims, box,
                                                periodic, np.int64(slots))
        if ok:
            return pa, pb, shift
        slots *= 2


def grid_for(pos, cutoff, domain_lo, domain_hi, periodic, max_cells):
    """Cell grid (lo (3,), cell (3,), dims (3,) int64, box (3,)) for the bodies at ``pos``.

    Periodic axes span the domain with cells of at least ``cutoff``; other axes span the
    bodies. The cell size grows when the grid would exceed ``max_cells`` cells.
    """
    lo = np.empty(3)
    ext = np.empty(3)
    box = np.ones(3)
    for a in range(3):
        if periodic[a]:
            lo[a] = domain_lo[a]
            ext[a] = domain_hi[a] - domain_lo[a]
            box[a] = ext[a]
        elif len(pos):
            lo[a] = pos[:, a].min()
            ext[a] = pos[:, a].max() - lo[a]
        else:
            lo[a] = 0.0
            ext[a] = 0.0
    size = max(cutoff, 1e-300)
    cap = float(max_cells) + 1.0      # a count past the cap only means "grow the cells"
    while True:
        dims = np.empty(3, np.int64)
        cell = np.empty(3)
        for a in range(3):
            if periodic[a]:
                dims[a] = max(1, int(min(ext[a] // size, cap)))
                cell[a] = ext[a] / dims[a]
            else:
                dims[a] = int(min(ext[a] // size, cap)) + 1
                cell[a] = size
        if int(dims[0]) * int(dims[1]) * int(dims[2]) <= max_cells:    # no int64 wrap
            return lo, cell, dims, box
        size *= 1.5


@njit(cache=True)
def task_list(pa, pb, shift, n, n_walls, base, reach, wall_reach, frozen, wall_static):
    """The narrow phase's tasks: the pairs ``(pa, pb, shift)`` of :func:`find_pairs` and one
    task per body and wall (b = -1 - w), in (a, b) order (a body's wall tasks first, b
    ascending), with each task's margin ``base + (reach[a] + reach[b])`` for two bodies and
    ``base + (reach[a] + wall_reach[a, w])`` against wall w. Pairs of two ``frozen`` bodies
    (sleepers, :mod:`peclet.dem.sleep`) and a frozen body's tasks with a ``wall_static`` wall
    are left out. Returns (a, b, shift (T, 3), margin)."""
    npair = pa.shape[0]
    total = npair + n * n_walls
    ta = np.empty(total, np.int64)
    tb = np.empty(total, np.int64)
    ts = np.zeros((total, 3))
    tm = np.empty(total)
    u = 0
    k = 0
    for a in range(n):
        for w in range(n_walls - 1, -1, -1):
            if frozen[a] and wall_static[w]:
                continue
            ta[k] = a
            tb[k] = -1 - w
            tm[k] = base + (reach[a] + wall_reach[a, w])
            k += 1
        while u < npair and pa[u] == a:
            if not (frozen[a] and frozen[pb[u]]):
                ta[k] = a
                tb[k] = pb[u]
                for e in range(3):
                    ts[k, e] = shift[u, e]
                tm[k] = base + (reach[a] + reach[pb[u]])
                k += 1
            u += 1
    return ta[:k], tb[:k], ts[:k], tm[:k]
