"""Exports of a frozen pack for CFD and visualisation: STL, a transforms CSV and VTU.

The element is meshed ONCE in its home frame (marching cubes of its tree through
:func:`peclet.core.geom.mesh.surface_mesh`) and every element is that mesh moved by its pose,
``v_world = R(q) v_home + p`` (quaternions (x, y, z, w), active, home -> world).

``shrink`` (a fraction of the element diameter ``d_elem``) opens point contacts for meshing: the
mesh is the level set phi = -shrink d_elem, i.e. the solid offset inward by shrink d_elem where
phi is a distance (every leaf's phi is, away from the CSG edges, where the offset surface keeps
a sharp edge). Two elements that touched are then 2 shrink d_elem apart; the element volume
falls by about shrink d_elem times its area.

Libraries: trimesh writes and reads the STL files (ASCII with one named solid per element, or
binary for one merged solid) and checks that a mesh is watertight and what volume it encloses;
meshio writes the VTU that ParaView reads (triangles, with the element id as cell data). Every
file is written through :func:`peclet.core.files.atomic_write`.
"""
from __future__ import annotations

import csv
import math
import struct

import numpy as np

from peclet.core.files import atomic_write, check_writable_path
from peclet.core.geom.mesh import MAX_LATTICE, surface_mesh
from peclet.core.validation import PecletArgumentError, check_bool, check_float

from .freeze import Pack

__all__ = ["element_mesh", "container_mesh", "bed_meshes", "write_stl", "write_vtu",
           "write_transforms_csv", "read_transforms_csv", "CSV_HEADER"]

CSV_HEADER = ("id", "element", "x", "y", "z", "qx", "qy", "qz", "qw")


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
        raise PecletArgumentError("pack", "a peclet.packing.freeze.Pack", pack)
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


def container_mesh(builder, root, lo, hi, spacing=0.125):
    """(verts, faces) of a container's wall tree (world frame, phi < 0 in the wall) clipped to
    the box [lo, hi]; the lattice has the same number of points on every axis, enough for
    ``spacing`` (a length) on the longest side. The clipped wall is a closed solid."""
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    h = check_float("container_spacing", spacing, 0.0, lo_open=True)
    n = int(math.ceil(float(np.max(hi - lo)) / h)) + 1
    if n > MAX_LATTICE:
        raise PecletArgumentError("container_spacing", "coarse enough for a lattice of at most "
                                  f"{MAX_LATTICE} points per axis", spacing)
    v, f, _ = surface_mesh(builder, root, lo, hi, n)
    return _outward(v, np.asarray(f, np.int64))


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


def write_stl(path, pack, per_element=False, spacing=0.04, d_elem=1.0, shrink=0.0,
              container=None, container_spacing=0.125, name="element", home_mesh=None):
    """Write the bed as STL; returns a dict (path, n_triangles, element_triangles, volume).

    ``per_element`` False (default): one merged binary solid, the elements' triangles in pack
    order, ``element_triangles`` each (50 bytes a triangle: about 0.5 GB for 1000 Pall rings at
    the default spacing); True: ASCII STL with one solid per element named ``{name}_{i}`` (i
    the pack index, as in the transforms CSV), then the container (if any) as the solid
    ``container`` (about 6 times larger and far slower to write; a container needs it).
    ``container``: ``(builder, root, lo, hi)``, the wall tree in the world frame clipped to the
    box [lo, hi] (see :func:`container_mesh`). ``home_mesh``: a (verts, faces) pair from
    :func:`element_mesh` to reuse; default meshes it here. ``volume`` is the home mesh's
    enclosed volume.
    """
    pack = _check_pack(pack)
    path = check_writable_path(path, "path")
    per = check_bool("per_element", per_element)
    if container is not None and not per:
        raise PecletArgumentError("per_element", "True when a container is exported (binary "
                                  "STL holds one solid)", per_element)
    if not isinstance(name, str) or not name.isidentifier():
        raise PecletArgumentError("name", "an identifier (letters, digits, _)", name)
    v0, f0 = home_mesh if home_mesh is not None else element_mesh(pack, spacing, d_elem, shrink)
    cont = container_mesh(*container, spacing=container_spacing) if container is not None \
        else None
    from trimesh.exchange import stl

    n0 = _trimesh(v0, f0).face_normals  # zero rows for zero-area faces, as trimesh has them
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
                # text, the uint32 triangle count) once, then each element's 50-byte records as
                # trimesh encodes them, so memory stays one element's worth at any bed size
                fh.write(b"peclet packed bed".ljust(80, b" "))
                fh.write(struct.pack("<I", pack.n * len(f0)))
                for i, v in enumerate(bed_meshes(pack, v0, f0)):
                    fh.write(stl.export_stl(_trimesh(v, f0, normals=n0 @ R[i].T))[84:])

    atomic_write(path, write)
    n_tri = pack.n * len(f0) + (0 if cont is None else len(cont[1]))
    return dict(path=path, n_triangles=int(n_tri), element_triangles=int(len(f0)),
                volume=float(_trimesh(v0, f0).volume))


def write_vtu(path, pack, spacing=0.04, d_elem=1.0, shrink=0.0, container=None,
              container_spacing=0.125, home_mesh=None, compress=True):
    """Write the bed as a VTU unstructured grid (meshio) for ParaView: triangle cells, cell data
    ``element_id`` (the pack index; -1 for the container). Arguments as :func:`write_stl`;
    ``compress`` zlib-compresses the arrays (about 3.5 times smaller, 5 times slower to write).
    Returns a dict (path, n_points, n_triangles)."""
    import meshio

    pack = _check_pack(pack)
    path = check_writable_path(path, "path")
    comp = "zlib" if check_bool("compress", compress) else None
    v0, f0 = home_mesh if home_mesh is not None else element_mesh(pack, spacing, d_elem, shrink)
    V = list(bed_meshes(pack, v0, f0))
    F = [f0 + i * len(v0) for i in range(pack.n)]
    ids = [np.repeat(np.arange(pack.n, dtype=np.int64), len(f0))]
    if container is not None:
        cv, cf = container_mesh(*container, spacing=container_spacing)
        F.append(cf + sum(len(v) for v in V))
        V.append(cv)
        ids.append(np.full(len(cf), -1, np.int64))
    mesh = meshio.Mesh(np.concatenate(V), [("triangle", np.concatenate(F))],
                       cell_data={"element_id": [np.concatenate(ids)]})
    atomic_write(path, lambda tmp: meshio.write(tmp, mesh, file_format="vtu", compression=comp))
    return dict(path=path, n_points=int(len(mesh.points)), n_triangles=int(sum(map(len, F))))


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
