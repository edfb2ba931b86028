"""Grid leaves from what a user has: a Python callable, a triangle mesh, a saved grid.

Each maker samples a signed distance on a lattice and adds it to a
:class:`~peclet.core.geom.builder.SceneBuilder` as a grid leaf (:meth:`add_grid`), placed so
that the solid stands where the source put it (the leaf's lattice is centred on its own origin;
the leaf's translation is the lattice's centre in the source's frame). Each returns the leaf's
node index; compose it in CSG like any leaf.

- :func:`grid_from_callable`: ``phi(points (N, 3)) -> (N,)`` over given bounds (negative
  inside, a distance or anything with the right sign whose zero set is the surface; the grid is
  only as good as phi is a distance near the surface);
- :func:`grid_from_mesh`: a closed, consistently wound triangle mesh (STL, OBJ, PLY, read by
  trimesh), signed distance by libigl: the distance to the nearest triangle, the sign from the
  generalised winding number (robust to the small gaps, duplicate vertices and
  self-intersections of real CAD output, where a pseudo-normal sign flips whole regions);
  :func:`mesh_mass_properties` gives the mesh's exact mass properties (divergence theorem) to
  check the grid's quadrature against;
- :func:`grid_from_npz` / :func:`save_grid`: a grid saved as ``values`` (nx, ny, nz),
  ``spacing`` and ``origin`` (the lattice's first sample), e.g. a CT scan's level set.

Resolution: ``spacing`` (a length) or, for a mesh, from its thinnest part: ``2 V / A`` (volume
over area) is the thickness of a plate and 2/3 of a sphere's radius, and the default spacing is
a sixth of it (a 0.12 D ring wall gets about 12 cells across; a sphere 27 across its
diameter). A margin of two cells is added around the bounds, so the faces' samples are outside.
The lattice is a cube (the longest side's samples on every axis), so that the quadrature's top
cells can be the lattice's own cells (:func:`quadrature_layout`): inside one lattice cell the
field is one trilinear polynomial, with no crease for the break search to locate. Measured on
a sampled unit sphere at h = 0.2: 3.0 s and a volume error estimate of 2e-14 aligned, against
15-24 s and 8e-8 with 4 lattice cells in each top cell (a loaded two-core machine).
"""
from __future__ import annotations

import math
import os
from typing import NamedTuple

import numpy as np

from peclet.core.files import atomic_write
from peclet.core.validation import PecletArgumentError, check_array, check_float

from .leaves import GRID, GRID_DIM_RANGE
from .quadrature.constants import V_PROBES
from .sampled import lattice_points

__all__ = ["grid_from_callable", "grid_from_mesh", "grid_from_npz", "save_grid", "load_mesh",
           "mesh_mass_properties", "MeshMassProperties", "MARGIN_CELLS", "quadrature_layout"]

#: Cells of margin added on every side of the bounds.
MARGIN_CELLS = 2
#: Top quadrature cells a side at most in :func:`quadrature_layout` (30^3 = 27,000 of the
#: quadrature's 50,000-cell budget, the rest left for refinement).
TOP_CELLS_A_SIDE = 30
#: The default spacing is the mesh's thickness 2 V / A over this.
CELLS_PER_THICKNESS = 6.0


class MeshMassProperties(NamedTuple):
    """Exact mass properties of a closed mesh at unit density (divergence theorem): volume
    (length^3), com (3,) and inertia (3, 3) about the com, in the mesh's frame."""

    volume: float
    com: np.ndarray
    inertia: np.ndarray


def _lattice(lo, hi, spacing):
    """(centre (3,), dims (3,), spacing) of the centred lattice covering [lo, hi] plus margin."""
    lo = check_array("lo", lo, (3,))
    hi = check_array("hi", hi, (3,))
    if not np.all(hi > lo):
        raise PecletArgumentError("hi", f"greater than lo = {lo.tolist()} on every axis",
                                  hi.tolist())
    h = check_float("spacing", spacing, 0.0, math.inf, lo_open=True)
    # a cube of samples: the quadrature's top cells can then be the lattice's cells
    dims = np.full(3, int(np.ceil(float((hi - lo).max()) / h)) + 1 + 2 * MARGIN_CELLS)
    lo_n, hi_n = GRID_DIM_RANGE
    if np.any(dims > hi_n):
        raise PecletArgumentError("spacing", f"a spacing giving at most {hi_n} samples per "
                                  f"axis over the bounds {(hi - lo).tolist()} (>= "
                                  f"{float((hi - lo).max()) / (hi_n - 1 - 2 * MARGIN_CELLS):.4g})",
                                  h)
    return 0.5 * (lo + hi), dims, h


def _sample(field, centre, dims, h):
    """field(points (N, 3)) on the centred lattice about ``centre``; values (nx, ny, nz)."""
    x, y, z = lattice_points(dims, h)
    X, Y, Z = np.meshgrid(x + centre[0], y + centre[1], z + centre[2], indexing="ij")
    pts = np.column_stack([X.ravel(order="F"), Y.ravel(order="F"), Z.ravel(order="F")])
    return field(pts), pts


def grid_from_callable(builder, phi, lo, hi, spacing):
    """A grid leaf of ``phi`` (a callable taking points (N, 3) float64 and returning (N,)
    values: negative inside, lengths) sampled over [lo, hi] (3 numbers each, the solid inside
    them) plus a margin of :data:`MARGIN_CELLS` cells, at ``spacing`` (a length > 0; at most
    1024 samples per axis). Returns the leaf's node index."""
    centre, dims, h = _lattice(lo, hi, spacing)

    def field(pts):
        v = np.asarray(phi(pts), dtype=np.float64)
        if v.shape != (len(pts),):
            raise PecletArgumentError("phi", f"a callable returning one value per point, shape "
                                      f"({len(pts)},)", f"shape {v.shape}")
        return v
    values, _ = _sample(field, centre, dims, h)
    return _add(builder, values.reshape(tuple(dims), order="F"), h, centre, "phi")


def _add(builder, values, h, centre, source):
    try:
        return builder.add_grid(values, h, translation=centre)
    except PecletArgumentError as e:
        raise PecletArgumentError(source, "a field whose solid lies inside the bounds (samples "
                                  "> 0 on the lattice's faces) and is not empty",
                                  f"{values.shape} samples", str(e)) from None


def quadrature_layout(builder, root):
    """``(lo (3,), hi (3,), n)`` for :func:`peclet.core.geom.body_properties` whose top-level
    quadrature cells are made of whole lattice cells of ``root`` (k^3 each, k the smallest that
    keeps at most :data:`TOP_CELLS_A_SIDE` top cells a side, within the quadrature's budget of
    cells with room to refine),
    when ``root`` is a grid leaf with a cubic lattice and no rotation (what the makers here
    build); None otherwise. The box starts at the lattice's first sample (``root``'s parent
    frame) and spans a whole number of top cells; ``n = V_PROBES * top cells``, so
    ``ceil(n / V_PROBES)`` top cells per axis fall on lattice planes."""
    kind, _, _, params, t, q, s = builder.node(root)
    if kind != GRID:
        return None
    dims = params[1:4].astype(int)
    if not (dims[0] == dims[1] == dims[2]) or not np.array_equal(q, [0.0, 0.0, 0.0, 1.0]):
        return None
    cells = int(dims[0]) - 1
    k = -(-cells // TOP_CELLS_A_SIDE)
    top = -(-cells // k)
    h = float(params[4]) * s
    lo = t - 0.5 * cells * h
    return lo, lo + top * k * h, int(V_PROBES * top)


def load_mesh(mesh):
    """(vertices (V, 3) float64, faces (F, 3) int64) of ``mesh``: a path to an STL, OBJ or PLY
    file, a ``trimesh.Trimesh``, or a (vertices, faces) pair. Checked: not empty, closed
    (every edge shared by two faces) and consistently wound; a mesh wound inside out (negative
    volume) is turned the right way out (the one repair made, and a harmless one).
    PecletArgumentError naming ``mesh`` otherwise."""
    import trimesh
    if isinstance(mesh, (str, os.PathLike)):
        if not os.path.isfile(mesh):
            raise PecletArgumentError("mesh", "a path to an existing STL, OBJ or PLY file",
                                      os.fspath(mesh))
        m = trimesh.load(os.fspath(mesh), force="mesh", process=True)
    elif isinstance(mesh, trimesh.Trimesh):
        m = mesh.copy()
    else:
        try:
            v, f = mesh
        except (TypeError, ValueError):
            raise PecletArgumentError("mesh", "a path, a trimesh.Trimesh or a (vertices, "
                                      "faces) pair", type(mesh).__name__) from None
        m = trimesh.Trimesh(np.asarray(v, float), np.asarray(f, np.int64), process=True)
    if len(m.faces) == 0:
        raise PecletArgumentError("mesh", "a mesh with triangles", "an empty mesh")
    if not np.all(np.isfinite(m.vertices)):
        raise PecletArgumentError("mesh", "finite vertex coordinates", "NaN or inf vertices")
    if not m.is_watertight:
        raise PecletArgumentError("mesh", "a closed mesh (every edge shared by exactly two "
                                  "faces): a solid's boundary", f"{len(m.faces)} faces with "
                                  "open or non-manifold edges; close it in the CAD tool or "
                                  "with trimesh.repair.fill_holes")
    if not m.is_winding_consistent:
        raise PecletArgumentError("mesh", "consistently wound faces", "inconsistent winding; "
                                  "trimesh.repair.fix_winding may repair it")
    if m.volume < 0.0:
        m.invert()
    return np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)


def mesh_mass_properties(mesh) -> MeshMassProperties:
    """Exact volume, com and inertia about the com (unit density) of a closed mesh
    (:func:`load_mesh`'s argument), by the divergence theorem (trimesh)."""
    import trimesh
    v, f = load_mesh(mesh)
    m = trimesh.Trimesh(v, f, process=False)
    return MeshMassProperties(float(m.volume), np.asarray(m.center_mass, float),
                              np.asarray(m.moment_inertia, float))


def default_spacing(vertices, faces):
    """A sixth of the mesh's thickness ``2 V / A`` (see the module notes), a length."""
    import trimesh
    m = trimesh.Trimesh(vertices, faces, process=False)
    return 2.0 * float(m.volume) / float(m.area) / CELLS_PER_THICKNESS


def grid_from_mesh(builder, mesh, spacing=None, scale=1.0):
    """A grid leaf of a closed triangle mesh (:func:`load_mesh`), its coordinates times
    ``scale`` (> 0; e.g. 1e-3 for a file in mm used in m), sampled at ``spacing`` (a length in
    the scaled units; default :func:`default_spacing`) over its bounding box plus a margin.
    Signed distance: libigl, sign by the winding number. Returns the leaf's node index."""
    v, f = load_mesh(mesh)
    s = check_float("scale", scale, 0.0, math.inf, lo_open=True)
    v = v * s
    h = default_spacing(v, f) if spacing is None else spacing
    centre, dims, h = _lattice(v.min(axis=0), v.max(axis=0), h)

    def field(pts):
        import igl
        d, _, _, _ = igl.signed_distance(
            pts, v, f, sign_type=igl.SignedDistanceType.SIGNED_DISTANCE_TYPE_WINDING_NUMBER)
        return np.asarray(d, np.float64)
    values, _ = _sample(field, centre, dims, h)
    return _add(builder, values.reshape(tuple(dims), order="F"), h, centre, "mesh")


def save_grid(path, values, spacing, origin=(0.0, 0.0, 0.0)):
    """Write a grid to ``path`` (.npz; temporary file then rename): ``values`` (nx, ny, nz)
    signed distances (x, y, z order; lengths), ``spacing`` and ``origin`` (the position of
    sample (0, 0, 0)). Returns the path."""
    v = check_array("values", values, (None, None, None))
    h = check_float("spacing", spacing, 0.0, math.inf, lo_open=True)
    o = check_array("origin", origin, (3,))

    def write(tmp):
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, values=v, spacing=np.float64(h), origin=o)
    return atomic_write(path, write)


def grid_from_npz(builder, path):
    """A grid leaf from a file written by :func:`save_grid` (``values``, ``spacing``,
    ``origin``), placed where its samples stand. Returns the leaf's node index."""
    try:
        with np.load(os.fspath(path)) as z:
            values, h, origin = z["values"], float(z["spacing"]), z["origin"]
    except (OSError, KeyError, ValueError) as e:
        raise PecletArgumentError("path", "an .npz file with arrays values (nx, ny, nz), "
                                  "spacing and origin (3,)", os.fspath(path), str(e)) from None
    values = check_array("values", values, (None, None, None))
    origin = check_array("origin", origin, (3,))
    centre = origin + 0.5 * (np.array(values.shape) - 1) * h
    return _add(builder, values, h, centre, "path")
