"""The grid leaf's field (kind 0): the one place its formula is written.

In a compiled program (:mod:`peclet.core.geom.kernels`) a grid leaf's row holds
``(rows to its data, nx, ny, nz, h)`` in its parameter slots: the lattice's samples follow the
program's leaf rows, ``LEAF_COLS`` to a row, flattened with x fastest (sample (i, j, k) at
``i + nx (j + ny k)``), starting ``int(row[0])`` rows after the leaf's own row (relative, so
programs concatenate unchanged). The lattice is centred on the leaf's origin: sample (i, j, k)
sits at ``(i h - X, j h - Y, k h - Z)`` with ``X = (nx - 1) h / 2`` (and Y, Z alike).

Inside the lattice's box B the field is the trilinear interpolant F of the samples. Outside it
is ``|p - c(p)| + F(c(p))`` with c(p) the nearest point of B (the clamp): the distance to the box
plus the value there. For a solid well inside the box (positive samples on the box's faces,
which the builder requires) this over-estimates the distance to the solid by at most F's own
error at c(p) plus the gap between the box and the solid's nearest point along the way; it is
exact where the nearest surface point lies straight across a face.

The gradient is the interpolant's own (not normalised): inside, the trilinear derivatives;
outside, the unit offset ``(p - c) / |p - c|`` on the clamped axes and F's derivatives along
the others. The feature is the parity of the cell on each axis, ``(i & 1) + 2 (j & 1) +
4 (k & 1)``: it changes across every cell face, where F's gradient jumps, so the quadrature sees
those creases as it sees a box's edges.
"""
from __future__ import annotations

import math

from numba import njit

#: Columns of a program row (kernels.LEAF_COLS; repeated here because kernels imports this).
_COLS = 24


@njit(cache=True, inline="always")
def _sample(L, base, idx):
    r = idx // _COLS
    return L[base + r, idx - r * _COLS]


@njit(cache=True, inline="always")
def _cell(x, half, h, n):
    """(clamped coordinate, cell index in [0, n - 2], fraction in [0, 1]) along one axis."""
    c = min(max(x, -half), half)
    u = (c + half) / h
    i = min(max(int(u), 0), n - 2)
    return c, i, u - i


@njit(cache=True)
def grid_eval(L, j, x, y, z):
    """(phi, gx, gy, gz, feature) of the grid leaf in program row ``j`` at canonical (x, y, z);
    see the module notes for the field, its extension and the gradient."""
    base = j + int(L[j, 0])
    nx = int(L[j, 1])
    ny = int(L[j, 2])
    nz = int(L[j, 3])
    h = L[j, 4]
    cx, i, fx = _cell(x, 0.5 * (nx - 1) * h, h, nx)
    cy, k, fy = _cell(y, 0.5 * (ny - 1) * h, h, ny)
    cz, m, fz = _cell(z, 0.5 * (nz - 1) * h, h, nz)
    sx = 1
    sy = nx
    sz = nx * ny
    o = i + nx * (k + ny * m)
    c000 = _sample(L, base, o)
    c100 = _sample(L, base, o + sx)
    c010 = _sample(L, base, o + sy)
    c110 = _sample(L, base, o + sx + sy)
    c001 = _sample(L, base, o + sz)
    c101 = _sample(L, base, o + sx + sz)
    c011 = _sample(L, base, o + sy + sz)
    c111 = _sample(L, base, o + sx + sy + sz)
    gx_ = 1.0 - fx
    gy_ = 1.0 - fy
    gz_ = 1.0 - fz
    # x first: four edges along x, then y, then z
    e00 = c000 * gx_ + c100 * fx
    e10 = c010 * gx_ + c110 * fx
    e01 = c001 * gx_ + c101 * fx
    e11 = c011 * gx_ + c111 * fx
    f0 = e00 * gy_ + e10 * fy
    f1 = e01 * gy_ + e11 * fy
    v = f0 * gz_ + f1 * fz
    dx = ((c100 - c000) * gy_ * gz_ + (c110 - c010) * fy * gz_ + (c101 - c001) * gy_ * fz
          + (c111 - c011) * fy * fz) / h
    dy = ((e10 - e00) * gz_ + (e11 - e01) * fz) / h
    dz = (f1 - f0) / h
    feat = (i & 1) + 2 * (k & 1) + 4 * (m & 1)
    ox = x - cx
    oy = y - cy
    oz = z - cz
    out = math.sqrt(ox * ox + oy * oy + oz * oz)
    if out > 0.0:
        gx = ox / out if ox != 0.0 else dx
        gy = oy / out if oy != 0.0 else dy
        gz = oz / out if oz != 0.0 else dz
        return out + v, gx, gy, gz, feat
    return v, dx, dy, dz, feat
