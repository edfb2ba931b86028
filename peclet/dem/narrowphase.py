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
surfaces. Hits within the task's margin are kept (speculative contacts; each pair has its
own, see :func:`peclet.dem.broadphase.task_list`).

Probes are grouped into clusters with a bounding sphere, clusters into super-clusters. When the
tree's field is 1-Lipschitz, phi grows by at most the distance travelled, so a lower bound of
phi at a sphere's centre minus its radius bounds every point inside: the body, a super-cluster,
a cluster or a single probe is skipped once that bound exceeds the margin. The bounds come from
the tree's distance grid (:mod:`peclet.dem.distgrid`, one array read), or one evaluation where
a tree has no grid (walls), or the enclosing level's bound minus the offset. Only the probes
that survive are evaluated on the exact tree; a skipped probe cannot be a hit, and the hits are
put back in probe order, so the contacts are bit for bit those of evaluating every probe.

Between steps (:mod:`peclet.dem.reuse`): a direction scanned with the culling widened to
``reach`` lists the probes that survived it; while the bodies' relative motion since that scan
plus the margin stays within reach, only the listed probes are tested again, with the same
exact evaluation, so the hits are again those of a scan.

The hits are reduced to at most ``MAX_PER_TASK`` contacts per task (:mod:`peclet.dem.manifold`),
written into the task's own slots (one for a task with a sphere in it, which tests one point).

Determinism: tasks run in parallel (fixed-size chunks dealt to a fixed number of workers,
the workers to the threads),
every task writes only its own slots; all choices break ties by the lowest index.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from peclet.core.shares import run_shares
from peclet.core.geom.kernels import MAX_STACK, STACK_COLS, eval_point
from peclet.core.geom.pruning import pruned_range
from peclet.dem.distgrid import lower_bound
from peclet.dem.manifold import HIT_COLS, MAX_CLUSTERS, MAX_PER_TASK, reduce_hits, sort_hits
from peclet.dem.reuse import POSE, motion_bound, relative_pose, sort_list

#: Feature ids of the second direction (b's probes in a's tree) are offset by this.
FEATURE_DIR = 1 << 24
#: Smallest chunk of tasks a worker takes at a time; a large task list is cut into about
#: CHUNKS_PER_WORKER chunks per worker instead, so that each worker runs through long
#: contiguous stretches of the tasks and their slots (chunks of 8 on the 147,000 tasks of the
#: stirred column made the workers' strided walks through the slot buffers cost twice the
#: serial pass). The chunk size depends on the task count alone; every task writes only its
#: own slots, so no size changes a bit.
TASK_CHUNK = 8
CHUNKS_PER_WORKER = 4
#: From this many tasks the contacts are gathered in parallel (:func:`gather_parallel`), in
#: chunks of GATHER_CHUNK tasks; either way the same arrays.
PARALLEL_GATHER_TASKS = 20000
GATHER_CHUNK = 2048
#: Parallel workers (each takes every WORKERS-th chunk): enough to even out 2..16 threads.
WORKERS = 32


class Tasks(NamedTuple):
    """Candidate pairs: body ``a`` (T,), body ``b`` (T,) (a wall is -1 - index), the image
    ``shift`` (T, 3) added to b's position (periodic minimum image; zero for walls) and each
    pair's speculative ``margin`` (T,): its hits with a gap below it are kept."""
    a: np.ndarray
    b: np.ndarray
    shift: np.ndarray
    margin: np.ndarray


class Scratch(NamedTuple):
    """Per-worker scratch, kept between calls (an allocation per call and worker was a
    page-mapping system call each, which serialises the threads): ``hits`` (WORKERS, H,
    HIT_COLS), ``lab`` (WORKERS, H) with H >= the geometry's ``max_hits``, ``st`` (WORKERS,
    MAX_STACK, STACK_COLS) the evaluation stack."""
    hits: np.ndarray
    lab: np.ndarray
    st: np.ndarray


def scratch_for(max_hits):
    """A :class:`Scratch` for every worker, for tasks of at most ``max_hits`` hits."""
    return Scratch(np.empty((WORKERS, max_hits, HIT_COLS)), np.empty((WORKERS, max_hits),
                                                                       np.int64),
                   np.empty((WORKERS, MAX_STACK, STACK_COLS)))


class Slots(NamedTuple):
    """Output buffers: task t writes ``count[t]`` contacts from slot ``first[t]`` (room for
    :func:`slot_room` of them): ``point`` (S, 3) world, ``normal`` (S, 3) unit from b to a,
    ``gap`` (S,), ``feat`` (S,)."""
    count: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    gap: np.ndarray
    feat: np.ndarray
    first: np.ndarray


@njit(cache=True)
def slot_room(ta, tb, kind):
    """(T + 1,) each task's first slot (the last entry: the slots needed). A task with a
    sphere in it tests one point (the centre line, or the sphere's centre against a tree) and
    has at most one contact; any other at most MAX_PER_TASK. ``kind`` (N,) each body's shape
    kind (0: sphere). Packed this way the slots of a sphere bed are dense: the narrow phase
    writes, and the gather reads, consecutive rows rather than one row in MAX_PER_TASK."""
    ntask = ta.shape[0]
    first = np.empty(ntask + 1, np.int64)
    first[0] = 0
    for t in range(ntask):
        one = kind[ta[t]] == 0 or (tb[t] >= 0 and kind[tb[t]] == 0)
        first[t + 1] = first[t] + (1 if one else MAX_PER_TASK)
    return first


@njit(cache=True, inline="always")
def _point_vs_tree(px, py, pz, r, xt, Rt, prog, sgn, lip, trad, nsign, feat, margin, reach,
                   lk, lr, grid, goff, gdims, goh, st, hits, nh):
    """A point (a probe with r = 0, or a sphere's centre with its radius r) against a tree
    placed at xt with rotation Rt; ``sgn`` = -1 for an inverted wall; the tree's distance grid
    (``gdims[0]`` = 0: none) spares the evaluation of a point it proves out of reach. ``prog``:
    (ops, block ranges, first block, lattice (5,), lattice dims, whole program's first and end
    row), the tree's pruned programs (:mod:`peclet.core.geom.pruning`), evaluated with the one
    of the point's block: the same bits as the whole program, for less work.

    Appends at most one hit (phi < margin). Returns (nh, bound): a lower bound of phi at the
    point, +inf when it is beyond the tree's bounding sphere by more than ``reach`` (the
    culling threshold, >= margin), the grid's bound when that exceeds reach, else phi itself
    on a 1-Lipschitz tree (-inf on any other, or where phi is not a number)."""
    dx = px - xt[0]
    dy = py - xt[1]
    dz = pz - xt[2]
    qx = Rt[0, 0] * dx + Rt[1, 0] * dy + Rt[2, 0] * dz
    qy = Rt[0, 1] * dx + Rt[1, 1] * dy + Rt[2, 1] * dz
    qz = Rt[0, 2] * dx + Rt[1, 2] * dy + Rt[2, 2] * dz
    lim = trad + r + reach
    if qx * qx + qy * qy + qz * qz > lim * lim:
        return nh, np.inf
    low = lower_bound(grid, goff, gdims, goh, qx, qy, qz) - r
    if low > reach:
        return nh, low
    ops, blocks, boff, pob, pdims, f0, f1 = prog
    b0, b1 = pruned_range(blocks, boff, pob, pdims, f0, f1, qx, qy, qz)
    phi, gx, gy, gz = eval_point(ops, lk, lr, b0, b1, qx, qy, qz, st)
    phi = sgn * phi - r
    bound = phi if (lip and phi == phi) else -np.inf
    if not (phi < margin):
        return nh, bound
    nx = sgn * (Rt[0, 0] * gx + Rt[0, 1] * gy + Rt[0, 2] * gz)
    ny = sgn * (Rt[1, 0] * gx + Rt[1, 1] * gy + Rt[1, 2] * gz)
    nz = sgn * (Rt[2, 0] * gx + Rt[2, 1] * gy + Rt[2, 2] * gz)
    nn = math.sqrt(nx * nx + ny * ny + nz * nz)
    if not (nn > 0.0):
        return nh, bound
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
    return nh + 1, bound


@njit(cache=True, inline="always")
def _sphere_bound(xa, Ra, c, rad, xt, Rt, o0, o1, sgn, lip, trad, reach, ops, lk, lr,
                  grid, goff, gdims, goh, st):
    """A lower bound of the tree's (signed) phi at body a's home-frame point ``c``, the centre
    of a sphere of radius ``rad``: +inf (nothing evaluated) when the sphere lies beyond the
    tree's bounding sphere ``trad`` by more than ``reach``; on a 1-Lipschitz tree the
    distance grid's bound where it has one, else the value at c; otherwise -inf (no bound)."""
    cx = xa[0] + Ra[0, 0] * c[0] + Ra[0, 1] * c[1] + Ra[0, 2] * c[2]
    cy = xa[1] + Ra[1, 0] * c[0] + Ra[1, 1] * c[1] + Ra[1, 2] * c[2]
    cz = xa[2] + Ra[2, 0] * c[0] + Ra[2, 1] * c[1] + Ra[2, 2] * c[2]
    dx = cx - xt[0]
    dy = cy - xt[1]
    dz = cz - xt[2]
    lim = trad + rad + reach
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


@njit(cache=True, inline="always")
def _probe_world(xa, Ra, probes, p):
    """Probe ``p`` (home frame) of the body at xa with rotation Ra, in the world frame."""
    px = xa[0] + Ra[0, 0] * probes[p, 0] + Ra[0, 1] * probes[p, 1] + Ra[0, 2] * probes[p, 2]
    py = xa[1] + Ra[1, 0] * probes[p, 0] + Ra[1, 1] * probes[p, 1] + Ra[1, 2] * probes[p, 2]
    pz = xa[2] + Ra[2, 0] * probes[p, 0] + Ra[2, 1] * probes[p, 1] + Ra[2, 2] * probes[p, 2]
    return px, py, pz


@njit(cache=True, inline="always")
def _scan(xa, Ra, s, geo, zero, xt, Rt, prog, sgn, lip, trad, nsign, fbase, margin, reach,
          grid, goff, gdims, goh, st, hits, nh, live_p, live_b, lpos, lend):
    """Body a's shell probes (shape s, at xa with rotation Ra) against a tree, hits (phi <
    margin) in probe order; the probes that survive the culling at ``reach`` are listed from
    ``live_p[lpos]``/``live_b[lpos]`` (their bounds) while ``lpos < lend``. Returns (nh,
    lpos); lpos = lend + 1: the list overflowed. ``grid``, ``goff``, ``gdims``, ``goh``: the
    tree's distance grid (``gdims[0]`` = 0: none); ``zero`` the home-frame origin (3,).

    Culling, from coarse to fine, never drops a probe within reach (a 1-Lipschitz phi grows by
    at most the distance travelled): the whole shape when the bound at its centre exceeds its
    radius + reach; a super-cluster skipped without evaluation when that bound minus its offset
    does; a super-cluster or cluster whose bounding sphere is beyond the tree's bounding sphere,
    or on which phi's bound exceeds its radius + reach, is skipped; a cluster is skipped
    without evaluation when the super-cluster's value minus the cluster's offset already does;
    a probe is skipped when its cluster's value minus its offset exceeds reach. Non-Lipschitz
    trees get the sphere tests only."""
    shape_p0, probes, probe_off = geo.shape_p0, geo.probes, geo.probe_off
    cl_centre, cl_rad, cl_range = geo.cl_centre, geo.cl_rad, geo.cl_range
    gr_centre, gr_rad, gr_range = geo.gr_centre, geo.gr_rad, geo.gr_range
    gr_member, gr_off = geo.gr_member, geo.gr_off
    lk, lr = geo.lk, geo.lr
    ops, o0, o1 = prog[0], prog[5], prog[6]
    gr_dist = geo.gr_dist
    phr = _sphere_bound(xa, Ra, zero, geo.shape_rad[s], xt, Rt, o0, o1, sgn, lip, trad,
                        reach, ops, lk, lr, grid, goff, gdims, goh, st)
    if phr > geo.shape_rad[s] + reach:
        return nh, lpos
    n0 = nh
    for g in range(geo.shape_gr[s, 0], geo.shape_gr[s, 1]):
        if phr - gr_dist[g] > gr_rad[g] + reach:
            continue
        phg = _sphere_bound(xa, Ra, gr_centre[g], gr_rad[g], xt, Rt, o0, o1, sgn, lip, trad,
                            reach, ops, lk, lr, grid, goff, gdims, goh, st)
        if phg > gr_rad[g] + reach:
            continue
        for m in range(gr_range[g, 0], gr_range[g, 1]):
            c = gr_member[m]
            if phg - gr_off[m] > cl_rad[c] + reach:
                continue
            phc = _sphere_bound(xa, Ra, cl_centre[c], cl_rad[c], xt, Rt, o0, o1, sgn, lip,
                                trad, reach, ops, lk, lr, grid, goff, gdims, goh, st)
            if phc > cl_rad[c] + reach:
                continue
            for p in range(cl_range[c, 0], cl_range[c, 1]):
                if phc - probe_off[p] > reach:
                    continue
                px, py, pz = _probe_world(xa, Ra, probes, p)
                nh, low = _point_vs_tree(px, py, pz, 0.0, xt, Rt, prog, sgn, lip, trad,
                                         nsign, fbase + p - shape_p0[s], margin, reach, lk,
                                         lr, grid, goff, gdims, goh, st, hits, nh)
                if low < reach:
                    if lpos < lend:
                        live_p[lpos] = p
                        live_b[lpos] = low
                        lpos += 1
                    else:
                        lpos = lend + 1
    sort_hits(hits, n0, nh)
    return nh, lpos


@njit(cache=True, inline="always")
def _replay(xa, Ra, s, geo, xt, Rt, prog, sgn, lip, trad, nsign, fbase, margin, mu,
            grid, goff, gdims, goh, st, hits, nh, old_p, old_b, i0, n):
    """The probes listed at ``old_p[i0:i0 + n]`` (bounds ``old_b``) of body a against the
    tree, pose moved by at most ``mu`` since they were listed: a probe whose bound minus mu
    exceeds the margin is skipped, the others are tested as a scan tests them. Hits in probe
    order."""
    probes, p0 = geo.probes, geo.shape_p0[s]
    lk, lr = geo.lk, geo.lr
    n0 = nh
    for k in range(i0, i0 + n):
        if old_b[k] - mu > margin:
            continue
        p = old_p[k]
        px, py, pz = _probe_world(xa, Ra, probes, p)
        nh, low = _point_vs_tree(px, py, pz, 0.0, xt, Rt, prog, sgn, lip, trad, nsign,
                                 fbase + p - p0, margin, margin, lk, lr, grid, goff, gdims,
                                 goh, st, hits, nh)
    sort_hits(hits, n0, nh)
    return nh


@njit(cache=True)
def _direction(t, d, old_t, prev, cur, xa, Ra, s, so, geo, zero, tree, nsign, fbase, margin,
               delta, st, hits, nh, pose, lpos, lend):
    """Direction ``d`` of task ``t`` (body a's probes, shape ``s``, against the tree of shape
    or wall ``so``): the listed probes of last step's task ``old_t`` when the list is still
    valid (see :mod:`peclet.dem.reuse`), else a scan (listing its probes when ``delta`` >= 0).
    Records the direction in ``cur`` from ``lpos`` (< ``lend``). Returns (nh, lpos).
    ``tree``: (xt, Rt, prog, sgn, lip, trad, grid, goff, gdims, goh), the tree's placement,
    programs (see _point_vs_tree), sign, Lipschitz flag, bounding radius and distance grid, one
    tuple. Not inlined: its three inlined copies cost minutes of compilation for a few percent
    of run time."""
    xt, Rt, prog, sgn, lip, trad, grid, goff, gdims, goh = tree
    relative_pose(xa, Ra, xt, Rt, pose)
    ok = (old_t >= 0 and delta >= 0.0 and prev.count[old_t, d] >= 0
          and prev.shape[old_t, d, 0] == s and prev.shape[old_t, d, 1] == so)
    mu = np.inf
    if ok:
        mu = motion_bound(pose, prev.pose[old_t, d], geo.shape_rad[s], xa, xt)
        ok = margin + mu <= prev.reach[old_t, d]
    cur.shape[t, d, 0] = s
    cur.shape[t, d, 1] = so
    cur.start[t, d] = lpos
    if ok:
        i0 = prev.start[old_t, d]
        n = prev.count[old_t, d]
        nh = _replay(xa, Ra, s, geo, xt, Rt, prog, sgn, lip, trad, nsign, fbase, margin, mu,
                     grid, goff, gdims, goh, st, hits, nh, prev.probe, prev.bound, i0, n)
        if lpos + n <= lend:
            # carried over unchanged: the list stays that of its scan, with the scan's pose
            for k in range(n):
                cur.probe[lpos + k] = prev.probe[i0 + k]
                cur.bound[lpos + k] = prev.bound[i0 + k]
            for k in range(POSE):
                cur.pose[t, d, k] = prev.pose[old_t, d, k]
            cur.reach[t, d] = prev.reach[old_t, d]
            cur.count[t, d] = n
            return nh, lpos + n
        cur.count[t, d] = -1
        return nh, lend + 1
    reach = margin + delta if delta > 0.0 else margin
    nh, lp = _scan(xa, Ra, s, geo, zero, xt, Rt, prog, sgn, lip, trad, nsign, fbase, margin,
                   reach, grid, goff, gdims, goh, st, hits, nh, cur.probe, cur.bound, lpos,
                   lend if delta >= 0.0 else lpos)
    if delta < 0.0 or lp > lend:
        cur.count[t, d] = -1
        return nh, (lpos if delta < 0.0 else lend + 1)
    sort_list(cur.probe, cur.bound, lpos, lp)
    for k in range(POSE):
        cur.pose[t, d, k] = pose[k]
    cur.reach[t, d] = reach
    cur.count[t, d] = lp - lpos
    return nh, lp


@njit(cache=True, nogil=True)
def narrow_workers(first, step, nw, size, tasks, pos, rot, shape_of, geo, tol2, touch, slots,
                   delta, old, prev, cur, scratch):
    """Workers ``first``, ``first + step``, ... of ``nw`` (a share of
    :func:`peclet.core.shares.run_shares`). Worker ``worker`` takes the chunks worker,
    worker + nw, ... of ``size`` tasks (interleaved, so that the workers' loads even out);
    gathers each task's hits and reduces them into its own slots. ``old`` (T,): each task's
    index in ``prev`` (-1: none); the worker lists probes in its own share of ``cur``'s
    buffer and reports its use (or -1 on overflow) in ``cur.fill[worker]``. Its scratch is
    ``scratch``'s row ``worker``: a task's hit buffer is large enough for every probe of both
    bodies."""
    # the tables are taken out of the tuple once: a field read in the per-probe loop would
    # cost a reference-count update per read
    shape_kind, shape_rad, shape_lip = geo.shape_kind, geo.shape_rad, geo.shape_lip
    lk, lr = geo.lk, geo.lr
    ops, blocks, pboff, pob, pdims, sop = (geo.ops, geo.block_range, geo.shape_pboff,
                                           geo.shape_pob, geo.shape_pdims, geo.shape_op)
    grid, goff = geo.grid, geo.shape_grid_off
    gdims, goh = geo.shape_grid_dims, geo.shape_grid_oh
    nogrid = np.zeros(3, np.int64)
    reps = np.empty(MAX_CLUSTERS, np.int64)
    pose = np.empty(POSE)
    xb = np.empty(3)
    origin = np.zeros(3)
    nolattice = np.ones(5)
    # integer arguments as int64 values, never literals: Numba compiles a callee once per
    # literal value (and per tuple type), and each copy of _direction costs ~20 s of a cold
    # first run (docs/architecture.md §7)
    zero_i = np.int64(0)
    one_i = np.int64(1)
    feat_dir = np.int64(FEATURE_DIR)
    share = cur.probe.shape[0] // nw
    ntask = tasks.a.shape[0]
    nchunk = (ntask + size - 1) // size
    for worker in range(first, nw, step):
        st = scratch.st[worker]
        hits = scratch.hits[worker]
        lab = scratch.lab[worker]
        lpos = worker * share
        lend = lpos + share
        for ch in range(worker, nchunk, nw):
            for t in range(ch * size, min(ntask, (ch + 1) * size)):
                a = tasks.a[t]
                b = tasks.b[t]
                margin = tasks.margin[t]
                sa = shape_of[a]
                nh = zero_i
                if b >= 0 and shape_kind[sa] == 0 and shape_kind[shape_of[b]] == 0:
                    # two spheres: the centre line, read straight from the arrays (the views and
                    # program tuples of the other cases cost more than this whole test)
                    sb = shape_of[b]
                    dx = pos[a, 0] - (pos[b, 0] + tasks.shift[t, 0])
                    dy = pos[a, 1] - (pos[b, 1] + tasks.shift[t, 1])
                    dz = pos[a, 2] - (pos[b, 2] + tasks.shift[t, 2])
                    dist = math.sqrt(dx * dx + dy * dy + dz * dz)
                    gap = dist - shape_rad[sa] - shape_rad[sb]
                    # at most one hit, written straight into the task's slot (what the manifold
                    # reduction makes of a single hit)
                    slots.count[t] = 0
                    if gap < margin:
                        if dist > 0.0:
                            nx = dx / dist
                            ny = dy / dist
                            nz = dz / dist
                        else:
                            nx, ny, nz = 0.0, 1.0, 0.0
                        h = shape_rad[sa] + 0.5 * gap
                        o = slots.first[t]
                        slots.point[o, 0] = pos[a, 0] - h * nx
                        slots.point[o, 1] = pos[a, 1] - h * ny
                        slots.point[o, 2] = pos[a, 2] - h * nz
                        slots.normal[o, 0] = nx
                        slots.normal[o, 1] = ny
                        slots.normal[o, 2] = nz
                        slots.gap[o] = gap
                        slots.feat[o] = 0
                        slots.count[t] = 1
                    continue
                xa = pos[a]
                Ra = rot[a]
                ot = old[t]
                if b >= 0:
                    sb = shape_of[b]
                    for e in range(3):
                        xb[e] = pos[b, e] + tasks.shift[t, e]
                    Rb = rot[b]
                    prog_a = (ops, blocks, pboff[sa], pob[sa], pdims[sa], sop[sa, 0],
                              sop[sa, 1])
                    prog_b = (ops, blocks, pboff[sb], pob[sb], pdims[sb], sop[sb, 0],
                              sop[sb, 1])
                    if shape_kind[sa] == 0:
                        nh, _ = _point_vs_tree(xa[0], xa[1], xa[2], shape_rad[sa], xb, Rb,
                                               prog_b, 1.0, shape_lip[sb], shape_rad[sb], 1.0,
                                               zero_i, margin, margin, lk, lr, grid, goff[sb],
                                               gdims[sb], goh[sb], st, hits, nh)
                    elif shape_kind[sb] == 0:
                        nh, _ = _point_vs_tree(xb[0], xb[1], xb[2], shape_rad[sb], xa, Ra,
                                               prog_a, 1.0, shape_lip[sa], shape_rad[sa], -1.0,
                                               feat_dir, margin, margin, lk, lr, grid, goff[sa],
                                               gdims[sa], goh[sa], st, hits, nh)
                    else:
                        # both ways: a's probes in b's tree, then b's probes in a's tree
                        tree = (xb, Rb, prog_b, 1.0, shape_lip[sb], shape_rad[sb], grid,
                                goff[sb], gdims[sb], goh[sb])
                        nh, lpos = _direction(t, zero_i, ot, prev, cur, xa, Ra, sa, sb, geo,
                                              origin, tree, 1.0, zero_i, margin, delta, st,
                                              hits, nh, pose, lpos, lend)
                        tree = (xa, Ra, prog_a, 1.0, shape_lip[sa], shape_rad[sa], grid,
                                goff[sa], gdims[sa], goh[sa])
                        nh, lpos = _direction(t, one_i, ot, prev, cur, xb, Rb, sb, sa, geo,
                                              origin, tree, -1.0, feat_dir, margin, delta, st,
                                              hits, nh, pose, lpos, lend)
                else:
                    w = -1 - b
                    # a wall has no lattice: its whole program
                    prog_w = (ops, blocks, zero_i, nolattice, nogrid, geo.wall_op[w, 0],
                              geo.wall_op[w, 1])
                    # the wall at its pose (identity for a wall that never moved)
                    xw = geo.wall_pos[w]
                    Rw = geo.wall_rot[w]
                    # its distance grid (of the signed field; dims 0: none) bounds it cheaply
                    wgo, wgd = geo.wall_grid_off[w], geo.wall_grid_dims[w]
                    wgh = geo.wall_grid_oh[w]
                    if shape_kind[sa] == 0:
                        nh, _ = _point_vs_tree(xa[0], xa[1], xa[2], shape_rad[sa], xw, Rw,
                                               prog_w, geo.wall_sign[w], geo.wall_lip[w], np.inf,
                                               1.0, zero_i, margin, margin, lk, lr, grid, wgo,
                                               wgd, wgh, st, hits, nh)
                    else:
                        tree = (xw, Rw, prog_w, geo.wall_sign[w], geo.wall_lip[w], np.inf,
                                grid, wgo, wgd, wgh)
                        nh, lpos = _direction(t, zero_i, ot, prev, cur, xa, Ra, sa, b, geo,
                                              origin, tree, 1.0, zero_i, margin, delta, st,
                                              hits, nh, pose, lpos, lend)
                slots.count[t] = reduce_hits(hits, nh, lab, reps, tol2, touch, slots.first[t],
                                             slots.point, slots.normal, slots.gap, slots.feat)
        cur.fill[worker] = lpos - worker * share if lpos <= lend else -1


def narrow_phase(tasks, pos, rot, shape_of, geo, tol2, touch, chunks, slots, delta, old, prev,
                 cur, scratch):
    """Contacts of every task into its own slots (from ``slots.first[t]``, at most
    :func:`slot_room`'s room); ``slots.count[t]`` = used.

    ``tasks`` a :class:`Tasks`; ``pos`` (N, 3) and ``rot`` (N, 3, 3) the bodies' centres and
    home -> world rotations, ``shape_of`` (N,) their shape ids; ``geo`` the
    :class:`peclet.dem.shapes.Geometry`; hits within the task's margin are kept; ``tol2``
    and ``touch`` tune the manifold reduction; ``slots`` a :class:`Slots`. Reuse between steps
    (:mod:`peclet.dem.reuse`): ``old`` (T,) each task's index in ``prev`` (last step's
    :class:`peclet.dem.reuse.ReuseCache`, -1: none), ``cur`` this step's (filled here),
    ``delta`` the scans' extra reach (< 0: nothing listed, every direction scanned).
    ``scratch``: a :class:`Scratch` for at least ``geo.max_hits`` hits.
    ``chunks`` = 1 runs serially in the calling thread (small problems, where a parallel launch
    costs more than it saves), otherwise WORKERS workers, each taking every WORKERS-th chunk
    of tasks (TASK_CHUNK, or about CHUNKS_PER_WORKER chunks per worker on a large task list),
    are dealt to the threads (:func:`peclet.core.shares.run_shares`). Either way every task
    writes only its own slots, and its hits are those of a scan, so the result is identical."""
    nw = WORKERS if chunks > 1 else 1
    cur.fill[nw:] = 0
    size = max(TASK_CHUNK, tasks.a.shape[0] // (WORKERS * CHUNKS_PER_WORKER))
    run_shares(narrow_workers, nw, nw, size, tasks, pos, rot, shape_of, geo, tol2, touch, slots,
               delta, old, prev, cur, scratch)


@njit(cache=True)
def gather(tasks, slots):
    """The contacts of :func:`narrow_phase` packed in task order: (a, b, shift (n, 3), point
    (n, 3), normal (n, 3), gap, feat), one row per used slot."""
    ntask = tasks.a.shape[0]
    first = np.empty(ntask + 1, np.int64)
    first[0] = 0
    for t in range(ntask):
        first[t + 1] = first[t] + slots.count[t]
    out = _gather_arrays(first[ntask])
    _gather_tasks(0, ntask, tasks, slots, first, *out)
    return out


@njit(cache=True, parallel=True)
def gather_parallel(tasks, slots):
    """:func:`gather` with the tasks dealt in chunks to parallel workers: each row is written
    by the one task it comes from, so the arrays are the same, bit for bit."""
    ntask = tasks.a.shape[0]
    first = np.empty(ntask + 1, np.int64)
    first[0] = 0
    for t in range(ntask):
        first[t + 1] = first[t] + slots.count[t]
    a, b, shift, point, normal, gap, feat = _gather_arrays(first[ntask])
    for ch in prange((ntask + GATHER_CHUNK - 1) // GATHER_CHUNK):
        _gather_tasks(ch * GATHER_CHUNK, min(ntask, (ch + 1) * GATHER_CHUNK), tasks, slots,
                      first, a, b, shift, point, normal, gap, feat)
    return a, b, shift, point, normal, gap, feat


@njit(cache=True)
def _gather_arrays(total):
    return (np.empty(total, np.int64), np.empty(total, np.int64), np.empty((total, 3)),
            np.empty((total, 3)), np.empty((total, 3)), np.empty(total),
            np.empty(total, np.int64))


@njit(cache=True)
def _gather_tasks(t0, t1, tasks, slots, first, a, b, shift, point, normal, gap, feat):
    """Tasks t0..t1-1: their used slots into rows from ``first[t]``."""
    for t in range(t0, t1):
        k = first[t]
        for u in range(slots.count[t]):
            o = slots.first[t] + u
            a[k] = tasks.a[t]
            b[k] = tasks.b[t]
            for e in range(3):
                shift[k, e] = tasks.shift[t, e]
                point[k, e] = slots.point[o, e]
                normal[k, e] = slots.normal[o, e]
            gap[k] = slots.gap[o]
            feat[k] = slots.feat[o]
            k += 1
