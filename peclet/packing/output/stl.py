"""The bed as STL (the layouts in the notes of :mod:`peclet.packing.output.export`):
:func:`write_stl` one file (one merged binary solid, or ASCII with one named solid per
element and the container), :func:`write_stl_files` a directory of binary STL files, one per
element (and ``container.stl``)."""
from __future__ import annotations

import os
import re
import shutil
import struct
import tempfile

import numpy as np

from peclet.core.files import atomic_write, check_writable_path
from peclet.core.validation import PecletArgumentError, check_bool

from .meshing import as_trimesh, bed_container, bed_meshes, check_pack, home_of
from .resolution import DEFAULT_RESOLUTION

__all__ = ["write_stl", "write_stl_files"]

#: The names :func:`write_stl_files` writes: the only entries it replaces in an existing
#: directory.
_EXPORTED_STL = re.compile(r"[A-Za-z_][A-Za-z0-9_]*_[0-9]+\.stl|container\.stl")

#: One binary STL triangle record: normal, three vertices (float32), attribute count (50 bytes).
_STL_RECORD = np.dtype([("normal", "<f4", (3,)), ("verts", "<f4", (3, 3)), ("attr", "<u2")])


def _stl_records(v, f, normals):
    """The binary STL records (bytes) of the triangles ``v[f]`` with face ``normals``."""
    rec = np.zeros(len(f), _STL_RECORD)
    rec["normal"] = normals
    rec["verts"] = v[f]
    return rec.tobytes()


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
    box [lo, hi] (see :func:`~peclet.packing.output.meshing.container_mesh`;
    ``container_spacing`` a length; decimated to
    :data:`~peclet.packing.output.meshing.CONTAINER_TRIANGLES`), or its (verts, faces) already
    meshed. ``home_mesh``: a (verts, faces) pair (or
    :func:`~peclet.packing.output.meshing.export_mesh`'s triple) to reuse; default
    :func:`~peclet.packing.output.meshing.export_mesh` at ``resolution`` (see the notes of
    :mod:`peclet.packing.output.export`), ``spacing`` (D), ``d_elem``
    (length) and ``shrink`` (fraction of D). ``volume`` is the home mesh's enclosed volume.
    """
    pack = check_pack(pack)
    path = check_writable_path(path, "path")
    per = check_bool("per_element", per_element)
    if container is not None and not per:
        raise PecletArgumentError("per_element", "True when a container is exported (binary "
                                  "STL holds one solid)", per_element)
    if not isinstance(name, str) or not name.isidentifier():
        raise PecletArgumentError("name", "an identifier (letters, digits, _)", name)
    v0, f0, n0 = home_of(pack, home_mesh, resolution, spacing, d_elem, shrink)
    cont = bed_container(container, container_spacing)
    from trimesh.exchange import stl

    R = pack.rotations()

    def write(tmp):
        with open(tmp, "wb") as fh:
            if per:
                for i, v in enumerate(bed_meshes(pack, v0, f0)):
                    m = as_trimesh(v, f0, f"{name}_{i}", n0 @ R[i].T)
                    fh.write(stl.export_stl_ascii(m).encode())
                if cont is not None:
                    fh.write(stl.export_stl_ascii(as_trimesh(*cont, "container")).encode())
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
                volume=float(as_trimesh(v0, f0).volume), bytes=os.path.getsize(path))


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
    pack = check_pack(pack)
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
    v0, f0, n0 = home_of(pack, home_mesh, resolution, spacing, d_elem, shrink)
    cont = bed_container(container, container_spacing)
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
            cm = as_trimesh(*cont)
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
                element_triangles=int(len(f0)), volume=float(as_trimesh(v0, f0).volume),
                bytes=sum(os.path.getsize(os.path.join(path, f)) for f in files))


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask
