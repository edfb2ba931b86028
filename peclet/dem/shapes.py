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
from peclet.core.validation import (PecletArgumentError, check_array, check_bool,
                                    check_float, check_int)

#: ``Geometry.shape_kind`` values.
SPHERE, SCENE = 0, 1

#: Probe clusters are voxels of this fraction of the shape's bounding radius.
CLUSTER_CELL_FRACTION = 0.25


class SphereShape(NamedTuple):
    """A sphere of ``radius`` about the body's centre of mass."""
    radius: float


class SceneShape(NamedTuple):
    """A composed CSG particle: the flat tree (``node_ints`` (n, 3), ``node_reals`` (n, 16)),
    its ``root`` node, surface ``shell`` probes (M, 3) in the home frame, the bounding radius
    about the origin, the compiled program, and whether phi is 1-Lipschitz (cluster culling)."""
    radius: float
    shell: np.ndarray
    node_ints: np.ndarray
    node_reals: np.ndarray
    root: int
    program: tuple
    lip: bool


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

    ``shape_op`` / ``wall_op`` (k, 2): the [start, end) op range of the tree in ``ops``/``lk``/
    ``lr`` (-1 for a sphere); ``shape_p0``: first probe of the shape; ``shape_cl`` (k, 2): its
    [start, end) cluster range; ``cl_range`` (C, 2): a cluster's [start, end) probe range;
    ``wall_sign`` -1 for an inverted wall; ``max_hits``: a task's hit buffer size."""
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
    wall_op: np.ndarray
    wall_sign: np.ndarray
    wall_lip: np.ndarray
    wall_e: np.ndarray
    wall_mu: np.ndarray
    ops: np.ndarray
    lk: np.ndarray
    lr: np.ndarray
    max_hits: int


def _tree(node_ints, node_reals, root):
    # a validated copy of the flat tree and its root
    b = SceneBuilder.decode(node_ints, node_reals)
    root = check_int("root", root, 0, b.num_nodes() - 1)
    ni, nr = b._node_arrays()
    return b, np.asarray(ni), np.asarray(nr, dtype=np.float64), root


def sphere_shape(radius):
    """A validated :class:`SphereShape` (``radius`` finite, > 0)."""
    return SphereShape(check_float("radius", radius, 0.0, lo_open=True))


def scene_shape(node_ints, node_reals, root, shell_points, bounding_radius):
    """A validated :class:`SceneShape`; the bounding radius is raised to the farthest probe."""
    b, ni, nr, root = _tree(node_ints, node_reals, root)
    shell = check_array("shell_points", shell_points, (None, 3))
    if len(shell) == 0:
        raise PecletArgumentError("shell_points", "an array of shape (M, 3) with M >= 1",
                                  shell_points)
    br = check_float("bounding_radius", bounding_radius, 0.0, lo_open=True)
    br = max(br, float(np.sqrt((shell ** 2).sum(axis=1)).max()))
    return SceneShape(br, shell.copy(), ni, nr, root, compile_root(ni, nr, root),
                      bool(b.is_lipschitz(root)))


def analytic_wall(node_ints, node_reals, root, invert, e, mu):
    """A validated :class:`Wall` (``invert`` a bool, ``e`` in [0, 1], ``mu`` finite >= 0)."""
    b, ni, nr, root = _tree(node_ints, node_reals, root)
    invert = check_bool("invert", invert)
    e = check_float("e", e, 0.0, 1.0)
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


def build_geometry(shapes, walls):
    """The :class:`Geometry` of ``shapes`` (by shape id) and ``walls`` (by wall index)."""
    progs, p0, clr = [], [], []
    probes, cl_centre, cl_rad, cl_range = [], [], [], []
    npro = ncl = 0
    for s in shapes:
        p0.append(npro)
        if isinstance(s, SceneShape):
            progs.append(s.program)
            order, rng, cen, crad = cluster_probes(s.shell, s.radius * CLUSTER_CELL_FRACTION)
            probes.append(s.shell[order])
            cl_centre.append(cen)
            cl_rad.append(crad)
            cl_range.append(rng + npro)
            clr.append((ncl, ncl + len(rng)))
            npro += len(order)
            ncl += len(rng)
        else:
            clr.append((ncl, ncl))
    progs.extend(w.program for w in walls)
    if progs:
        ops, lk, lr, ranges = concatenate(progs)
    else:
        ops = np.zeros((1, 2), np.int32)
        lk = np.zeros(1, np.int32)
        lr = np.zeros((1, 24))
        ranges = np.zeros((0, 2), np.int64)
    scene = [isinstance(s, SceneShape) for s in shapes]
    shape_op = np.full((len(shapes), 2), -1, np.int64)
    shape_op[np.asarray(scene, bool)] = np.asarray(ranges[:sum(scene)], np.int64).reshape(-1, 2)
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
        wall_op=np.asarray(ranges[sum(scene):], np.int64).reshape(-1, 2),
        wall_sign=np.array([-1.0 if w.invert else 1.0 for w in walls]),
        wall_lip=np.array([w.lip for w in walls], np.bool_),
        wall_e=np.array([w.e for w in walls]),
        wall_mu=np.array([w.mu for w in walls]),
        ops=ops, lk=lk, lr=lr, max_hits=2 * maxm + 2)
