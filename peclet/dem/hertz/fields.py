"""The two sides of a composed particle's contact and their exact fields: what the patch and the
distributed laws evaluate (docstring of :mod:`peclet.dem.hertz.patch`).

Bundles: :class:`Shapes` (the bodies' poses, the shape and wall tables, the program tables
and the elliptical Hertz table: everything a composed kernel reads), :class:`Side` (one side
of a contact: an analytic sphere, a tree or a wall) and :class:`Pair` (a contact's two sides
with the shapes, its length scale and the tree evaluator's stack)."""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from peclet.core.geom.kernels import MAX_STACK, STACK_COLS, eval_point
from peclet.dem.treeframe import to_home, to_world

from .calibration import elliptic_table
from .law import Walls, cross, walls_of


#: The fields of :class:`Shapes`: the bodies and their shapes, then the walls part, which is
#: :class:`~peclet.dem.hertz.law.Walls`'s fields (one definition serves both bundles), then the
#: elliptical Hertz table.
_SHAPES_FIELDS = ("pos", "rot", "shape_of", "shape_kind", "shape_rad", "shape_op", "shape_p0",
                  "shape_np", "probes", *Walls._fields, "ctab_t", "ctab_c")
# flat, not a Walls nested in a Shapes: a parallel loop over a bundle (patches_parallel)
# unpacks one level of tuples only
Shapes = NamedTuple("Shapes", [(f, np.ndarray) for f in _SHAPES_FIELDS])
Shapes.__doc__ = """The bodies' positions ``pos`` (N, 3) and rotations ``rot`` (N, 3, 3),
    ``shape_of`` (N,), per shape its kind, radius, program rows (k, 2), first probe and probe
    count, the probes (home frame), then the fields of a :class:`~peclet.dem.hertz.law.Walls`
    (per wall its program rows, sign and pose, and the program tables ``ops``, ``lk``, ``lr``,
    which the shapes' rows index too), and the elliptical Hertz table (``ctab_t``,
    ``ctab_c``)."""


def probe_counts(geo):
    """Probes per shape (int64) of a :class:`peclet.dem.shapes.Geometry`."""
    return np.diff(np.append(geo.shape_p0, len(geo.probes))).astype(np.int64)


def shapes_of(pos, rot, shape_of, geo):
    """The :class:`Shapes` of bodies at ``pos`` with rotations ``rot`` in geometry ``geo``."""
    ct, cc = elliptic_table()
    return Shapes(pos, rot, shape_of, geo.shape_kind, geo.shape_rad, geo.shape_op, geo.shape_p0,
                  probe_counts(geo), geo.probes, *walls_of(geo), ct, cc)


class Side(NamedTuple):
    """One side of a contact: ``kind`` 0 an analytic sphere of radius ``rad`` centred at ``x``;
    1 the tree program rows [``o0``, ``o1``) placed at ``x`` with rotation ``R`` (tree ->
    world), its value times ``sgn`` (a wall's sign; +1 for a body)."""
    kind: np.int64
    rad: float
    x: np.ndarray
    R: np.ndarray
    o0: np.int64
    o1: np.int64
    sgn: float


class Pair(NamedTuple):
    """A contact's sides ``a`` (a body) and ``b`` (a body or a wall), the :class:`Shapes`,
    the length ``scale`` (the smaller radius) and the tree evaluator's stack ``st``."""
    a: Side
    b: Side
    sh: Shapes
    scale: float
    st: np.ndarray



@njit(cache=True)
def field(side, sh, px, py, pz, st):
    """phi and its world gradient at (px, py, pz) of one :class:`Side` of a contact (the
    program tables of ``sh``; ``st`` the evaluator's stack)."""
    kind, rad, xt, Rt, o0, o1, sgn = side
    ops, lk, lr = sh.ops, sh.lk, sh.lr
    dx = px - xt[0]
    dy = py - xt[1]
    dz = pz - xt[2]
    if kind == 0:
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        if d > 0.0:
            return d - rad, dx / d, dy / d, dz / d
        return -rad, 1.0, 0.0, 0.0
    qx, qy, qz = to_home(Rt, dx, dy, dz)
    phi, gx, gy, gz = eval_point(ops, lk, lr, o0, o1, qx, qy, qz, st)
    wx, wy, wz = to_world(Rt, sgn, gx, gy, gz)
    return sgn * phi, wx, wy, wz


@njit(cache=True)
def hessian(side, sh, px, py, pz, h, st, H):
    """The Hessian (3, 3) of one side's phi at p into ``H``: closed form for a sphere,
    otherwise central differences (step ``h``) of the exact gradient, symmetrised."""
    kind, xt = side.kind, side.x
    if kind == 0:
        dx = px - xt[0]
        dy = py - xt[1]
        dz = pz - xt[2]
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        u = (dx / d, dy / d, dz / d)
        for r in range(3):
            for c in range(3):
                H[r, c] = ((1.0 if r == c else 0.0) - u[r] * u[c]) / d
        return
    for c in range(3):
        ex = h if c == 0 else 0.0
        ey = h if c == 1 else 0.0
        ez = h if c == 2 else 0.0
        _, p0, p1, p2 = field(side, sh, px + ex, py + ey, pz + ez, st)
        _, m0, m1, m2 = field(side, sh, px - ex, py - ey, pz - ez, st)
        H[0, c] = (p0 - m0) / (2.0 * h)
        H[1, c] = (p1 - m1) / (2.0 * h)
        H[2, c] = (p2 - m2) / (2.0 * h)
    for r in range(3):
        for c in range(r + 1, 3):
            s = 0.5 * (H[r, c] + H[c, r])
            H[r, c] = s
            H[c, r] = s


@njit(cache=True)
def tangents(nx, ny, nz):
    """A unit basis (t1, t2) of the plane normal to the unit n (deterministic)."""
    ax, ay, az = abs(nx), abs(ny), abs(nz)
    if ax <= ay and ax <= az:
        ux, uy, uz = 0.0, -nz, ny
    elif ay <= az:
        ux, uy, uz = nz, 0.0, -nx
    else:
        ux, uy, uz = -ny, nx, 0.0
    un = math.sqrt(ux * ux + uy * uy + uz * uz)
    ux /= un
    uy /= un
    uz /= un
    vx, vy, vz = cross(nx, ny, nz, ux, uy, uz)
    return ux, uy, uz, vx, vy, vz


@njit(cache=True)
def tt(H, ux, uy, uz, vx, vy, vz):
    """u^T H v."""
    return (ux * (H[0, 0] * vx + H[0, 1] * vy + H[0, 2] * vz)
            + uy * (H[1, 0] * vx + H[1, 1] * vy + H[1, 2] * vz)
            + uz * (H[2, 0] * vx + H[2, 1] * vy + H[2, 2] * vz))


@njit(cache=True)
def surface_curvature(H, gn, s, t):
    """The 2x2 curvature (k11, k12, k22) of a side's surface in the tangent basis ``t``
    (6,), from its Hessian ``H`` at a point at signed distance ``s`` from the surface with
    gradient norm ``gn``: the level set's shape operator P H P / |grad|, carried to the surface
    by the parallel-surface relation K_surface = K (I - s K)^-1 (exact for a distance field)."""
    k11 = tt(H, t[0], t[1], t[2], t[0], t[1], t[2]) / gn
    k12 = tt(H, t[0], t[1], t[2], t[3], t[4], t[5]) / gn
    k22 = tt(H, t[3], t[4], t[5], t[3], t[4], t[5]) / gn
    a11 = 1.0 - s * k11
    a12 = -s * k12
    a22 = 1.0 - s * k22
    det = a11 * a22 - a12 * a12
    i11 = a22 / det
    i12 = -a12 / det
    i22 = a11 / det
    c11 = k11 * i11 + k12 * i12
    c12 = 0.5 * ((k11 * i12 + k12 * i22) + (k12 * i11 + k22 * i12))
    c22 = k12 * i12 + k22 * i22
    return c11, c12, c22


@njit(cache=True)
def _side(body, shift, sh, xt):
    """One side of a contact: (kind, radius, rotation, program start, end, sign), its centre
    written into ``xt``; a body (b's image ``shift`` added) or, for body < 0, wall -1 - body."""
    if body >= 0:
        s = sh.shape_of[body]
        for e in range(3):
            xt[e] = sh.pos[body, e] + shift[e]
        return (sh.shape_kind[s], sh.shape_rad[s], sh.rot[body], sh.shape_op[s, 0],
                sh.shape_op[s, 1], 1.0)
    w = -1 - body
    for e in range(3):
        xt[e] = sh.wall_pos[w, e]
    return np.int64(1), np.inf, sh.wall_rot[w], sh.wall_op[w, 0], sh.wall_op[w, 1], \
        sh.wall_sign[w]


@njit(cache=True)
def pair_of(ia, ib, shift, sh):
    """The :class:`Pair` of the contact of ``ia`` with ``ib`` (b's image ``shift``): both
    sides (their centres in new arrays), the scale min(radius a, radius b), a new stack."""
    xa = np.empty(3)
    xb = np.empty(3)
    ka, rada, Ra, oa0, oa1, _ = _side(ia, np.zeros(3), sh, xa)
    kb, radb, Rb, ob0, ob1, sb = _side(ib, shift, sh, xb)
    st = np.empty((MAX_STACK, STACK_COLS))
    return Pair(Side(ka, rada, xa, Ra, oa0, oa1, 1.0), Side(kb, radb, xb, Rb, ob0, ob1, sb), sh,
                min(rada, radb), st)
