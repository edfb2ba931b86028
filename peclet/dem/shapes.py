"""Particle shapes, static walls, and the flat geometry tables the contact kernels read.

A shape is a :class:`SphereShape` (exact sphere-sphere / sphere-tree paths) or a
:class:`SceneShape` (a composed CSG tree given in the body's home frame -- centre of mass at the
origin, principal axes on x, y, z -- with surface probes in the same frame). A :class:`Wall` is a
static CSG tree in the world frame; ``invert`` makes its complement the solid (a container).
Trees follow the geometry core: phi < 0 inside, gradient outward.

:func:`build_geometry` concatenates every shape's and wall's compiled program into one flat
:class:`Geometry` (a NamedTuple of arrays, which Numba kernels take as one argument): per-shape
rows, the probes grouped in voxel clusters with a bounding sphere, and per-wall rows.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from peclet.core.geom import SceneBuilder
from peclet.core.geom.program import compile_root, concatenate
from peclet.core.geom.pruning import bake_pruned, concatenate_pruned
from peclet.dem import distgrid
from peclet.dem.limits import check_length, check_size_ratio
from peclet.core.validation import (PecletArgumentError, check_array, check_bool,
                                    check_float, check_int)

#: ``Geometry.shape_kind`` values.
SPHERE, SCENE = 0, 1

#: Probe clusters are voxels of this fraction of the shape's bounding radius.
CLUSTER_CELL_FRACTION = 0.25
#: Clusters are grouped in super-clusters: voxels of this many cluster cells a side.
GROUP_CELLS = 2
#: The pruned programs' blocks are this many distance-grid cells a side (2 cells: near the
#: surface of a Pall ring ~2 of its 11 leaves remain, for 0.6 MB; see benchmarks/bench_pruning).
PRUNE_BLOCK_CELLS = 2


class SphereShape(NamedTuple):
    """A sphere of ``radius`` about the body's centre of mass."""
    radius: float


class SceneShape(NamedTuple):
    """A composed CSG particle: the flat tree (``node_ints`` (n, 3), ``node_reals`` (n, 16)),
    its ``root`` node, surface ``shell`` probes (M, 3) in the home frame, the bounding radius
    about the origin, the compiled program, whether phi is 1-Lipschitz (cluster culling),
    for a 1-Lipschitz tree its :mod:`peclet.dem.distgrid` (``grid`` values, ``grid_dims`` (3,),
    ``grid_oh`` (origin, h); dims 0 = none), and its ``pruned`` programs
    (:mod:`peclet.core.geom.pruning`, bit for bit the program's values, block by block)."""
    radius: float
    shell: np.ndarray
    node_ints: np.ndarray
    node_reals: np.ndarray
    root: int
    program: tuple
    lip: bool
    grid: np.ndarray
    grid_dims: np.ndarray
    grid_oh: np.ndarray
    pruned: tuple


class Wall(NamedTuple):
    """A static solid in the world frame; restitution ``e`` in [0, 1], friction ``mu`` >= 0."""
    node_ints: np.ndarray
    node_reals: np.ndarray
    root: int
    invert: bool
    e: float
    mu: float
    program: tuple
    lip: bool


class Geometry(NamedTuple):
    """Flat tables of all shapes (rows by shape id) and walls (rows by wall index).

    ``ops`` (with ``lk``/``lr``, the leaf tables): every tree's whole program and its pruned
    programs (:func:`peclet.core.geom.pruning.concatenate_pruned`); ``shape_op`` / ``wall_op``
    (k, 2): the [start, end) rows of the whole program in ``ops`` (-1 for a sphere);
    ``block_range`` (B, 2) the rows of each block's pruned program, and per shape
    ``shape_pboff`` (its first block), ``shape_pob`` (k, 5) (lattice origin, block, 1/block)
    and ``shape_pdims`` (k, 3) (blocks per axis; 0: no lattice, as for walls); ``shape_p0``: first probe of the shape; ``shape_cl`` (k, 2): its
    [start, end) cluster range; ``cl_range`` (C, 2): a cluster's [start, end) probe range;
    ``probe_off`` (M,): a probe's distance from its cluster's centre (rounded up);
    ``shape_gr`` (k, 2): the shape's [start, end) super-cluster range; ``gr_centre`` (G, 3),
    ``gr_rad`` (G,): a super-cluster's bounding sphere (containing its clusters' spheres),
    ``gr_dist`` (G,) its centre's distance from the shape's origin (rounded up);
    ``gr_range`` (G, 2): its [start, end) range in ``gr_member`` (cluster ids) and ``gr_off``
    (a member cluster's centre distance from the super-cluster's centre, rounded up);
    ``grid`` the shapes' distance grids concatenated, shape k's from ``shape_grid_off[k]``
    with ``shape_grid_dims`` (k, 3) (0 = none) and ``shape_grid_oh`` (k, 4) (origin, h);
    ``wall_sign`` -1 for an inverted wall; ``wall_pos`` (W, 3) / ``wall_rot`` (W, 3, 3) each
    wall's pose (tree -> world: p = R p_tree + t), filled in place from
    :class:`peclet.dem.wallmotion.WallMotion` before every detection (identity for a wall that
    never moved), so that the geometry keeps its identity (the probe-list reuse is tied to it);
    ``max_hits``: a task's hit buffer size; ``wall_grid_off`` (W,), ``wall_grid_dims``
    (W, 3) (0 = none) and ``wall_grid_oh`` (W, 4): each wall's distance grid of its signed
    field in ``grid``, in the wall's own frame (none as built; a detection of many bodies
    adds them, :func:`peclet.dem.distgrid.with_wall_grids`).
    All home-frame lengths; the bounds are inflated by a relative 1e-12 (+ 1e-15) so that a
    round-off never makes a culled sphere miss a point it contains."""
    shape_kind: np.ndarray
    shape_rad: np.ndarray
    shape_op: np.ndarray
    shape_lip: np.ndarray
    shape_p0: np.ndarray
    shape_cl: np.ndarray
    cl_centre: np.ndarray
    cl_rad: np.ndarray
    cl_range: np.ndarray
    probes: np.ndarray
    probe_off: np.ndarray
    shape_gr: np.ndarray
    gr_centre: np.ndarray
    gr_rad: np.ndarray
    gr_dist: np.ndarray
    gr_range: np.ndarray
    gr_member: np.ndarray
    gr_off: np.ndarray
    grid: np.ndarray
    shape_grid_off: np.ndarray
    shape_grid_dims: np.ndarray
    shape_grid_oh: np.ndarray
    wall_op: np.ndarray
    wall_sign: np.ndarray
    wall_lip: np.ndarray
    wall_e: np.ndarray
    wall_mu: np.ndarray
    wall_pos: np.ndarray
    wall_rot: np.ndarray
    ops: np.ndarray
    lk: np.ndarray
    lr: np.ndarray
    block_range: np.ndarray
    shape_pboff: np.ndarray
    shape_pob: np.ndarray
    shape_pdims: np.ndarray
    max_hits: int
    wall_grid_off: np.ndarray
    wall_grid_dims: np.ndarray
    wall_grid_oh: np.ndarray


def _tree(node_ints, node_reals, root):
    # a validated copy of the flat tree and its root
    b = SceneBuilder.decode(node_ints, node_reals)
    root = check_int("root", root, 0, b.num_nodes() - 1)
    ni, nr = b.node_arrays()
    return b, np.asarray(ni), np.asarray(nr, dtype=np.float64), root


def sphere_shape(radius):
    """A validated :class:`SphereShape` (``radius`` in [1e-100, 1e100], length;
    :mod:`peclet.dem.limits`)."""
    return SphereShape(check_length("radius", check_float("radius", radius, 0.0, lo_open=True)))


def scene_shape(node_ints, node_reals, root, shell_points, bounding_radius, radii_in_use=None):
    """A validated :class:`SceneShape`; the bounding radius is raised to the farthest probe
    and must then lie in [1e-100, 1e100] (length; :mod:`peclet.dem.limits`) and, given the
    bounding radii already ``radii_in_use``, within a factor 1e6 of them, checked before the
    shape's grids are built."""
    b, ni, nr, root = _tree(node_ints, node_reals, root)
    shell = check_array("shell_points", shell_points, (None, 3))
    if len(shell) == 0:
        raise PecletArgumentError("shell_points", "an array of shape (M, 3) with M >= 1",
                                  shell_points)
    br = check_float("bounding_radius", bounding_radius, 0.0, lo_open=True)
    far = float(np.hypot(np.hypot(shell[:, 0], shell[:, 1]), shell[:, 2]).max())
    br = check_length("bounding_radius", max(br, far))   # raised to the farthest probe
    if radii_in_use is not None:
        check_size_ratio("bounding_radius", br, radii_in_use)
    prog = compile_root(ni, nr, root)
    lip = bool(b.is_lipschitz(root))
    if lip:
        grid, dims, oh = distgrid.bake(prog, br)
    else:
        grid, dims, oh = np.zeros(0), np.zeros(3, np.int64), np.ones(4)
    origin, h, cells = distgrid.lattice(br)
    nb = -(-cells // PRUNE_BLOCK_CELLS)
    pruned = bake_pruned(prog, origin, PRUNE_BLOCK_CELLS * h, (nb, nb, nb))
    return SceneShape(br, shell.copy(), ni, nr, root, prog, lip, grid, dims, oh, pruned)


def analytic_wall(node_ints, node_reals, root, invert, e_n, mu):
    """A validated :class:`Wall` (``invert`` a bool, ``e_n`` in [0, 1], ``mu`` finite >= 0)."""
    b, ni, nr, root = _tree(node_ints, node_reals, root)
    invert = check_bool("invert", invert)
    e = check_float("e_n", e_n, 0.0, 1.0)
    mu = check_float("mu", mu, 0.0)
    return Wall(ni, nr, root, invert, e, mu, compile_root(ni, nr, root),
                bool(b.is_lipschitz(root)))


def cluster_probes(points, cell):
    """Group probe points (M, 3) by a voxel grid of size ``cell``.

    Returns (order (M,), cluster_range (C, 2), centre (C, 3), radius (C,)): ``points[order]``
    lists the clusters' members contiguously; a cluster's sphere contains all its members.
    """
    pts = np.asarray(points, dtype=np.float64)
    if len(pts) == 0:
        return (np.zeros(0, np.int64), np.zeros((0, 2), np.int64), np.zeros((0, 3)),
                np.zeros(0))
    key = np.floor((pts - pts.min(axis=0)) / cell).astype(np.int64)
    order = np.lexsort((np.arange(len(pts)), key[:, 0], key[:, 1], key[:, 2]))
    ks = key[order]
    brk = np.flatnonzero(np.any(np.diff(ks, axis=0) != 0, axis=1)) + 1
    starts = np.concatenate([[0], brk])
    ends = np.concatenate([brk, [len(pts)]])
    centre = np.empty((len(starts), 3))
    radius = np.empty(len(starts))
    for c, (s, e) in enumerate(zip(starts, ends)):
        m = pts[order[s:e]]
        centre[c] = m.mean(axis=0)
        radius[c] = np.sqrt(((m - centre[c]) ** 2).sum(axis=1)).max() * (1.0 + 1e-12) + 1e-15
    return (order.astype(np.int64), np.stack([starts, ends], axis=1).astype(np.int64), centre,
            radius)


def _up(d):
    # a distance rounded up, so that bounds built from it are never short by a round-off
    return d * (1.0 + 1e-12) + 1e-15


def group_clusters(centre, radius, cell):
    """Group clusters (centres (C, 3), radii (C,)) by a voxel grid of size ``cell``.

    Returns (member (C,), group_range (G, 2), group_centre (G, 3), group_radius (G,),
    offset (C,)): ``member[s:e]`` lists a group's cluster ids (ascending), ``offset[k]`` is
    the distance of cluster ``member[k]`` from its group's centre (rounded up); a group's
    sphere contains the spheres of all its clusters."""
    cen = np.asarray(centre, dtype=np.float64)
    rad = np.asarray(radius, dtype=np.float64)
    if len(cen) == 0:
        return (np.zeros(0, np.int64), np.zeros((0, 2), np.int64), np.zeros((0, 3)),
                np.zeros(0), np.zeros(0))
    order, rng, gcen, _ = cluster_probes(cen, cell)
    off = np.empty(len(cen))
    grad = np.empty(len(rng))
    for g, (s, e) in enumerate(rng):
        m = order[s:e]
        off[s:e] = _up(np.sqrt(((cen[m] - gcen[g]) ** 2).sum(axis=1)))
        grad[g] = _up((off[s:e] + rad[m]).max())
    return order, rng, gcen, grad, off


def build_geometry(shapes, walls):
    """The :class:`Geometry` of ``shapes`` (by shape id) and ``walls`` (by wall index)."""
    progs, p0, clr = [], [], []
    probes, cl_centre, cl_rad, cl_range, probe_off = [], [], [], [], []
    grr, gr_centre, gr_rad, gr_range, gr_member, gr_off = [], [], [], [], [], []
    npro = ncl = ngr = 0
    for s in shapes:
        p0.append(npro)
        if isinstance(s, SceneShape):
            progs.append(s.program)
            cell = s.radius * CLUSTER_CELL_FRACTION
            order, rng, cen, crad = cluster_probes(s.shell, cell)
            pts = s.shell[order]
            probes.append(pts)
            owner = np.repeat(np.arange(len(rng)), rng[:, 1] - rng[:, 0])
            probe_off.append(_up(np.sqrt(((pts - cen[owner]) ** 2).sum(axis=1))))
            cl_centre.append(cen)
            cl_rad.append(crad)
            cl_range.append(rng + npro)
            clr.append((ncl, ncl + len(rng)))
            member, grng, gcen, grad, goff = group_clusters(cen, crad, GROUP_CELLS * cell)
            gr_member.append(member + ncl)
            gr_range.append(grng + ncl)
            gr_centre.append(gcen)
            gr_rad.append(grad)
            gr_off.append(goff)
            grr.append((ngr, ngr + len(grng)))
            npro += len(order)
            ncl += len(rng)
            ngr += len(grng)
        else:
            clr.append((ncl, ncl))
            grr.append((ngr, ngr))
    progs.extend(w.program for w in walls)
    tables = [s.pruned for s in shapes if isinstance(s, SceneShape)] + [None] * len(walls)
    if progs:
        # the leaf tables of the plain concatenation; the pruned set numbers leaves the same
        # way and holds every whole program besides the pruned ones
        _, lk, lr, _ = concatenate(progs)
        ps = concatenate_pruned(progs, tables)
        ops, ranges, block_range = ps.ops, ps.full, ps.block_range
    else:
        ops = np.zeros((1, 2), np.int32)
        lk = np.zeros(1, np.int32)
        lr = np.zeros((1, 24))
        ranges = np.zeros((0, 2), np.int64)
        block_range = np.zeros((0, 2), np.int64)
    scene = [isinstance(s, SceneShape) for s in shapes]
    is_scene = np.asarray(scene, bool)
    nscene = int(is_scene.sum())
    pboff = np.zeros(len(shapes), np.int64)
    pob = np.ones((len(shapes), 5))
    pdims = np.zeros((len(shapes), 3), np.int64)
    if nscene:
        pboff[is_scene] = ps.block_off[:nscene]
        pob[is_scene] = ps.ob[:nscene]
        pdims[is_scene] = ps.dims[:nscene]
    grids = [s.grid if c else np.zeros(0) for s, c in zip(shapes, scene)]
    goff = np.concatenate([[0], np.cumsum([len(g) for g in grids])])[:len(shapes)]
    shape_op = np.full((len(shapes), 2), -1, np.int64)
    shape_op[is_scene] = np.asarray(ranges[:nscene], np.int64).reshape(-1, 2)
    maxm = max([len(s.shell) for s in shapes if isinstance(s, SceneShape)] + [1])
    return Geometry(
        shape_kind=np.array([SCENE if c else SPHERE for c in scene], np.int64),
        shape_rad=np.array([s.radius for s in shapes], np.float64),
        shape_op=shape_op,
        shape_lip=np.array([getattr(s, "lip", True) for s in shapes], np.bool_),
        shape_p0=np.asarray(p0, np.int64),
        shape_cl=np.asarray(clr, np.int64).reshape(-1, 2),
        cl_centre=np.concatenate(cl_centre) if cl_centre else np.zeros((0, 3)),
        cl_rad=np.concatenate(cl_rad) if cl_rad else np.zeros(0),
        cl_range=np.concatenate(cl_range) if cl_range else np.zeros((0, 2), np.int64),
        probes=np.ascontiguousarray(np.concatenate(probes)) if probes else np.zeros((0, 3)),
        probe_off=np.concatenate(probe_off) if probe_off else np.zeros(0),
        shape_gr=np.asarray(grr, np.int64).reshape(-1, 2),
        gr_centre=np.concatenate(gr_centre) if gr_centre else np.zeros((0, 3)),
        gr_rad=np.concatenate(gr_rad) if gr_rad else np.zeros(0),
        gr_dist=(_up(np.sqrt((np.concatenate(gr_centre) ** 2).sum(axis=1))) if gr_centre
                 else np.zeros(0)),
        gr_range=np.concatenate(gr_range) if gr_range else np.zeros((0, 2), np.int64),
        gr_member=np.concatenate(gr_member) if gr_member else np.zeros(0, np.int64),
        gr_off=np.concatenate(gr_off) if gr_off else np.zeros(0),
        grid=np.concatenate(grids) if grids else np.zeros(0),
        shape_grid_off=np.asarray(goff, np.int64),
        shape_grid_dims=np.array([s.grid_dims if c else np.zeros(3, np.int64)
                                  for s, c in zip(shapes, scene)], np.int64).reshape(-1, 3),
        shape_grid_oh=np.array([s.grid_oh if c else np.ones(4) for s, c in zip(shapes, scene)],
                               np.float64).reshape(-1, 4),
        wall_op=np.asarray(ranges[nscene:], np.int64).reshape(-1, 2),
        wall_sign=np.array([-1.0 if w.invert else 1.0 for w in walls]),
        wall_lip=np.array([w.lip for w in walls], np.bool_),
        wall_e=np.array([w.e for w in walls]),
        wall_mu=np.array([w.mu for w in walls]),
        wall_pos=np.zeros((len(walls), 3)),
        wall_rot=np.ascontiguousarray(np.tile(np.eye(3), (len(walls), 1, 1))),
        ops=ops, lk=lk, lr=lr, block_range=block_range,
        shape_pboff=pboff, shape_pob=pob, shape_pdims=pdims,
        max_hits=2 * maxm + 2,
        wall_grid_off=np.zeros(len(walls), np.int64),
        wall_grid_dims=np.zeros((len(walls), 3), np.int64),
        wall_grid_oh=np.ones((len(walls), 4)))
