"""The meshes the writers move into place: one element's home-frame mesh
(:func:`element_mesh` on a marching-cubes lattice, :func:`export_mesh` decimated to a
resolution and checked closed), a container's wall (:func:`container_mesh`) and the bed's
element meshes (:func:`bed_meshes`). Shrink, resolution, decimation and the watertight check
are stated in the notes of :mod:`peclet.packing.output.export`."""
from __future__ import annotations

import math

import numpy as np

from peclet.core.geom.mesh import MAX_LATTICE, surface_mesh
from peclet.core.validation import PecletArgumentError, check_float

from ..bed.freeze import Pack
from .resolution import (DEFAULT_RESOLUTION, MIN_ELEMENT_TRIANGLES, RESOLUTION_HELP,
                         parse_resolution)

__all__ = ["element_mesh", "export_mesh", "container_mesh", "bed_meshes", "bed_container",
           "home_of", "check_pack", "as_trimesh", "EXPORT_LATTICE_MAX", "BASE_SPACING",
           "CONTAINER_TRIANGLES"]

#: Largest marching-cubes lattice an export bakes, points per axis (512^3 doubles = 1 GiB).
EXPORT_LATTICE_MAX = 512

#: Largest container mesh the writers export (triangles): a column of 10 D by 37 D meshes to
#: 1.7 M triangles at the 0.125 D lattice (16 MB of VTU), decimated to 100000 (1.5 MB) with a
#: chord error of 0.044 D and its volume within 0.5 %.
CONTAINER_TRIANGLES = 100_000

#: The lattice step decimation starts from, in D (a thinner wall asks for less, see
#: :func:`export_mesh`); its marching-cubes mesh has a chord error of about half of it.
BASE_SPACING = 0.015


class _Offset:
    """The builder seen through phi + s: its zero set is the solid shrunk by s (s >= 0).

    Only what :func:`surface_mesh` uses is provided. The narrow band is widened by s: values
    with |phi + s| <= band need |phi| <= band + s, and outside that band the bake returns
    bounds of the right sign with |phi| > band + s, so phi + s keeps its sign there too.
    """

    def __init__(self, builder, s):
        self.builder = builder
        self.s = float(s)

    def is_lipschitz(self, root):
        return self.builder.is_lipschitz(root)

    def bake(self, root, origin, spacing, dims, band=None):
        b = None if band is None else band + self.s
        return self.builder.bake(root, origin=origin, spacing=spacing, dims=dims, band=b) + self.s


def check_pack(pack):
    """``pack`` if it is a :class:`~peclet.packing.bed.freeze.Pack`, else
    :class:`PecletArgumentError` naming "pack"."""
    if not isinstance(pack, Pack):
        raise PecletArgumentError("pack", "a peclet.packing.bed.freeze.Pack", pack)
    return pack


def element_mesh(pack, spacing=0.04, d_elem=1.0, shrink=0.0):
    """(verts (V, 3), faces (F, 3)) of one element in its home frame, outward-oriented.

    ``spacing``: the lattice step in element diameters (in (0, 0.5]); the lattice is the cube
    of half-side bounding_radius + 2 steps about the home origin. ``shrink`` in [0, 0.2):
    the inward offset as a fraction of ``d_elem`` (see the notes of
    :mod:`peclet.packing.output.export`).
    """
    pack = check_pack(pack)
    d = check_float("d_elem", d_elem, 0.0, lo_open=True)
    h = check_float("spacing", spacing, 0.0, 0.5, lo_open=True) * d
    s = check_float("shrink", shrink, 0.0, 0.2, hi_open=True) * d
    half = pack.bounding_radius + 2.0 * h
    n = int(math.ceil(2.0 * half / h)) + 1
    if n > MAX_LATTICE:
        raise PecletArgumentError("spacing", f"at least {2 * half / (MAX_LATTICE - 1) / d:.3g} "
                                  "element diameters (the lattice limit)", spacing)
    b = pack.builder()
    try:
        v, f, _ = surface_mesh(_Offset(b, s), pack.home_root, [-half] * 3, [half] * 3, n)
    except ValueError as e:  # no sign change: the shrink ate the element
        raise PecletArgumentError("shrink", "small enough to leave a solid at this spacing",
                                  shrink, str(e)) from None
    return _outward(v, np.asarray(f, np.int64))


def _outward(v, f):
    """The mesh welded and oriented so its enclosed volume is positive (normals outward).

    Welding: a lattice value of exactly 0 puts the vertices of every edge through that lattice
    point at the same place, as distinct vertices joined by zero-area triangles; readers that
    merge equal vertices (trimesh, CFD meshers) would see those triangles collapse. Equal
    vertices are merged here and the collapsed triangles dropped, which keeps every edge shared
    by exactly two faces.
    """
    v, inv = np.unique(v, axis=0, return_inverse=True)
    f = inv.reshape(-1)[f]
    f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])]
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    if np.einsum("ij,ij->i", a, np.cross(b, c)).sum() < 0.0:
        f = f[:, ::-1].copy()
    return v, f


def _chord_error(builder, root, v, f, s):
    """max |phi + s| over the vertices, edge midpoints and face centroids of (v, f) (length)."""
    tri = v[f]
    pts = np.vstack([v, tri.mean(axis=1), 0.5 * (tri[:, 0] + tri[:, 1]),
                     0.5 * (tri[:, 1] + tri[:, 2]), 0.5 * (tri[:, 2] + tri[:, 0])])
    return float(np.abs(builder.eval_root(root, pts) + s).max())


def _closed(v, f, euler=None):
    """True if (v, f) is watertight (every edge in exactly two faces), consistently wound,
    encloses a positive volume and (with ``euler``) has that Euler number, i.e. the lattice
    mesh's topology (trimesh's checks, vertices as given)."""
    m = as_trimesh(v, f)
    return bool(len(f) >= 4 and m.is_watertight and m.is_winding_consistent
                and m.volume > 0.0 and (euler is None or m.euler_number == euler))


#: Quadric-collapse aggressiveness tried, best first (fast-simplification's default 7 has
#: twice the chord error of 5 on the Pall ring at 1000 triangles and sometimes leaves an edge
#: in four faces; 3 may stop short of the target count).
_AGGRESSIVENESS = (5.0, 4.0, 3.0, 7.0)


def _decimations(v, f, count, aggs=_AGGRESSIVENESS):
    """Each closed (v, f) that quadric edge collapse (fast-simplification) makes of the
    lattice mesh (v, f) with about ``count`` triangles, one per aggressiveness in ``aggs``,
    welded and outward; meshes that are not closed or change the topology are left out."""
    import fast_simplification

    euler = as_trimesh(v, f).euler_number
    for agg in aggs:
        vv, ff = fast_simplification.simplify(np.ascontiguousarray(v, np.float64),
                                              np.ascontiguousarray(f, np.int32),
                                              target_count=int(count), agg=agg)
        vv, ff = _outward(np.asarray(vv, np.float64), np.asarray(ff, np.int64))
        if _closed(vv, ff, euler):
            yield vv, ff


def export_mesh(pack, resolution=DEFAULT_RESOLUTION, d_elem=1.0, shrink=0.0, spacing=None,
                min_feature=None, name="resolution"):
    """(verts (V, 3), faces (F, 3), info) of one element in its home frame at ``resolution``
    (see the notes of :mod:`peclet.packing.output.export`), outward-oriented and closed.

    ``d_elem``: the element diameter D (length); ``shrink`` as :func:`element_mesh`.
    ``spacing``: the lattice step in D that decimation starts from (default
    :data:`BASE_SPACING` and 4/3 of it, the better result kept; at most a third of
    ``min_feature``, the thinnest wall as a length, when given; a budget above a quarter of
    the lattice mesh's triangles refines it, a chord error below the lattice mesh's own
    too). ``name``: the argument named in errors about the resolution (e.g.
    ``"--stl-resolution"``).

    A budget keeps, of the closed decimations of each lattice (see :func:`_decimations`), the
    one with the smallest chord error and at most N triangles (if none has, the closed one
    with the fewest). A chord error bisects the triangle count (to 5 %) for the fewest
    triangles whose decimation stays within it.

    ``info``: ``resolution`` (canonical text), ``triangles``, ``vertices``, ``chord_error``
    (D), ``lattice_spacing`` (D) and ``lattice_triangles`` (the mesh decimated), ``volume``
    (length^3, enclosed), ``volume_rel_error`` ((volume - pack.ring_volume) /
    pack.ring_volume; None with a shrink), ``watertight`` (True).
    """
    pack = check_pack(pack)
    res = parse_resolution(resolution, name)
    d = check_float("d_elem", d_elem, 0.0, lo_open=True)
    s_frac = check_float("shrink", shrink, 0.0, 0.2, hi_open=True)
    if spacing is None:
        h = BASE_SPACING
        if min_feature is not None and math.isfinite(float(min_feature)) \
                and float(min_feature) > 0.0:
            h = min(h, float(min_feature) / d / 3.0)
        steps = [h, 4.0 * h / 3.0]
    else:
        h = check_float("spacing", spacing, 0.0, 0.5, lo_open=True)
        steps = [h]
    h_min = 2.0 * pack.bounding_radius / d / (EXPORT_LATTICE_MAX - 5)
    if res.kind == "chord":
        steps = [min(h, res.value)]
    if min(steps) < h_min:
        raise PecletArgumentError(name, f"coarse enough for a lattice of at most "
                                  f"{EXPORT_LATTICE_MAX} points per axis (a step of at least "
                                  f"{h_min:.3g} D for this element)", str(res),
                                  "finer than memory allows")
    b = pack.builder()
    s = s_frac * d

    def chord(v, f):
        return _chord_error(b, pack.home_root, v, f, s) / d

    def lattice(step):
        v, f = element_mesh(pack, step, d, s_frac)
        return step, v, f

    best = None  # (key, v, f, chord error, step, lattice triangles)
    if res.kind == "triangles":
        n = int(res.value)
        first = lattice(steps[0])
        if len(first[2]) < 4 * n and steps[0] > h_min:  # start from about 4 x the budget
            first = lattice(max(h_min, steps[0] * math.sqrt(len(first[2]) / (4.0 * n))))
            steps = [first[0]]
        for step, v, f in [first] + [lattice(st) for st in steps[1:]]:
            cands = [(v, f)] if len(f) <= n else list(_decimations(v, f, n))
            for vv, ff in cands + ([] if len(f) <= n else [(v, f)]):
                e = chord(vv, ff)
                key = (len(ff) > n, e if len(ff) <= n else len(ff))
                if best is None or key < best[0]:
                    best = (key, vv, ff, e, step, len(f))
    else:
        step, v, f = lattice(steps[0])
        e0 = chord(v, f)
        while e0 > res.value and step > h_min:
            step, v, f = lattice(max(h_min, step / 1.5))
            e0 = chord(v, f)
        if e0 > res.value:
            raise PecletArgumentError(name, RESOLUTION_HELP, str(res), "finer than memory "
                                      f"allows: the finest lattice reaches {e0:.3g} D")
        best = ((False, e0), v, f, e0, step, len(f))
        lo, hi = MIN_ELEMENT_TRIANGLES, len(f)  # hi: the lattice mesh itself passes
        while hi > 1.05 * lo:
            mid = int(math.sqrt(lo * hi))
            ok = None
            for vv, ff in _decimations(v, f, mid, _AGGRESSIVENESS[:2]):
                e = chord(vv, ff)
                if e <= res.value and len(ff) < hi:
                    ok = (vv, ff, e)
                    break
            if ok is None:
                lo = mid
            else:
                hi = len(ok[1])
                best = ((False, ok[2]), ok[0], ok[1], ok[2], step, len(f))
    _, v, f, err, step, n_lattice = best
    vol = float(as_trimesh(v, f).volume)
    info = dict(resolution=str(res), triangles=int(len(f)), vertices=int(len(v)),
                chord_error=float(err), lattice_spacing=float(step),
                lattice_triangles=int(n_lattice), volume=vol,
                volume_rel_error=None if s_frac > 0 else
                float((vol - pack.ring_volume) / pack.ring_volume),
                watertight=_closed(v, f))
    return v, f, info


def container_mesh(builder, root, lo, hi, spacing=0.125, max_triangles=None):
    """(verts, faces) of a container's wall tree (world frame, phi < 0 in the wall) clipped to
    the box [lo, hi]; the lattice has the same number of points on every axis, enough for
    ``spacing`` (a length) on the longest side. The clipped wall is a closed solid.
    ``max_triangles`` (default None: the lattice mesh as it is): decimate a larger mesh to
    that many triangles (quadric collapse, kept only if closed with the same topology; the
    writers use :data:`CONTAINER_TRIANGLES`)."""
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    h = check_float("container_spacing", spacing, 0.0, lo_open=True)
    n = int(math.ceil(float(np.max(hi - lo)) / h)) + 1
    if n > MAX_LATTICE:
        raise PecletArgumentError("container_spacing", "coarse enough for a lattice of at most "
                                  f"{MAX_LATTICE} points per axis", spacing)
    v, f, _ = surface_mesh(builder, root, lo, hi, n)
    v, f = _outward(v, np.asarray(f, np.int64))
    if max_triangles is not None and len(f) > int(max_triangles):
        for m in _decimations(v, f, int(max_triangles), _AGGRESSIVENESS[:1]):
            return m
    return v, f


def bed_container(container, spacing):
    """The container's (verts, faces): None; a (verts, faces) pair as given (e.g. meshed once
    for several files); or ``(builder, root, lo, hi)`` meshed by :func:`container_mesh` at
    ``spacing`` and decimated to :data:`CONTAINER_TRIANGLES`."""
    if container is None:
        return None
    if len(container) == 2:
        return np.asarray(container[0], np.float64), np.asarray(container[1], np.int64)
    return container_mesh(*container, spacing=spacing, max_triangles=CONTAINER_TRIANGLES)


def bed_meshes(pack, verts, faces):
    """Generator of each element's world-frame vertices (the home mesh moved by its pose)."""
    R = pack.rotations()
    for i in range(pack.n):
        yield verts @ R[i].T + pack.positions[i]


def as_trimesh(v, f, name=None, normals=None):
    """A trimesh view of (v, f). ``normals``: the face normals when known (rotated copies of
    the home mesh's), which spares trimesh recomputing them for every triangle of the bed."""
    import trimesh
    m = trimesh.Trimesh(vertices=v, faces=f, face_normals=normals, process=False)
    if name is not None:
        m.metadata["name"] = name
    return m


def home_of(pack, home_mesh, resolution, spacing, d_elem, shrink, name="resolution"):
    """(v0, f0, face normals) of the element's home mesh: ``home_mesh`` ((verts, faces), or
    the triple :func:`export_mesh` returns) or one made at ``resolution``."""
    if home_mesh is None:
        v0, f0, _ = export_mesh(pack, resolution, d_elem, shrink, spacing, name=name)
    else:
        v0, f0 = home_mesh[0], home_mesh[1]
    v0 = np.asarray(v0, np.float64)
    f0 = np.asarray(f0, np.int64)
    return v0, f0, as_trimesh(v0, f0).face_normals  # zero rows for zero-area faces
