"""Marching-cubes surface of a CSG tree: the one place the project calls marching cubes.

phi is baked on the lattice ``lo + (i, j, k) * h``, ``h = (hi - lo) / (n - 1)`` (n points per
axis, both box faces on the lattice), and scikit-image's Lewiner marching cubes extracts the
zero level set. Vertices are in the root's parent frame (the frame of ``lo``/``hi``).

Closing the surface: when phi > 0 on every lattice point of the box's faces the surface is
already closed and the lattice is used as it is. Otherwise (the solid meets or crosses the box)
the lattice is padded by one layer of a large positive value, which puts the surface's cut
exactly (to rounding) on the box faces: the mesh is then the closed boundary of the solid
clipped to the box. Either way the mesh is watertight (every edge shared by two faces) for a
solid whose zero set the lattice resolves.

The narrow band: for a 1-Lipschitz root, only lattice values within one cell diagonal of the
surface are computed exactly (the rest are bounds of the right sign, see
:meth:`~peclet.core.geom.builder.SceneBuilder.bake`). Every corner of a cube the surface crosses
lies within one cell diagonal of it, and marching cubes reads values only through such cubes and
the signs elsewhere, so the mesh is bitwise the one of the exact bake.
"""
from __future__ import annotations

import numpy as np

from peclet.core.validation import PecletArgumentError, check_array, check_bool, check_int

__all__ = ["surface_mesh", "MAX_LATTICE"]

#: Largest accepted lattice size per axis (1024^3 doubles is 8 GiB already).
MAX_LATTICE = 1024

#: The padding layer's value, relative to the largest |phi| on the lattice plus a cell diagonal:
#: large enough that an interpolated crossing sits on the box face to rounding, small enough that
#: products of a few lattice values in the ambiguity tests stay far from overflow.
_PAD_FACTOR = 1e30


def surface_mesh(builder, root, lo, hi, n, close=True):
    """(verts (V, 3) float64, faces (F, 3) int, area) of the zero set of ``root`` in [lo, hi].

    ``builder``: a :class:`~peclet.core.geom.builder.SceneBuilder`; ``root``: a node index.
    ``lo``, ``hi``: the box corners (3 finite numbers each, lo < hi, lengths in the root's parent
    frame). ``n``: lattice points per axis, an integer in [3, 1024]; the lattice spacing is
    ``(hi - lo) / (n - 1)``. ``area`` is the mesh's area (scikit-image), which converges to the
    surface area as O(h^2) on smooth parts; sharp edges are rounded off at the lattice scale.
    ``close`` (bool): a solid reaching the box faces is clipped by them and closed there (see the
    module notes; the cut faces count in ``area``); with ``close=False`` it is left open at
    the box faces (the surface probes want only points of phi = 0). The mesh is watertight in
    the index sense: every edge is shared by exactly two faces (cut-face vertices meeting at a
    box edge may coincide in space, as marching cubes' own vertices do at exact zeros). Raises :class:`~peclet.core.validation.PecletArgumentError` for a bad
    argument and ``ValueError`` when phi does not change sign on the lattice (no surface).
    """
    from skimage import measure

    lo = check_array("lo", lo, (3,))
    hi = check_array("hi", hi, (3,))
    if not np.all(hi > lo):
        raise PecletArgumentError("hi", f"greater than lo = {lo.tolist()} on every axis",
                                  hi.tolist())
    res = check_int("n", n, 3, MAX_LATTICE)
    close = check_bool("close", close)
    sp = (hi - lo) / (res - 1)
    band = float(np.linalg.norm(sp)) if builder.is_lipschitz(root) else None
    vals = builder.bake(root, origin=lo, spacing=sp, dims=[res] * 3, band=band)
    grid = np.ascontiguousarray(vals.reshape((res, res, res), order="F"))
    if not (grid.min() < 0.0 < grid.max()):
        raise ValueError(f"no surface inside the box: phi does not change sign on the {res}^3 "
                         "lattice (n may be too coarse, or the solid is empty or fills the box)")
    origin = lo
    if close and _open_at_box(grid):
        pad = _PAD_FACTOR * (float(np.abs(grid).max()) + float(np.linalg.norm(sp)))
        grid = np.pad(grid, 1, mode="constant", constant_values=pad)
        origin = lo - sp
    verts, faces, _, _ = measure.marching_cubes(grid, level=0.0, spacing=tuple(sp))
    verts = verts + origin
    area = float(measure.mesh_surface_area(verts, faces))
    return verts, faces, area


def _open_at_box(grid):
    """True if some lattice point on the box's faces is not strictly outside (phi <= 0)."""
    return bool((grid[0].min() <= 0.0) or (grid[-1].min() <= 0.0)
                or (grid[:, 0].min() <= 0.0) or (grid[:, -1].min() <= 0.0)
                or (grid[:, :, 0].min() <= 0.0) or (grid[:, :, -1].min() <= 0.0))
