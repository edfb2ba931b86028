"""A body's shell probes against a tree: the narrow phase's inner kernels (the culling, the
replay of a kept probe list and the choice between them: docstring of
:mod:`peclet.dem.narrowphase`).

The kernels take their arguments bundled: :class:`Tree` (the tree tested, placed, with its
programs, sign, bounding radius and distance grid), :class:`Probing` (the body whose probes are
tested, and the direction's sign and feature ids), :class:`Worker` (a worker's own buffers) and
:class:`ReuseStep` (this step's probe lists, :mod:`peclet.dem.reuse`). The narrow phase's worker
builds a task's trees and probing sides (:func:`body_tree`, :func:`wall_tree`; values and views,
no allocation) and its :class:`Worker` once per worker; the step's :class:`ReuseStep` is built
once per step."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from peclet.core.geom.kernels import eval_point
from peclet.core.geom.pruning import pruned_range
from peclet.dem.distgrid import lower_bound
from peclet.dem.manifold import sort_hits
from peclet.dem.reuse import POSE, ReuseCache, motion_bound, relative_pose, sort_list
from peclet.dem.treeframe import to_home, world_normal


class Tree(NamedTuple):
    """A tree as the narrow phase tests it: placed at ``x`` (3,) with rotation ``R`` (3, 3)
    (home -> world); its program tables ``ops``, ``lk``, ``lr``; its pruned programs
    (:mod:`peclet.core.geom.pruning`): ``blocks`` (B, 2) each block's rows, ``boff`` its first
    block, ``pob`` (5,) its lattice (origin, block, 1/block) and ``pdims`` (3,) blocks per axis
    (0: no lattice, a wall), and [``o0``, ``o1``) its whole program's rows; ``sgn`` its sign
    (-1 for an inverted wall), ``lip`` whether phi is 1-Lipschitz, ``rad`` its bounding radius
    about ``x`` (inf for a wall); its distance grid in ``grid`` from ``goff`` with ``gdims``
    (3,) (0: none) and ``goh`` (4,) (origin, h), home frame; ``key`` its shape id (a wall:
    -1 - index), what a probe list is tied to. Home-frame lengths."""
    x: np.ndarray
    R: np.ndarray
    ops: np.ndarray
    lk: np.ndarray
    lr: np.ndarray
    blocks: np.ndarray
    boff: np.int64
    pob: np.ndarray
    pdims: np.ndarray
    o0: np.int64
    o1: np.int64
    sgn: float
    lip: bool
    rad: float
    grid: np.ndarray
    goff: np.int64
    gdims: np.ndarray
    goh: np.ndarray
    key: np.int64


class Probing(NamedTuple):
    """The probing side of a direction: direction ``d`` (0: a's probes in b's tree, 1: b's in
    a's), the body's position ``x`` (3,), rotation ``R`` (3, 3) (home -> world) and shape
    ``s``; ``nsign`` the sign that turns the tree's outward normal into the stored one (from b
    to a: +1 in direction 0, -1 in direction 1) and ``fbase`` added to a probe's index within
    its shape to make its feature id."""
    d: np.int64
    x: np.ndarray
    R: np.ndarray
    s: np.int64
    nsign: float
    fbase: np.int64


class Worker(NamedTuple):
    """A worker's own buffers: the evaluation stack ``st`` (MAX_STACK, STACK_COLS), the hit
    buffer ``hits`` (H, HIT_COLS), ``origin`` (3,) zeros (the home-frame origin), ``pose``
    (POSE,) a direction's relative pose, and ``lend`` the end of its share of the probe lists'
    buffer."""
    st: np.ndarray
    hits: np.ndarray
    origin: np.ndarray
    pose: np.ndarray
    lend: np.int64


class ReuseStep(NamedTuple):
    """This step's probe lists (:mod:`peclet.dem.reuse`): ``old`` (T,) each task's index in
    ``prev`` (last step's :class:`~peclet.dem.reuse.ReuseCache`, -1: none), ``cur`` this
    step's (filled by the narrow phase) and ``delta`` the scans' extra reach (length; < 0:
    nothing listed, every direction scanned)."""
    old: np.ndarray
    prev: ReuseCache
    cur: ReuseCache
    delta: float


@njit(cache=True, inline="always")
def body_tree(geo, x, R, s):
    """The :class:`Tree` of shape ``s`` (a composed one) of the
    :class:`peclet.dem.shapes.Geometry` ``geo``, placed at ``x`` with rotation ``R``."""
    return Tree(x, R, geo.ops, geo.lk, geo.lr, geo.block_range, geo.shape_pboff[s],
                geo.shape_pob[s], geo.shape_pdims[s], geo.shape_op[s, 0], geo.shape_op[s, 1],
                1.0, geo.shape_lip[s], geo.shape_rad[s], geo.grid, geo.shape_grid_off[s],
                geo.shape_grid_dims[s], geo.shape_grid_oh[s], s)


@njit(cache=True, inline="always")
def wall_tree(geo, b, nolattice, nogrid):
    """The :class:`Tree` of wall ``-1 - b`` at its pose (identity for a wall that never
    moved): a wall has no lattice (``nolattice`` (5,) ones, ``nogrid`` (3,) zeros: its whole
    program) and its distance grid is of its signed field (dims 0: none)."""
    w = -1 - b
    return Tree(geo.wall_pos[w], geo.wall_rot[w], geo.ops, geo.lk, geo.lr, geo.block_range,
                np.int64(0), nolattice, nogrid, geo.wall_op[w, 0], geo.wall_op[w, 1],
                geo.wall_sign[w], geo.wall_lip[w], np.inf, geo.grid, geo.wall_grid_off[w],
                geo.wall_grid_dims[w], geo.wall_grid_oh[w], b)


@njit(cache=True, inline="always")
def point_vs_tree(px, py, pz, r, tree, nsign, feat, margin, reach, st, hits, nh):
    """A point (a probe with r = 0, or a sphere's centre with its radius r) against a
    :class:`Tree`; the tree's distance grid spares the evaluation of a point it proves out of
    reach, and the program evaluated is the pruned one of the point's block (the same bits as
    the whole program, for less work).

    Appends at most one hit (phi < margin; its normal times ``nsign``, its feature ``feat``).
    Returns (nh, bound): a lower bound of phi at the point, +inf when it is beyond the tree's
    bounding sphere by more than ``reach`` (the culling threshold, >= margin), the grid's bound
    when that exceeds reach, else phi itself on a 1-Lipschitz tree (-inf on any other, or where
    phi is not a number)."""
    xt, Rt = tree.x, tree.R
    qx, qy, qz = to_home(Rt, px - xt[0], py - xt[1], pz - xt[2])
    lim = tree.rad + r + reach
    if qx * qx + qy * qy + qz * qz > lim * lim:
        return nh, np.inf
    low = lower_bound(tree.grid, tree.goff, tree.gdims, tree.goh, qx, qy, qz) - r
    if low > reach:
        return nh, low
    b0, b1 = pruned_range(tree.blocks, tree.boff, tree.pob, tree.pdims, tree.o0, tree.o1, qx,
                          qy, qz)
    phi, gx, gy, gz = eval_point(tree.ops, tree.lk, tree.lr, b0, b1, qx, qy, qz, st)
    sgn = tree.sgn
    phi = sgn * phi - r
    bound = phi if (tree.lip and phi == phi) else -np.inf
    if not (phi < margin):
        return nh, bound
    nx, ny, nz, nn = world_normal(Rt, sgn, gx, gy, gz)
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
def sphere_bound(xa, Ra, c, rad, tree, reach, st):
    """A lower bound of the :class:`Tree`'s (signed) phi at body a's home-frame point ``c``
    (a at ``xa`` with rotation ``Ra``), the centre of a sphere of radius ``rad``: +inf (nothing
    evaluated) when the sphere lies beyond the tree's bounding sphere by more than ``reach``;
    on a 1-Lipschitz tree the distance grid's bound where it has one, else the value at c;
    otherwise -inf (no bound)."""
    cx = xa[0] + Ra[0, 0] * c[0] + Ra[0, 1] * c[1] + Ra[0, 2] * c[2]
    cy = xa[1] + Ra[1, 0] * c[0] + Ra[1, 1] * c[1] + Ra[1, 2] * c[2]
    cz = xa[2] + Ra[2, 0] * c[0] + Ra[2, 1] * c[1] + Ra[2, 2] * c[2]
    xt = tree.x
    dx = cx - xt[0]
    dy = cy - xt[1]
    dz = cz - xt[2]
    lim = tree.rad + rad + reach
    if dx * dx + dy * dy + dz * dz > lim * lim:
        return np.inf
    if not tree.lip:
        return -np.inf
    qx, qy, qz = to_home(tree.R, dx, dy, dz)
    if tree.gdims[0] > 0:
        return lower_bound(tree.grid, tree.goff, tree.gdims, tree.goh, qx, qy, qz)
    return tree.sgn * eval_point(tree.ops, tree.lk, tree.lr, tree.o0, tree.o1, qx, qy, qz,
                                 st)[0]


@njit(cache=True, inline="always")
def level_bound(xa, Ra, above, centre, rad, tree, reach, st):
    """A lower bound of the tree's phi on a super-cluster's or cluster's bounding sphere
    (``centre`` in body a's home frame, radius ``rad``): +inf, nothing evaluated, when
    ``above`` (the enclosing level's bound less the sphere's offset) already exceeds rad +
    reach, else :func:`sphere_bound`. The level is skipped when this exceeds rad + reach."""
    if above > rad + reach:
        return np.inf
    return sphere_bound(xa, Ra, centre, rad, tree, reach, st)


@njit(cache=True, inline="always")
def probe_world(xa, Ra, probes, p):
    """Probe ``p`` (home frame) of the body at xa with rotation Ra, in the world frame."""
    px = xa[0] + Ra[0, 0] * probes[p, 0] + Ra[0, 1] * probes[p, 1] + Ra[0, 2] * probes[p, 2]
    py = xa[1] + Ra[1, 0] * probes[p, 0] + Ra[1, 1] * probes[p, 1] + Ra[1, 2] * probes[p, 2]
    pz = xa[2] + Ra[2, 0] * probes[p, 0] + Ra[2, 1] * probes[p, 1] + Ra[2, 2] * probes[p, 2]
    return px, py, pz


@njit(cache=True, inline="always")
def scan(probing, geo, tree, margin, reach, worker, nh, live_p, live_b, lpos, lend):
    """The shell probes of the :class:`Probing` side against the :class:`Tree`, hits (phi <
    margin) in probe order into ``worker.hits`` from ``nh``; the probes that survive the
    culling at ``reach`` are listed from ``live_p[lpos]``/``live_b[lpos]`` (their bounds)
    while ``lpos < lend``. Returns (nh, lpos); lpos = lend + 1: the list overflowed. ``geo``:
    the :class:`peclet.dem.shapes.Geometry` (the probes and their clusters).

    Culling, from coarse to fine, never drops a probe within reach (a 1-Lipschitz phi grows by
    at most the distance travelled): the whole shape when the bound at its centre exceeds its
    radius + reach; a super-cluster skipped without evaluation when that bound minus its offset
    does; a super-cluster or cluster whose bounding sphere is beyond the tree's bounding sphere,
    or on which phi's bound exceeds its radius + reach, is skipped; a cluster is skipped
    without evaluation when the super-cluster's value minus the cluster's offset already does;
    a probe is skipped when its cluster's value minus its offset exceeds reach. Non-Lipschitz
    trees get the sphere tests only."""
    xa, Ra, s, nsign, fbase = probing.x, probing.R, probing.s, probing.nsign, probing.fbase
    st, hits = worker.st, worker.hits
    shape_p0, probes, probe_off = geo.shape_p0, geo.probes, geo.probe_off
    cl_centre, cl_rad, cl_range = geo.cl_centre, geo.cl_rad, geo.cl_range
    gr_centre, gr_rad, gr_range = geo.gr_centre, geo.gr_rad, geo.gr_range
    gr_member, gr_off = geo.gr_member, geo.gr_off
    gr_dist = geo.gr_dist
    phr = sphere_bound(xa, Ra, worker.origin, geo.shape_rad[s], tree, reach, st)
    if phr > geo.shape_rad[s] + reach:
        return nh, lpos
    n0 = nh
    for g in range(geo.shape_gr[s, 0], geo.shape_gr[s, 1]):
        phg = level_bound(xa, Ra, phr - gr_dist[g], gr_centre[g], gr_rad[g], tree, reach, st)
        if phg > gr_rad[g] + reach:
            continue
        for m in range(gr_range[g, 0], gr_range[g, 1]):
            c = gr_member[m]
            phc = level_bound(xa, Ra, phg - gr_off[m], cl_centre[c], cl_rad[c], tree, reach,
                              st)
            if phc > cl_rad[c] + reach:
                continue
            for p in range(cl_range[c, 0], cl_range[c, 1]):
                if phc - probe_off[p] > reach:
                    continue
                px, py, pz = probe_world(xa, Ra, probes, p)
                nh, low = point_vs_tree(px, py, pz, 0.0, tree, nsign, fbase + p - shape_p0[s],
                                        margin, reach, st, hits, nh)
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
def replay(probing, geo, tree, margin, mu, worker, nh, old_p, old_b, i0, n):
    """The probes listed at ``old_p[i0:i0 + n]`` (bounds ``old_b``) of the :class:`Probing`
    side against the :class:`Tree`, pose moved by at most ``mu`` since they were listed: a
    probe whose bound minus mu exceeds the margin is skipped, the others are tested as a scan
    tests them. Hits in probe order."""
    xa, Ra, nsign, fbase = probing.x, probing.R, probing.nsign, probing.fbase
    st, hits = worker.st, worker.hits
    probes, p0 = geo.probes, geo.shape_p0[probing.s]
    n0 = nh
    for k in range(i0, i0 + n):
        if old_b[k] - mu > margin:
            continue
        p = old_p[k]
        px, py, pz = probe_world(xa, Ra, probes, p)
        nh, low = point_vs_tree(px, py, pz, 0.0, tree, nsign, fbase + p - p0, margin, margin,
                                st, hits, nh)
    sort_hits(hits, n0, nh)
    return nh


@njit(cache=True)
def direction(t, geo, reuse, worker, probing, tree, margin, nh, lpos):
    """Direction ``probing.d`` of task ``t`` (the :class:`Probing` side's probes against the
    :class:`Tree`): the listed probes of last step's task ``reuse.old[t]`` when the list is
    still valid (see :mod:`peclet.dem.reuse`), else a scan (listing its probes when
    ``reuse.delta`` >= 0). Records the direction in ``reuse.cur`` from ``lpos`` (<
    ``worker.lend``). Returns (nh, lpos). Not inlined: its three inlined copies cost minutes of
    compilation for a few percent of run time."""
    prev, cur, delta, old_t = reuse.prev, reuse.cur, reuse.delta, reuse.old[t]
    d, xa, s, so = probing.d, probing.x, probing.s, tree.key
    pose, lend = worker.pose, worker.lend
    relative_pose(xa, probing.R, tree.x, tree.R, pose)
    ok = (old_t >= 0 and delta >= 0.0 and prev.count[old_t, d] >= 0
          and prev.shape[old_t, d, 0] == s and prev.shape[old_t, d, 1] == so)
    mu = np.inf
    if ok:
        mu = motion_bound(pose, prev.pose[old_t, d], geo.shape_rad[s], xa, tree.x)
        ok = margin + mu <= prev.reach[old_t, d]
    cur.shape[t, d, 0] = s
    cur.shape[t, d, 1] = so
    cur.start[t, d] = lpos
    if ok:
        i0 = prev.start[old_t, d]
        n = prev.count[old_t, d]
        nh = replay(probing, geo, tree, margin, mu, worker, nh, prev.probe, prev.bound, i0, n)
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
    nh, lp = scan(probing, geo, tree, margin, reach, worker, nh, cur.probe, cur.bound, lpos,
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
