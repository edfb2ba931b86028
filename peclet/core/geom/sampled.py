"""The grid leaf's samples in the flat encoding: data rows, checks and the measured ball.

A grid leaf (kind 0, :data:`~peclet.core.geom.leaves.GRID`) is a lattice of signed-distance
samples ``values[i, j, k]`` (x, y, z; length units of the leaf's frame) at spacing ``h``,
centred on the leaf's origin (sample (i, j, k) at ``(i - (nx - 1) / 2, ...) * h``); its field
is written once, in :mod:`peclet.core.geom.grid_kernel`.

Where the samples live: in the node table itself, as *data rows* (kind
:data:`~peclet.core.geom.leaves.DATA` = 31, children -1) just before the leaf, 16 samples to a
``node_reals`` row (x fastest; the last row padded with zeros). The leaf's parameters are
``(first_row, nx, ny, nz, h)``: the node index of its first data row and the lattice. So the
encoding stays the two flat arrays every pack, checkpoint and page call already carries, and a
consumer needs nothing but the file. Data rows are not nodes: they cannot be roots or children.
A float32 copy of the table (the page's calls) rounds the samples to float32 (relative 6e-8).

The ball (Equation 1, docs/architecture.md §4) is measured from the samples and proven, not
guessed: with ``r = max over samples of (|x_ijk| - f_ijk)``, inside a cell the interpolant is a
convex combination of its corners, so ``F(p) >= |p| - r`` there (|.| is convex); outside the box,
``F(p) = |p - c| + F(c) >= |p - c| + |c| - r >= |p| - r``. Equation 1 holds about the origin with
that r, up to rounding. The field is not 1-Lipschitz in general (the interpolant of a distance
can reach sqrt 3 in a cell, the extension sqrt 2), so the leaf is never *certified*: it is
evaluated, never culled (the rule of §4 unchanged).
"""
from __future__ import annotations

import math

import numpy as np

from peclet.core.validation import PecletArgumentError, check_array, check_float

from .leaves import DATA, GRID_DIM_RANGE

__all__ = ["SAMPLES_PER_ROW", "data_rows", "grid_values", "grid_radius", "grid_lipschitz",
           "check_grid_values", "program_rows", "lattice_points"]

#: Samples per node_reals row of a data block.
SAMPLES_PER_ROW = 16


def data_rows(values):
    """(rows (n_rows, 16) float64): the samples ``values`` (nx, ny, nz), x fastest, padded."""
    return program_rows(values, SAMPLES_PER_ROW)


def n_data_rows(params):
    """Number of data rows of a grid leaf with ``params`` (first_row, nx, ny, nz, h)."""
    n = int(params[1]) * int(params[2]) * int(params[3])
    return -(-n // SAMPLES_PER_ROW)


def grid_values(kinds, reals, params, leaf_index):
    """The samples (nx, ny, nz) float64 of the grid leaf at node ``leaf_index`` with ``params``,
    read from its data rows (``kinds``: the node kinds, ``reals``: node_reals rows, any
    sequence of rows of 16). Raises PecletArgumentError naming ``params`` when the rows it
    names are not data rows before the leaf, or a sample is not finite."""
    first, dims = int(params[0]), tuple(int(v) for v in params[1:4])
    count = n_data_rows(params)
    if not (0 <= first and first + count <= leaf_index):
        raise PecletArgumentError("params", f"a grid whose {count} data rows (first_row "
                                  f"{first}) lie before its leaf (node {leaf_index})", params)
    bad = [i for i in range(first, first + count) if int(kinds[i]) != DATA]
    if bad:
        raise PecletArgumentError("params", f"rows {first}..{first + count - 1} all data rows "
                                  f"(kind {DATA})", params, f"row {bad[0]} is a node")
    flat = np.asarray([reals[i] for i in range(first, first + count)], np.float64).ravel()
    flat = flat[:math.prod(dims)]
    if not np.all(np.isfinite(flat)):
        raise PecletArgumentError("params", "a grid of finite samples", params,
                                  f"{int((~np.isfinite(flat)).sum())} samples are not finite")
    return flat.reshape(dims, order="F")


def lattice_points(dims, h):
    """(x (nx,), y (ny,), z (nz,)): the sample coordinates of a centred lattice, lengths."""
    return tuple((np.arange(n) - 0.5 * (n - 1)) * h for n in dims)


def check_grid_values(values, spacing, name="values"):
    """(values (nx, ny, nz) float64, spacing float) validated: each axis in
    :data:`~peclet.core.geom.leaves.GRID_DIM_RANGE`, finite samples, some negative (a solid),
    and every sample on the lattice's faces > 0 (the solid lies inside with a margin, so the
    extension outside the box is a distance bound and not a clipped solid)."""
    v = check_array(name, values, (None, None, None))
    lo, hi = GRID_DIM_RANGE
    if not all(lo <= n <= hi for n in v.shape):
        raise PecletArgumentError(name, f"a 3-D array with {lo} to {hi} samples per axis",
                                  f"shape {v.shape}")
    h = check_float("spacing", spacing, 0.0, math.inf, lo_open=True)
    if not (v < 0.0).any():
        raise PecletArgumentError(name, "samples with at least one < 0 (inside the solid)",
                                  f"min {float(v.min())!r}")
    faces = np.concatenate([v[[0, -1]].ravel(), v[:, [0, -1]].ravel(), v[:, :, [0, -1]].ravel()])
    if not (faces > 0.0).all():
        raise PecletArgumentError(name, "samples > 0 on every face of the lattice (the solid "
                                  "inside it with a margin of at least one cell)",
                                  f"min on the faces {float(faces.min())!r}")
    return v, h


def grid_radius(values, h):
    """Radius of the proven Equation 1 ball about the leaf's origin: ``max(|x| - f)`` over the
    samples (see the module notes), raised by a relative 1e-12 against rounding."""
    x, y, z = lattice_points(values.shape, h)
    r = np.sqrt(x[:, None, None] ** 2 + y[None, :, None] ** 2 + z[None, None, :] ** 2)
    m = float((r - values).max())
    return m + 1e-12 * (abs(m) + float(r.max()))


def grid_lipschitz(values, h):
    """A proven Lipschitz constant of the grid leaf's field (dimensionless).

    In a cell, dF/dx is a bilinear blend of the cell's four x-differences over h, so
    |dF/dx| <= mx = max of their magnitudes / h (y, z alike) and |grad F| <= |(mx, my, mz)|;
    the maximum over the cells bounds the interpolant. Outside the box, the gradient is the
    unit offset on the clamped axes and F's derivatives along the free ones (orthogonal), so
    |grad| <= sqrt(1 + my^2 + mz^2) beyond an x-face (and alike), over the face's cells.
    Samples of an exact distance give about 1.0 to 1.3; the leaf counts as 1-Lipschitz only if
    this is <= 1 (docs/architecture.md §4)."""
    v = np.asarray(values, np.float64)
    ax = np.abs(np.diff(v, axis=0)) / h
    ay = np.abs(np.diff(v, axis=1)) / h
    az = np.abs(np.diff(v, axis=2)) / h
    # per cell: the largest of its four edges along each axis
    mx = np.maximum.reduce([ax[:, :-1, :-1], ax[:, 1:, :-1], ax[:, :-1, 1:], ax[:, 1:, 1:]])
    my = np.maximum.reduce([ay[:-1, :, :-1], ay[1:, :, :-1], ay[:-1, :, 1:], ay[1:, :, 1:]])
    mz = np.maximum.reduce([az[:-1, :-1, :], az[1:, :-1, :], az[:-1, 1:, :], az[1:, 1:, :]])
    inside = float(np.sqrt(mx ** 2 + my ** 2 + mz ** 2).max())
    faces = max(float((my[[0, -1]] ** 2 + mz[[0, -1]] ** 2).max()),
                float((mx[:, [0, -1]] ** 2 + mz[:, [0, -1]] ** 2).max()),
                float((mx[:, :, [0, -1]] ** 2 + my[:, :, [0, -1]] ** 2).max()))
    # a relative 1e-12 against the rounding of the differences
    return max(inside, math.sqrt(1.0 + faces)) * (1.0 + 1e-12)


def program_rows(values, cols):
    """The samples as rows of ``cols`` (x fastest, the last row zero-padded): the node table's
    data rows (cols 16) or a compiled program's (cols ``kernels.LEAF_COLS``)."""
    flat = np.asarray(values, np.float64).ravel(order="F")
    n_rows = -(-flat.size // cols)
    out = np.zeros(n_rows * cols)
    out[:flat.size] = flat
    return out.reshape(n_rows, cols)
