"""A per-shape distance grid: a certified lower bound of a 1-Lipschitz tree's phi for the
price of one array read.

Baked once when a shape is registered: phi at the nodes of a regular lattice (spacing ``h``)
covering the shape's bounding cube plus a pad. For a home-frame point q and the lattice node n
nearest to it (clamped to the lattice), a 1-Lipschitz phi obeys phi(q) >= phi(n) - |q - n|,
with |q - n| <= h sqrt(3) / 2 inside the lattice. Far from the surface the lattice is
sphere-traced (:func:`peclet.core.geom.kernels.bake_lattice`): a stored positive value there is
phi at a nearby node minus the distance to it, never more than phi, so the bound holds for
every stored positive value. Stored negative values carry no lower bound and give -inf.

The narrow phase uses the bound only to SKIP work (a probe, cluster or body whose bound exceeds
the margin cannot give a contact); every contact is still the exact tree's value at the probe.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from peclet.core.geom.kernels import bake_lattice

#: Lattice spacing = bounding radius / CELLS_PER_RADIUS.
CELLS_PER_RADIUS = 32
#: Nodes beyond the covering cube on each side.
PAD_CELLS = 2
#: Values within this many cells of the surface are exact evaluations (the rest are bounds).
BAND_CELLS = 8


def lattice(radius):
    """(origin (3,), spacing h, cells per axis) of the lattice of a shape whose solid lies
    within ``radius`` of its home-frame origin: a cube of ``cells`` cells of side h, centred
    on the origin, covering the bounding sphere plus PAD_CELLS cells."""
    h = float(radius) / CELLS_PER_RADIUS
    return np.full(3, -(CELLS_PER_RADIUS + PAD_CELLS) * h), h, 2 * (CELLS_PER_RADIUS + PAD_CELLS)


def bake(program, radius):
    """(values (n,), dims (3,) int64, origin_and_h (4,)) of the grid of a 1-Lipschitz
    ``program`` whose solid lies within ``radius`` of the home-frame origin; its nodes are
    the corners of :func:`lattice`'s cells."""
    origin, h, cells = lattice(radius)
    dims = np.full(3, cells + 1, np.int64)
    out = np.empty(int(np.prod(dims)))
    bake_lattice(program.ops, program.leaf_kind, program.leaf_reals, program.op_begin,
                 program.op_end, origin, np.full(3, h), dims, BAND_CELLS * h, out)
    return out, dims, np.array([origin[0], origin[1], origin[2], h])


@njit(cache=True, inline="always")
def _node(q, o, h, n):
    # index of the nearest node along one axis, clamped to the lattice
    t = (q - o) / h + 0.5
    if not (t >= 1.0):
        return 0
    if t >= n:
        return n - 1
    return int(t)


@njit(cache=True, inline="always")
def lower_bound(grid, off, dims, oh, qx, qy, qz):
    """A lower bound of phi at the home-frame point q from the grid stored at ``grid[off:]``
    with ``dims`` (3,) and ``oh`` = (origin x, y, z, h); -inf when none (no grid: dims[0] = 0,
    or a non-positive stored value)."""
    nx = dims[0]
    if nx == 0:
        return -np.inf
    ny = dims[1]
    nz = dims[2]
    h = oh[3]
    i = _node(qx, oh[0], h, nx)
    j = _node(qy, oh[1], h, ny)
    k = _node(qz, oh[2], h, nz)
    v = grid[off + (k * ny + j) * nx + i]
    if not (v > 0.0):
        return -np.inf
    dx = qx - (oh[0] + i * h)
    dy = qy - (oh[1] + j * h)
    dz = qz - (oh[2] + k * h)
    # the distance rounded up, so that a round-off never makes the bound exceed phi
    return v - (math.sqrt(dx * dx + dy * dy + dz * dz) * (1.0 + 1e-12) + 1e-15)


#: Walls get a distance grid when a detection holds at least this many body-wall tasks (below
#: it, baking costs more than the evaluations it spares).
WALL_GRID_MIN_TASKS = 6000
#: A wall grid's node budget: this many nodes per body, at most WALL_GRID_MAX_NODES.
WALL_GRID_NODES_PER_BODY = 40
WALL_GRID_MAX_NODES = 2_000_000


def bake_wall(ops, lk, lr, op_range, sign, centre, half, h):
    """(values, dims (3,) int64, origin_and_h (4,)) of a grid of ``sign * phi`` of a
    1-Lipschitz wall program (rows ``op_range``) on the cube of half side ``half`` about the
    wall-frame point ``centre``, spacing ``h``. Baked with the sphere-traced lattice of
    :func:`peclet.core.geom.kernels.bake_lattice`: its stored values of the sign of phi are
    bounds of phi's magnitude, so after the sign flip every positive value is still a lower
    bound of ``sign * phi`` (the only values :func:`lower_bound` uses). A point outside the
    cube reads the nearest node: a valid, weaker bound."""
    cells = max(1, int(math.ceil(2.0 * half / h)))
    origin = np.asarray(centre, np.float64) - 0.5 * cells * h
    dims = np.full(3, cells + 1, np.int64)
    out = np.empty(int(np.prod(dims)))
    bake_lattice(ops, lk, lr, np.int64(op_range[0]), np.int64(op_range[1]), origin,
                 np.full(3, h), dims, BAND_CELLS * h, out)
    if sign < 0.0:
        np.negative(out, out=out)
    return out, dims, np.array([origin[0], origin[1], origin[2], h])


def with_wall_grids(geo, pos, reach):
    """``geo`` with a distance grid for each 1-Lipschitz wall (``wall_grid_*`` fields), each
    covering, in the wall's own frame at its current pose, a cube about the bodies' box
    (``pos`` (N, 3)) grown by ``reach``; the cube's half side is the box's half diagonal, so a
    wall that turns about the box's centre keeps the bodies inside it. The grids only spare
    evaluations (a bound above the margin), so the contacts never depend on them; ``geo``
    itself when there are too few body-wall tasks to pay for them."""
    n, nw = len(pos), len(geo.wall_op)
    if n * nw < WALL_GRID_MIN_TASKS or not np.any(geo.wall_lip):
        return geo
    lo = pos.min(axis=0) - reach
    hi = pos.max(axis=0) + reach
    centre_w = 0.5 * (lo + hi)
    half = 0.5 * float(np.sqrt(((hi - lo) ** 2).sum()))
    nodes = min(WALL_GRID_MAX_NODES, WALL_GRID_NODES_PER_BODY * n)
    h = 2.0 * half / max(2.0, nodes ** (1.0 / 3.0) - 1.0)
    grids, offs = [], []
    dims = np.zeros((nw, 3), np.int64)
    oh = np.ones((nw, 4))
    total = len(geo.grid)
    for w in range(nw):
        offs.append(total)
        if not geo.wall_lip[w]:
            continue
        c = geo.wall_rot[w].T @ (centre_w - geo.wall_pos[w])
        g, dims[w], oh[w] = bake_wall(geo.ops, geo.lk, geo.lr, geo.wall_op[w],
                                      float(geo.wall_sign[w]), c, half, h)
        grids.append(g)
        total += len(g)
    return geo._replace(grid=np.concatenate([geo.grid] + grids),
                        wall_grid_off=np.asarray(offs, np.int64), wall_grid_dims=dims,
                        wall_grid_oh=oh)
