"""Narrow phase: contact manifolds for body-body and body-wall tasks.

Every task is one pair: (a, b) with b >= 0 a body (image shift given), or b = -1 - w a wall.

- sphere / sphere: the exact analytic contact along the centre line;
- sphere / tree: the sphere's centre against the tree's exact field, ``phi - radius``;
- tree / tree: each body's shell probes, mapped into the other's home frame, against the
  other's exact tree -- BOTH ways, so a thin rim pressed between one body's probes is still
  caught by the other's probes;
- body / wall: the body's probes (a sphere: its centre) against the wall's tree.

Normals are the analytic gradients of the tree (normalised), rotated to the world frame; the
stored normal always points from b to a (it pushes a away from b). ``gap`` is the signed
separation (< 0 is a penetration of depth -gap); the contact point is midway between the two
surfaces. Hits within ``margin`` are kept (speculative contacts).

Probes are grouped into clusters with a bounding sphere, clusters into super-clusters. When the
tree's field is 1-Lipschitz, phi grows by at most the distance travelled, so a lower bound of
phi at a sphere's centre minus its radius bounds every point inside: the body, a super-cluster,
a cluster or a single probe is skipped once that bound exceeds the margin. The bounds come from
the tree's distance grid (:mod:`peclet.dem.distgrid`, one array read), or one evaluation where
a tree has no grid (walls), or the enclosing level's bound minus the offset. Only the probes
that survive are evaluated on the exact tree; a skipped probe cannot be a hit, and the hits are
put back in probe order, so the contacts are bit for bit those of evaluating every probe.

Manifold reduction (so that a pair's impulse does not depend on how many probes happen to be
inside): hits are grouped by normal direction (at most ``MAX_CLUSTERS`` groups, each seeded by
its deepest remaining hit), and each group keeps at most four points: the deepest, the one
farthest from it in the contact plane, and the two extremes on either side of that line.
A task therefore writes at most ``MAX_PER_TASK`` contacts, into its own slots.

Determinism: tasks run in parallel (fixed-size chunks dealt to a fixed number of workers),
every task writes only its own slots; all choices break ties by the lowest index.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from peclet.core.geom.kernels import MAX_STACK, STACK_COLS, eval_point
from peclet.dem.distgrid import lower_bound

MAX_CLUSTERS = 4
POINTS_PER_CLUSTER = 4
MAX_PER_TASK = MAX_CLUSTERS * POINTS_PER_CLUSTER
#: Two hits belong to the same normal group when their normals make an angle below ~37 deg.
CLUSTER_COS = 0.8
#: Feature ids of the second direction (b's probes in a's tree) are offset by this.
FEATURE_DIR = 1 << 24
TASK_CHUNK = 8
#: Parallel workers (each takes every WORKERS-th chunk): enough to even out 2..16 threads.
WORKERS = 32

# hit row layout
_HX, _HN, _HG, _HF = 0, 3, 6, 7
HIT_COLS = 8


class Tasks(NamedTuple):
    """Candidate pairs: body ``a`` (T,), body ``b`` (T,) (a wall is -1 - index) and the image
    ``shift`` (T, 3) added to b's position (periodic minimum image; zero for walls)."""
    a: np.ndarray
    b: np.ndarray
    shift: np.ndarray


class Slots(NamedTuple):
    """Output buffers: task t writes ``count[t]`` contacts from slot ``t * MAX_PER_TASK``:
    ``point`` (S, 3) world, ``normal`` (S, 3) unit from b to a, ``gap`` (S,), ``feat`` (S,)."""
    count: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    gap: np.ndarray
    feat: np.ndarray


@njit(cache=True, inline="always")
def _point_vs_tree(px, py, pz, r, xt, Rt, o0, o1, sgn, trad, nsign, feat, margin, ops, lk, lr,
                   grid, goff, gdims, goh, st, hits, nh):
    """A point (a probe with r = 0, or a sphere's centre with its radius r) against a tree
    placed at xt with rotation Rt; ``sgn`` = -1 for an inverted wall; the tree's distance grid
    (``gdims[0]`` = 0: none) spares the evaluation of a point it proves out of reach. Appends
    at most one hit."""
    dx = px - xt[0]
    dy = py - xt[1]
    dz = pz - xt[2]
    qx = Rt[0, 0] * dx + Rt[1, 0] * dy + Rt[2, 0] * dz
    qy = Rt[0, 1] * dx + Rt[1, 1] * dy + Rt[2, 1] * dz
    qz = Rt[0, 2] * dx + Rt[1, 2] * dy + Rt[2, 2] * dz
    lim = trad + r + margin
    if qx * qx + qy * qy + qz * qz > lim * lim:
        return nh
    if lower_bound(grid, goff, gdims, goh, qx, qy, qz) - r > margin:
        return nh
    phi, gx, gy, gz = eval_point(ops, lk, lr, o0, o1, qx, qy, qz, st)
    phi = sgn * phi - r
    if not (phi < margin):
        return nh
    nx = sgn * (Rt[0, 0] * gx + Rt[0, 1] * gy + Rt[0, 2] * gz)
    ny = sgn * (Rt[1, 0] * gx + Rt[1, 1] * gy + Rt[1, 2] * gz)
    nz = sgn * (Rt[2, 0] * gx + Rt[2, 1] * gy + Rt[2, 2] * gz)
    nn = math.sqrt(nx * nx + ny * ny + nz * nz)
    if not (nn > 0.0):
        return nh
    nx /= nn
    ny /= nn
    nz /= nn
    # midway between the point's surface (at distance r) and the tree's surface
    h = r + 0.5 * phi
    hits[nh, 0] = px - h * nx
    hits[nh, 1] = py - h * ny
    hits[nh, 2] = pz - h * nz
    hits[nh, 3] = nsign * nx
    hits[nh, 4] = nsign * ny
    hits[nh, 5] = nsign * nz
    hits[nh, 6] = phi
    hits[nh, 7] = feat
    return nh + 1


@njit(cache=True, inline="always")
def _sphere_bound(xa, Ra, c, rad, xt, Rt, o0, o1, sgn, lip, trad, margin, ops, lk, lr,
                  grid, goff, gdims, goh, st):
    """A lower bound of the tree's (signed) phi at body a's home-frame point ``c``, the centre
    of a sphere of radius ``rad``: +inf (nothing evaluated) when the sphere lies beyond the
    tree's bounding sphere ``trad`` by more than the margin; on a 1-Lipschitz tree the
    distance grid's bound where it has one, else the value at c; otherwise -inf (no bound)."""
    cx = xa[0] + Ra[0, 0] * c[0] + Ra[0, 1] * c[1] + Ra[0, 2] * c[2]
    cy = xa[1] + Ra[1, 0] * c[0] + Ra[1, 1] * c[1] + Ra[1, 2] * c[2]
    cz = xa[2] + Ra[2, 0] * c[0] + Ra[2, 1] * c[1] + Ra[2, 2] * c[2]
    dx = cx - xt[0]
    dy = cy - xt[1]
    dz = cz - xt[2]
    lim = trad + rad + margin
    if dx * dx + dy * dy + dz * dz > lim * lim:
        return np.inf
    if not lip:
        return -np.inf
    qx = Rt[0, 0] * dx + Rt[1, 0] * dy + Rt[2, 0] * dz
    qy = Rt[0, 1] * dx + Rt[1, 1] * dy + Rt[2, 1] * dz
    qz = Rt[0, 2] * dx + Rt[1, 2] * dy + Rt[2, 2] * dz
    if gdims[0] > 0:
        return lower_bound(grid, goff, gdims, goh, qx, qy, qz)
    return sgn * eval_point(ops, lk, lr, o0, o1, qx, qy, qz, st)[0]


@njit(cache=True)
def _sort_hits(hits, n0, n1):
    """Insertion sort of the rows [n0, n1) by feature id: the probe order, whatever order the
    culling visited them in (so the reduction sees the same rows in the same order)."""
    for i in range(n0 + 1, n1):
        j = i
        while j > n0 and hits[j - 1, _HF] > hits[j, _HF]:
            for e in range(HIT_COLS):
                v = hits[j, e]
                hits[j, e] = hits[j - 1, e]
                hits[j - 1, e] = v
            j -= 1


@njit(cache=True, inline="always")
def _shell_vs_body(xa, Ra, sa, xt, Rt, so, geo, nsign, fbase, margin, origin, st, hits, nh):
    """One way of the two-way test: body a's shell probes (shape ``sa``) against the tree of
    the body at ``xt``/``Rt`` (shape ``so``), first bounded at a's centre. ``nsign`` and
    ``fbase`` orient the normals and feature ids of this direction (see _probes_vs_tree)."""
    op = geo.shape_op
    rad = geo.shape_rad
    goff, gd, gh = geo.shape_grid_off[so], geo.shape_grid_dims[so], geo.shape_grid_oh[so]
    phr = _sphere_bound(xa, Ra, origin, rad[sa], xt, Rt, op[so, 0], op[so, 1], 1.0,
                        geo.shape_lip[so], rad[so], margin, geo.ops, geo.lk, geo.lr, geo.grid,
                        goff, gd, gh, st)
    return _probes_vs_tree(xa, Ra, sa, geo, xt, Rt, op[so, 0], op[so, 1], 1.0,
                           geo.shape_lip[so], rad[so], nsign, fbase, margin, phr, geo.grid, goff,
                           gd, gh, st, hits, nh)


@njit(cache=True, inline="always")
def _probes_vs_tree(xa, Ra, s, geo, xt, Rt, o0, o1, sgn, lip, trad, nsign, fbase, margin,
                    phr, grid, goff, gdims, goh, st, hits, nh):
    """Body a's shell probes (shape s, at xa with rotation Ra) against a tree, hits in probe
    order. ``phr``: a lower bound of the tree's signed phi at xa (-inf: none); ``grid``,
    ``goff``, ``gdims``, ``goh``: the tree's distance grid (``gdims[0]`` = 0: none).

    Culling, from coarse to fine, never drops a hit (a 1-Lipschitz phi grows by at most the
    distance travelled): the whole shape when ``phr`` exceeds its radius + margin; a
    super-cluster skipped without evaluation when ``phr`` minus its offset does; a super-cluster
    or cluster whose bounding sphere is beyond the tree's
    bounding sphere, or on which phi's bound exceeds its radius + margin, is skipped; a cluster
    is skipped without evaluation when the super-cluster's value minus the cluster's offset
    already does; a probe is skipped when its cluster's value minus its offset exceeds the
    margin. Non-Lipschitz trees get the sphere tests only."""
    shape_p0, probes, probe_off = geo.shape_p0, geo.probes, geo.probe_off
    cl_centre, cl_rad, cl_range = geo.cl_centre, geo.cl_rad, geo.cl_range
    gr_centre, gr_rad, gr_range = geo.gr_centre, geo.gr_rad, geo.gr_range
    gr_member, gr_off = geo.gr_member, geo.gr_off
    ops, lk, lr = geo.ops, geo.lk, geo.lr
    gr_dist = geo.gr_dist
    if phr > geo.shape_rad[s] + margin:
        return nh
    n0 = nh
    for g in range(geo.shape_gr[s, 0], geo.shape_gr[s, 1]):
        if phr - gr_dist[g] > gr_rad[g] + margin:
            continue
        phg = _sphere_bound(xa, Ra, gr_centre[g], gr_rad[g], xt, Rt, o0, o1, sgn, lip, trad,
                            margin, ops, lk, lr, grid, goff, gdims, goh, st)
        if phg > gr_rad[g] + margin:
            continue
        for m in range(gr_range[g, 0], gr_range[g, 1]):
            c = gr_member[m]
            if phg - gr_off[m] > cl_rad[c] + margin:
                continue
            phc = _sphere_bound(xa, Ra, cl_centre[c], cl_rad[c], xt, Rt, o0, o1, sgn, lip,
                                trad, margin, ops, lk, lr, grid, goff, gdims, goh, st)
            if phc > cl_rad[c] + margin:
                continue
            for p in range(cl_range[c, 0], cl_range[c, 1]):
                if phc - probe_off[p] > margin:
                    continue
                px = xa[0] + Ra[0, 0] * probes[p, 0] + Ra[0, 1] * probes[p, 1] + Ra[0, 2] * probes[p, 2]
                py = xa[1] + Ra[1, 0] * probes[p, 0] + Ra[1, 1] * probes[p, 1] + Ra[1, 2] * probes[p, 2]
                pz = xa[2] + Ra[2, 0] * probes[p, 0] + Ra[2, 1] * probes[p, 1] + Ra[2, 2] * probes[p, 2]
                nh = _point_vs_tree(px, py, pz, 0.0, xt, Rt, o0, o1, sgn, trad, nsign,
                                    fbase + p - shape_p0[s], margin, ops, lk, lr, grid, goff,
                                    gdims, goh, st, hits, nh)
    _sort_hits(hits, n0, nh)
    return nh


@njit(cache=True)
def _reduce(hits, nh, lab, reps, tol2, touch, base, out_point, out_normal, out_gap, out_feat):
    """Reduce a task's hits to at most MAX_PER_TASK contacts written from slot ``base``."""
    for i in range(nh):
        lab[i] = -1
    ncl = 0
    while ncl < MAX_CLUSTERS:
        best = -1
        for i in range(nh):
            if lab[i] < 0 and (best < 0 or hits[i, _HG] < hits[best, _HG]):
                best = i
        if best < 0:
            break
        for i in range(nh):
            if lab[i] < 0:
                d = (hits[i, 3] * hits[best, 3] + hits[i, 4] * hits[best, 4]
                     + hits[i, 5] * hits[best, 5])
                if d >= CLUSTER_COS:
                    lab[i] = ncl
        lab[best] = ncl
        reps[ncl] = best
        ncl += 1
    for i in range(nh):
        if lab[i] < 0:
            bk = 0
            bd = -2.0
            for k in range(ncl):
                r = reps[k]
                d = hits[i, 3] * hits[r, 3] + hits[i, 4] * hits[r, 4] + hits[i, 5] * hits[r, 5]
                if d > bd:
                    bd = d
                    bk = k
            lab[i] = bk
    nout = 0
    for k in range(ncl):
        i0 = reps[k]
        nx = hits[i0, 3]
        ny = hits[i0, 4]
        nz = hits[i0, 5]
        # farthest from the deepest point, in the contact plane
        # the spread points are chosen among the hits within ``touch`` of the deepest: the
        # support polygon of what actually touches, not of far speculative probes
        lim = hits[i0, _HG] + touch
        i1 = -1
        b1 = tol2
        for i in range(nh):
            if lab[i] == k and hits[i, _HG] <= lim:
                ex = hits[i, 0] - hits[i0, 0]
                ey = hits[i, 1] - hits[i0, 1]
                ez = hits[i, 2] - hits[i0, 2]
                en = ex * nx + ey * ny + ez * nz
                d2 = ex * ex + ey * ey + ez * ez - en * en
                if d2 > b1:
                    b1 = d2
                    i1 = i
        i2 = -1
        i3 = -1
        if i1 >= 0:
            ux = hits[i1, 0] - hits[i0, 0]
            uy = hits[i1, 1] - hits[i0, 1]
            uz = hits[i1, 2] - hits[i0, 2]
            # signed (doubled) triangle area n . (u x e), largest either side of the line
            thr = tol2 ** 0.5 * b1 ** 0.5
            b2 = thr
            b3 = -thr
            for i in range(nh):
                if lab[i] == k and hits[i, _HG] <= lim:
                    ex = hits[i, 0] - hits[i0, 0]
                    ey = hits[i, 1] - hits[i0, 1]
                    ez = hits[i, 2] - hits[i0, 2]
                    a = (nx * (uy * ez - uz * ey) + ny * (uz * ex - ux * ez)
                         + nz * (ux * ey - uy * ex))
                    if a > b2:
                        b2 = a
                        i2 = i
                    if a < b3:
                        b3 = a
                        i3 = i
        for i in (i0, i1, i2, i3):
            if i >= 0:
                o = base + nout
                for e in range(3):
                    out_point[o, e] = hits[i, e]
                    out_normal[o, e] = hits[i, 3 + e]
                out_gap[o] = hits[i, _HG]
                out_feat[o] = np.int64(hits[i, _HF])
                nout += 1
    return nout


@njit(cache=True)
def _worker(worker, nw, size, tasks, pos, rot, shape_of, geo, margin, tol2, touch, slots):
    """Worker ``worker`` of ``nw``: the chunks worker, worker + nw, ... of ``size`` tasks (interleaved, so
    that the workers' loads even out); gathers each task's hits and reduces them into its own
    slots. The scratch buffers are allocated once per worker: a task's hit buffer is large
    enough for every probe of both bodies, and allocating it per chunk cost a page-mapping
    system call each time, which serialised the threads."""
    # the tables are taken out of the tuple once: a field read in the per-probe loop would
    # cost a reference-count update per read
    shape_kind, shape_rad, shape_op = geo.shape_kind, geo.shape_rad, geo.shape_op
    ops, lk, lr = geo.ops, geo.lk, geo.lr
    grid, goff, gdims, goh = geo.grid, geo.shape_grid_off, geo.shape_grid_dims, geo.shape_grid_oh
    nogrid = np.zeros(3, np.int64)
    st = np.empty((MAX_STACK, STACK_COLS))
    hits = np.empty((geo.max_hits, HIT_COLS))
    lab = np.empty(geo.max_hits, np.int64)
    reps = np.empty(MAX_CLUSTERS, np.int64)
    xb = np.empty(3)
    ident = np.eye(3)
    origin = np.zeros(3)
    ntask = tasks.a.shape[0]
    nchunk = (ntask + size - 1) // size
    for ch in range(worker, nchunk, nw):
        for t in range(ch * size, min(ntask, (ch + 1) * size)):
            a = tasks.a[t]
            b = tasks.b[t]
            sa = shape_of[a]
            xa = pos[a]
            Ra = rot[a]
            nh = 0
            if b >= 0:
                sb = shape_of[b]
                for e in range(3):
                    xb[e] = pos[b, e] + tasks.shift[t, e]
                Rb = rot[b]
                if shape_kind[sa] == 0 and shape_kind[sb] == 0:
                    dx = xa[0] - xb[0]
                    dy = xa[1] - xb[1]
                    dz = xa[2] - xb[2]
                    dist = math.sqrt(dx * dx + dy * dy + dz * dz)
                    gap = dist - shape_rad[sa] - shape_rad[sb]
                    if gap < margin:
                        if dist > 0.0:
                            nx = dx / dist
                            ny = dy / dist
                            nz = dz / dist
                        else:
                            nx, ny, nz = 0.0, 1.0, 0.0
                        h = shape_rad[sa] + 0.5 * gap
                        hits[0, 0] = xa[0] - h * nx
                        hits[0, 1] = xa[1] - h * ny
                        hits[0, 2] = xa[2] - h * nz
                        hits[0, 3] = nx
                        hits[0, 4] = ny
                        hits[0, 5] = nz
                        hits[0, 6] = gap
                        hits[0, 7] = 0.0
                        nh = 1
                elif shape_kind[sa] == 0:
                    nh = _point_vs_tree(xa[0], xa[1], xa[2], shape_rad[sa], xb, Rb,
                                        shape_op[sb, 0], shape_op[sb, 1], 1.0, shape_rad[sb],
                                        1.0, 0, margin, ops, lk, lr, grid, goff[sb], gdims[sb],
                                        goh[sb], st, hits, nh)
                elif shape_kind[sb] == 0:
                    nh = _point_vs_tree(xb[0], xb[1], xb[2], shape_rad[sb], xa, Ra,
                                        shape_op[sa, 0], shape_op[sa, 1], 1.0, shape_rad[sa],
                                        -1.0, FEATURE_DIR, margin, ops, lk, lr, grid, goff[sa],
                                        gdims[sa], goh[sa], st, hits, nh)
                else:
                    # a bound at each centre covers the whole shape: many candidate pairs of a
                    # settled bed are neighbours that do not touch
                    nh = _shell_vs_body(xa, Ra, sa, xb, Rb, sb, geo, 1.0, 0, margin, origin,
                                        st, hits, nh)
                    nh = _shell_vs_body(xb, Rb, sb, xa, Ra, sa, geo, -1.0, FEATURE_DIR, margin,
                                        origin, st, hits, nh)
            else:
                w = -1 - b
                sg = geo.wall_sign[w]
                o0 = geo.wall_op[w, 0]
                o1 = geo.wall_op[w, 1]
                skip = False
                phc = -np.inf
                if geo.wall_lip[w]:
                    # whole-body cull: phi is 1-Lipschitz and the body lies within its radius
                    phc = sg * eval_point(ops, lk, lr, o0, o1, xa[0], xa[1], xa[2], st)[0]
                    skip = phc > shape_rad[sa] + margin
                if not skip:
                    if shape_kind[sa] == 0:
                        nh = _point_vs_tree(xa[0], xa[1], xa[2], shape_rad[sa], origin, ident,
                                            o0, o1, sg, np.inf, 1.0, 0, margin, ops, lk, lr, grid,
                                            0, nogrid, origin, st, hits, nh)
                    else:
                        nh = _probes_vs_tree(xa, Ra, sa, geo, origin, ident, o0, o1, sg,
                                             geo.wall_lip[w], np.inf, 1.0, 0, margin, phc, grid, 0,
                                             nogrid, origin, st, hits, nh)
            slots.count[t] = _reduce(hits, nh, lab, reps, tol2, touch, t * MAX_PER_TASK,
                                     slots.point, slots.normal, slots.gap, slots.feat)


@njit(cache=True, parallel=True)
def narrow_phase(tasks, pos, rot, shape_of, geo, margin, tol2, touch, chunks, slots):
    """Contacts of every task into its own ``MAX_PER_TASK`` slots; ``slots.count[t]`` = used.

    ``tasks`` a :class:`Tasks`; ``pos`` (N, 3) and ``rot`` (N, 3, 3) the bodies' centres and
    home -> world rotations, ``shape_of`` (N,) their shape ids; ``geo`` the
    :class:`peclet.dem.shapes.Geometry`; hits within ``margin`` are kept; ``tol2`` and ``touch``
    tune the manifold reduction; ``slots`` a :class:`Slots`. ``chunks`` = 1 runs serially in
    the calling thread (small problems, where a parallel launch costs more than it saves),
    otherwise WORKERS workers run in parallel, each taking every WORKERS-th chunk of
    TASK_CHUNK tasks. Either way every task writes only its own slots, so the result is
    identical."""
    nw = WORKERS if chunks > 1 else 1
    for k in prange(nw):
        _worker(k, nw, TASK_CHUNK, tasks, pos, rot, shape_of, geo, margin, tol2, touch, slots)
