"""Exports of a frozen pack for CFD and visualisation: STL, a transforms CSV and VTU.

The element is meshed ONCE in its home frame (marching cubes of its tree through
:func:`peclet.core.geom.mesh.surface_mesh`) and every element is that mesh moved by its pose,
``v_world = R(q) v_home + p`` (quaternions (x, y, z, w), active, home -> world).

``shrink`` (a fraction of the element diameter ``d_elem``) opens point contacts for meshing: the
mesh is the level set phi = -shrink d_elem, i.e. the solid offset inward by shrink d_elem where
phi is a distance (every leaf's phi is, away from the CSG edges, where the offset surface keeps
a sharp edge). Two elements that touched are then 2 shrink d_elem apart; the element volume
falls by about shrink d_elem times its area.

Resolution (:func:`export_mesh`, what the writers use): the marching-cubes mesh of a fine
lattice (0.02 D, finer for a thinner wall) is decimated by quadric edge collapse
(fast-simplification) to what ``resolution`` asks, given as text or a number:

* ``"Ntri"`` (e.g. ``"2000tri"``): a budget of N triangles per element, N an integer in
  [:data:`MIN_ELEMENT_TRIANGLES`, :data:`MAX_ELEMENT_TRIANGLES`]; the mesh has N (fewer if
  the lattice mesh has fewer; more only if no mesh of N triangles keeps the element closed
  with its topology: a Pall ring needs 388).
* ``"0.01"`` or ``"0.01D"`` (or the number 0.01): a chord error in element diameters D, in
  [:data:`CHORD_MIN`, :data:`CHORD_MAX`]: the fewest triangles (to 5 %) whose chord error is
  at most that. The chord error is the largest |phi| (phi + shrink d_elem with a shrink) over
  the mesh's vertices, edge midpoints and face centroids, in D: the distance from the mesh to
  the element's surface where the tree is a distance (1-Lipschitz, as every library element).

The default, :data:`DEFAULT_RESOLUTION` = ``"1000tri"``, is chosen so that 1000 elements write
a 50 MB binary STL (50 bytes a triangle) and a 22.5 MB VTU (zlib). On the Pall ring it has a
chord error of 0.0064 D and an enclosed volume 0.9 % under the exact one (the old undecimated
0.04 D lattice: 10112 triangles, 0.015 D, -4.0 %, 506 MB + 228 MB): quadric collapse keeps
the flat faces and the cylinders' curvature, and marching cubes rounds the sharp edges at its
lattice scale, which is where the volume goes. Every element mesh is checked watertight (every edge
shared by exactly two faces, consistently wound, positive volume) before it is written; a
decimation that is not is redone less aggressively or with more triangles. Bounds from memory:
the lattice has at most :data:`EXPORT_LATTICE_MAX` points per axis and the VTU, assembled in
memory by meshio, at most :data:`MAX_BED_TRIANGLES` triangles in all.

Layouts: :func:`write_stl` writes one file (binary, one merged solid; or ASCII with one named
solid per element and the container); :func:`write_stl_files` a directory of binary STL files,
one per element (and ``container.stl``).

Libraries: trimesh writes and reads the STL files (ASCII with one named solid per element, or
binary for one merged solid) and checks that a mesh is watertight and what volume it encloses;
fast-simplification decimates; meshio writes the VTU that ParaView reads (triangles, with the
element id as cell data). Every file is written through
:func:`peclet.core.files.atomic_write` (a directory of files through a temporary sibling
renamed into place).
"""
from __future__ import annotations

import csv
import math
import numbers
import os
import re
import shutil
import struct
import tempfile
from dataclasses import dataclass

import numpy as np

from peclet.core.files import atomic_write, check_writable_path
from peclet.core.geom.mesh import MAX_LATTICE, surface_mesh
from peclet.core.validation import PecletArgumentError, check_bool, check_float

from ..bed.freeze import Pack

__all__ = ["element_mesh", "export_mesh", "container_mesh", "bed_meshes", "write_stl",
           "write_stl_files", "write_vtu", "write_transforms_csv", "read_transforms_csv",
           "parse_resolution", "check_bed_triangles", "Resolution", "CSV_HEADER",
           "DEFAULT_RESOLUTION", "RESOLUTION_HELP", "MIN_ELEMENT_TRIANGLES",
           "MAX_ELEMENT_TRIANGLES", "CHORD_MIN", "CHORD_MAX", "EXPORT_LATTICE_MAX",
           "MAX_BED_TRIANGLES", "BASE_SPACING", "CONTAINER_TRIANGLES"]

CSV_HEADER = ("id", "element", "x", "y", "z", "qx", "qy", "qz", "qw")

#: The names :func:`write_stl_files` writes: the only entries it replaces in an existing
#: directory.
_EXPORTED_STL = re.compile(r"[A-Za-z_][A-Za-z0-9_]*_[0-9]+\.stl|container\.stl")

#: The export resolution when none is given: 1000 triangles per element (1000 Pall rings:
#: STL 50 MB, VTU about 23 MB).
DEFAULT_RESOLUTION = "1000tri"

#: Triangle budgets accepted per element. A budget below what keeps the element closed with
#: its topology gives the fewest triangles that do (a Pall ring: 388); above the maximum one
#: element alone is 10 MB of binary STL.
MIN_ELEMENT_TRIANGLES = 100
MAX_ELEMENT_TRIANGLES = 200_000

#: Chord errors accepted, in element diameters D. CHORD_MIN comes from memory: the lattice
#: (spacing at most the chord error) of an element of bounding radius up to 1.2 D then fits
#: in :data:`EXPORT_LATTICE_MAX` points per axis.
CHORD_MIN = 0.005
CHORD_MAX = 0.1

#: Largest marching-cubes lattice an export bakes, points per axis (512^3 doubles = 1 GiB).
EXPORT_LATTICE_MAX = 512

#: Largest bed (triangles in all, container included) written as VTU: meshio assembles the
#: whole bed in memory, about 150 bytes a triangle at its peak (3 GB here).
MAX_BED_TRIANGLES = 20_000_000

#: Largest container mesh the writers export (triangles): a column of 10 D by 37 D meshes to
#: 1.7 M triangles at the 0.125 D lattice (16 MB of VTU), decimated to 100000 (1.5 MB) with a
#: chord error of 0.044 D and its volume within 0.5 %.
CONTAINER_TRIANGLES = 100_000

#: The lattice step decimation starts from, in D (a thinner wall asks for less, see
#: :func:`export_mesh`); its marching-cubes mesh has a chord error of about half of it.
BASE_SPACING = 0.015

#: What ``resolution`` accepts, for error messages and command-line help.
RESOLUTION_HELP = (f"a chord error in element diameters D in [{CHORD_MIN:g}, {CHORD_MAX:g}] "
                   f"(e.g. 0.01 or 0.01D) or a triangle budget per element 'Ntri' with N an "
                   f"integer in [{MIN_ELEMENT_TRIANGLES}, {MAX_ELEMENT_TRIANGLES}] "
                   f"(e.g. 2000tri)")


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



def _check_pack(pack):
    if not isinstance(pack, Pack):
        raise PecletArgumentError("pack", "a peclet.packing.bed.freeze.Pack", pack)
    return pack


def element_mesh(pack, spacing=0.04, d_elem=1.0, shrink=0.0):
    """(verts (V, 3), faces (F, 3)) of one element in its home frame, outward-oriented.

    ``spacing``: the lattice step in element diameters (in (0, 0.5]); the lattice is the cube
    of half-side bounding_radius + 2 steps about the home origin. ``shrink`` in [0, 0.2):
    the inward offset as a fraction of ``d_elem`` (see the module notes).
    """
    pack = _check_pack(pack)
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


@dataclass(frozen=True)
class Resolution:
    """A parsed export resolution: ``kind`` "triangles" (``value`` the budget per element, an
    int) or "chord" (``value`` the chord error in element diameters D). ``str()`` is the
    canonical text (``"1000tri"``, ``"0.01D"``)."""

    kind: str
    value: float

    def __str__(self):
        return f"{int(self.value)}tri" if self.kind == "triangles" else f"{self.value:g}D"


def parse_resolution(value, name="resolution"):
    """A :class:`Resolution` from ``value``: text ``"Ntri"`` (a triangle budget per element) or
    ``"0.01"`` / ``"0.01D"`` (a chord error in D), a number (a chord error in D) or a
    :class:`Resolution`. Refused (:class:`PecletArgumentError` naming ``name``): anything else,
    a budget outside [:data:`MIN_ELEMENT_TRIANGLES`, :data:`MAX_ELEMENT_TRIANGLES`], a chord
    error outside [:data:`CHORD_MIN`, :data:`CHORD_MAX`] (NaN, zero and negatives included;
    below CHORD_MIN the lattice would not fit in memory)."""
    if isinstance(value, Resolution):
        value = str(value)
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (str, numbers.Real)):
        raise PecletArgumentError(name, RESOLUTION_HELP, value)
    if isinstance(value, str):
        text = value.strip().lower()
        if text.endswith("tri"):
            try:
                n = int(text[:-3])
            except ValueError:
                raise PecletArgumentError(name, RESOLUTION_HELP, value) from None
            if not MIN_ELEMENT_TRIANGLES <= n <= MAX_ELEMENT_TRIANGLES:
                raise PecletArgumentError(name, RESOLUTION_HELP, value,
                                          "triangle budget out of range")
            return Resolution("triangles", n)
        try:
            eps = float(text[:-1] if text.endswith("d") else text)
        except ValueError:
            raise PecletArgumentError(name, RESOLUTION_HELP, value) from None
    else:
        eps = float(value)
    if not (math.isfinite(eps) and CHORD_MIN <= eps <= CHORD_MAX):
        detail = "finer than memory allows" if math.isfinite(eps) and 0 < eps < CHORD_MIN \
            else "chord error out of range"
        raise PecletArgumentError(name, RESOLUTION_HELP, value, detail)
    return Resolution("chord", eps)


def check_bed_triangles(n_elements, resolution, name="resolution", per_element=None):
    """Refuse (naming ``name``) a bed whose VTU would exceed :data:`MAX_BED_TRIANGLES`:
    ``n_elements`` elements of ``per_element`` triangles, by default the budget of
    ``resolution`` (a chord error passes then: its count is known once meshed, see
    :func:`export_mesh`'s ``info``). Returns the parsed :class:`Resolution`."""
    r = parse_resolution(resolution, name)
    per = r.value if per_element is None and r.kind == "triangles" else per_element
    if per is not None and int(n_elements) * int(per) > MAX_BED_TRIANGLES:
        raise PecletArgumentError(name, f"at most {MAX_BED_TRIANGLES} triangles for the whole "
                                  f"bed (the VTU is assembled in memory)", str(r),
                                  f"{int(n_elements)} elements x {int(per)} triangles")
    return r


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
    m = _trimesh(v, f)
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

    euler = _trimesh(v, f).euler_number
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
    (see the module notes), outward-oriented and closed.

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
    pack = _check_pack(pack)
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
    vol = float(_trimesh(v, f).volume)
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


def _container(container, spacing):
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


def _trimesh(v, f, name=None, normals=None):
    """A trimesh view of (v, f). ``normals``: the face normals when known (rotated copies of
    the home mesh's), which spares trimesh recomputing them for every triangle of the bed."""
    import trimesh
    m = trimesh.Trimesh(vertices=v, faces=f, face_normals=normals, process=False)
    if name is not None:
        m.metadata["name"] = name
    return m


#: One binary STL triangle record: normal, three vertices (float32), attribute count (50 bytes).
_STL_RECORD = np.dtype([("normal", "<f4", (3,)), ("verts", "<f4", (3, 3)), ("attr", "<u2")])


def _stl_records(v, f, normals):
    """The binary STL records (bytes) of the triangles ``v[f]`` with face ``normals``."""
    rec = np.zeros(len(f), _STL_RECORD)
    rec["normal"] = normals
    rec["verts"] = v[f]
    return rec.tobytes()


def _home(pack, home_mesh, resolution, spacing, d_elem, shrink, name="resolution"):
    """(v0, f0, face normals) of the element's home mesh: ``home_mesh`` ((verts, faces), or
    the triple :func:`export_mesh` returns) or one made at ``resolution``."""
    if home_mesh is None:
        v0, f0, _ = export_mesh(pack, resolution, d_elem, shrink, spacing, name=name)
    else:
        v0, f0 = home_mesh[0], home_mesh[1]
    v0 = np.asarray(v0, np.float64)
    f0 = np.asarray(f0, np.int64)
    return v0, f0, _trimesh(v0, f0).face_normals  # zero rows for zero-area faces


def write_stl(path, pack, per_element=False, spacing=None, d_elem=1.0, shrink=0.0,
              container=None, container_spacing=0.125, name="element", home_mesh=None,
              resolution=DEFAULT_RESOLUTION):
    """Write the bed as one STL file; returns a dict (path, n_triangles, element_triangles,
    volume, bytes).

    ``per_element`` False (default): one merged binary solid, the elements' triangles in pack
    order, ``element_triangles`` each (50 bytes a triangle: 50 MB for 1000 elements at the
    default 1000 triangles); True: ASCII STL with one solid per element named ``{name}_{i}`` (i
    the pack index, as in the transforms CSV), then the container (if any) as the solid
    ``container`` (about 6 times larger and far slower to write; a container needs it).
    ``container``: ``(builder, root, lo, hi)``, the wall tree in the world frame clipped to the
    box [lo, hi] (see :func:`container_mesh`; ``container_spacing`` a length; decimated to
    :data:`CONTAINER_TRIANGLES`), or its (verts, faces) already meshed. ``home_mesh``:
    a (verts, faces) pair (or :func:`export_mesh`'s triple) to reuse; default
    :func:`export_mesh` at ``resolution`` (see the module notes), ``spacing`` (D), ``d_elem``
    (length) and ``shrink`` (fraction of D). ``volume`` is the home mesh's enclosed volume.
    """
    pack = _check_pack(pack)
    path = check_writable_path(path, "path")
    per = check_bool("per_element", per_element)
    if container is not None and not per:
        raise PecletArgumentError("per_element", "True when a container is exported (binary "
                                  "STL holds one solid)", per_element)
    if not isinstance(name, str) or not name.isidentifier():
        raise PecletArgumentError("name", "an identifier (letters, digits, _)", name)
    v0, f0, n0 = _home(pack, home_mesh, resolution, spacing, d_elem, shrink)
    cont = _container(container, container_spacing)
    from trimesh.exchange import stl

    R = pack.rotations()

    def write(tmp):
        with open(tmp, "wb") as fh:
            if per:
                for i, v in enumerate(bed_meshes(pack, v0, f0)):
                    m = _trimesh(v, f0, f"{name}_{i}", n0 @ R[i].T)
                    fh.write(stl.export_stl_ascii(m).encode())
                if cont is not None:
                    fh.write(stl.export_stl_ascii(_trimesh(*cont, "container")).encode())
            else:
                # one binary solid streamed element by element: the 84-byte header (80 bytes of
                # text, the uint32 triangle count) once, then each element's 50-byte records,
                # so memory stays one element's worth at any bed size
                fh.write(b"peclet packed bed".ljust(80, b" "))
                fh.write(struct.pack("<I", pack.n * len(f0)))
                for i, v in enumerate(bed_meshes(pack, v0, f0)):
                    fh.write(_stl_records(v, f0, n0 @ R[i].T))

    atomic_write(path, write)
    n_tri = pack.n * len(f0) + (0 if cont is None else len(cont[1]))
    return dict(path=path, n_triangles=int(n_tri), element_triangles=int(len(f0)),
                volume=float(_trimesh(v0, f0).volume), bytes=os.path.getsize(path))


def _check_directory(path, name="path"):
    """The absolute ``path`` if it can be created or replaced as a directory, else
    :class:`PecletArgumentError` naming ``name``."""
    p = os.path.abspath(os.fspath(path))
    if os.path.lexists(p) and not os.path.isdir(p):
        raise PecletArgumentError(name, "a directory path", os.fspath(path), "it is a file")
    check_writable_path(os.path.join(p, "probe.stl"), name)
    return p


def write_stl_files(directory, pack, spacing=None, d_elem=1.0, shrink=0.0, container=None,
                    container_spacing=0.125, name="element", home_mesh=None,
                    resolution=DEFAULT_RESOLUTION):
    """Write the bed as a directory of binary STL files, one closed solid each:
    ``{name}_{i}.stl`` for element i (the pack index, zero-padded to the same width, as in the
    transforms CSV) and ``container.stl`` (with ``container``). Arguments as
    :func:`write_stl`. The directory is filled under a temporary name and renamed into place,
    replacing an existing one whole (a reader sees the old set or the new one); an existing
    one that holds anything but such STL files is refused, naming the entry, before any work.
    Returns a dict (path, files (names, sorted), n_triangles, element_triangles, volume,
    bytes)."""
    pack = _check_pack(pack)
    path = _check_directory(directory, "directory")
    if os.path.isdir(path):
        for entry in sorted(os.listdir(path)):
            q = os.path.join(path, entry)
            if not _EXPORTED_STL.fullmatch(entry) or not os.path.isfile(q) or os.path.islink(q):
                raise PecletArgumentError(
                    "directory", "a new directory or one holding only an earlier export's "
                    "<name>_<i>.stl and container.stl", os.fspath(directory),
                    f"{entry} in it is not such a file (it would be removed with the old set)")
    if not isinstance(name, str) or not name.isidentifier() or name == "container":
        raise PecletArgumentError("name", "an identifier (letters, digits, _) other than "
                                  "'container'", name)
    v0, f0, n0 = _home(pack, home_mesh, resolution, spacing, d_elem, shrink)
    cont = _container(container, container_spacing)
    R = pack.rotations()
    width = len(str(pack.n - 1))
    header = b"peclet packed bed element".ljust(80, b" ") + struct.pack("<I", len(f0))
    files = []

    def fill(tmp):
        for i, v in enumerate(bed_meshes(pack, v0, f0)):
            files.append(f"{name}_{i:0{width}d}.stl")
            with open(os.path.join(tmp, files[-1]), "wb") as fh:
                fh.write(header)
                fh.write(_stl_records(v, f0, n0 @ R[i].T))
        if cont is not None:
            files.append("container.stl")
            cm = _trimesh(*cont)
            with open(os.path.join(tmp, files[-1]), "wb") as fh:
                fh.write(b"peclet container".ljust(80, b" ") + struct.pack("<I", len(cont[1])))
                fh.write(_stl_records(cont[0], cont[1], cm.face_normals))

    parent = os.path.dirname(path)
    os.makedirs(parent, exist_ok=True)
    tmp = tempfile.mkdtemp(prefix=".peclet-tmp-" + os.path.basename(path) + "-", dir=parent)
    old = None
    try:
        fill(tmp)
        os.chmod(tmp, 0o777 & ~_umask())
        if os.path.isdir(path):
            old = tempfile.mkdtemp(prefix=".peclet-old-" + os.path.basename(path) + "-",
                                   dir=parent)
            os.rmdir(old)
            os.rename(path, old)
        os.rename(tmp, path)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        if old is not None and not os.path.exists(path):
            os.rename(old, path)
            old = None
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
    n_tri = pack.n * len(f0) + (0 if cont is None else len(cont[1]))
    return dict(path=path, files=sorted(files), n_triangles=int(n_tri),
                element_triangles=int(len(f0)), volume=float(_trimesh(v0, f0).volume),
                bytes=sum(os.path.getsize(os.path.join(path, f)) for f in files))


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_vtu(path, pack, spacing=None, d_elem=1.0, shrink=0.0, container=None,
              container_spacing=0.125, home_mesh=None, compress=True,
              resolution=DEFAULT_RESOLUTION):
    """Write the bed as a VTU unstructured grid (meshio) for ParaView: triangle cells, cell data
    ``element_id`` (the pack index; -1 for the container). Arguments as :func:`write_stl`
    (the same ``resolution``); ``compress`` zlib-compresses the arrays (about 3.5 times
    smaller, 5 times slower to write). The bed is assembled in memory: more than
    :data:`MAX_BED_TRIANGLES` triangles are refused (naming ``resolution``). Returns a dict
    (path, n_points, n_triangles, bytes)."""
    import meshio

    pack = _check_pack(pack)
    path = check_writable_path(path, "path")
    comp = "zlib" if check_bool("compress", compress) else None
    v0, f0, _ = _home(pack, home_mesh, resolution, spacing, d_elem, shrink)
    cont = _container(container, container_spacing)
    n_tri = pack.n * len(f0) + (0 if cont is None else len(cont[1]))
    if n_tri > MAX_BED_TRIANGLES:
        raise PecletArgumentError("resolution", f"at most {MAX_BED_TRIANGLES} triangles for "
                                  "the whole bed (the VTU is assembled in memory)",
                                  resolution, f"{pack.n} elements x {len(f0)} triangles")
    V = list(bed_meshes(pack, v0, f0))
    F = [f0 + i * len(v0) for i in range(pack.n)]
    ids = [np.repeat(np.arange(pack.n, dtype=np.int64), len(f0))]
    if cont is not None:
        cv, cf = cont
        F.append(cf + sum(len(v) for v in V))
        V.append(cv)
        ids.append(np.full(len(cf), -1, np.int64))
    mesh = meshio.Mesh(np.concatenate(V), [("triangle", np.concatenate(F))],
                       cell_data={"element_id": [np.concatenate(ids)]})
    del V, F, ids
    atomic_write(path, lambda tmp: meshio.write(tmp, mesh, file_format="vtu", compression=comp))
    return dict(path=path, n_points=int(len(mesh.points)), n_triangles=int(n_tri),
                bytes=os.path.getsize(path))


def write_transforms_csv(path, pack, element="element"):
    """Write ``id, element, x, y, z, qx, qy, qz, qw`` per element (world frame, quaternion
    (x, y, z, w) home -> world), floats as ``repr`` so they read back bit for bit."""
    pack = _check_pack(pack)
    path = check_writable_path(path, "path")
    if not isinstance(element, str) or not element or "," in element or "\n" in element:
        raise PecletArgumentError("element", "a non-empty name without commas or newlines",
                                  element)

    def write(tmp):
        with open(tmp, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(CSV_HEADER)
            for i, (p, q) in enumerate(zip(pack.positions, pack.quaternions)):
                w.writerow([i, element] + [repr(float(v)) for v in (*p, *q)])

    return atomic_write(path, write)


def read_transforms_csv(path):
    """Read a transforms CSV: dict(ids (N,), element (list of str), positions (N, 3),
    quaternions (N, 4))."""
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    if not rows or tuple(rows[0]) != CSV_HEADER:
        raise ValueError(f"{path}: not a transforms CSV (header {','.join(CSV_HEADER)})")
    body = rows[1:]
    num = np.array([[float(v) for v in r[2:9]] for r in body], dtype=np.float64).reshape(-1, 7)
    return dict(ids=np.array([int(r[0]) for r in body], np.int64),
                element=[r[1] for r in body], positions=num[:, :3], quaternions=num[:, 3:])
