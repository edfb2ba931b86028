"""Elements from a user's own files: a triangle mesh or a saved grid (issue 41).

``--element pellet.stl`` (or .obj, .ply) with options ``pellet.stl:scale=0.04,resolution=0.02``
(``scale`` multiplies the file's coordinates, e.g. 1/25 for a 25 mm pellet drawn in mm packed in
units of its own size; ``resolution`` is the grid spacing in the scaled units, default a sixth
of the mesh's thickness 2 V / A), and ``--element bean.npz`` for a grid saved by
:func:`peclet.core.geom.grids.save_grid`. Both become a grid leaf
(:mod:`peclet.core.geom.grids`); the packing layer measures it like any tree.

Packs are made in units of the element's size (the library's elements are about 1 across), so
a mesh whose largest extent after ``scale`` is outside :data:`EXTENT_RANGE` is refused with the
scale that would bring it to 1: a file in mm read as if in element units is the usual cause.
"""
from __future__ import annotations

import functools
import hashlib
import math
import os

import numpy as np

from peclet.core import geom
from peclet.core.geom import grids
from peclet.core.validation import PecletArgumentError

__all__ = ["MESH_SUFFIXES", "EXTENT_RANGE", "CONTAINER_SPACING", "is_user_file",
           "user_file_element", "mesh_container_tree", "is_file_element",
           "file_element_text", "file_digest", "grid_npz_element", "is_grid_npz"]

MESH_SUFFIXES = (".stl", ".obj", ".ply")
#: Accepted largest extent of a user's element (pack units, the library's elements ~1).
EXTENT_RANGE = (0.05, 20.0)
_OPTIONS = {"scale": (0.0, math.inf), "resolution": (0.0, math.inf)}
#: Default grid spacing of a container from a mesh (element diameters): walls are touched
#: by elements of size 1, so their field is sampled at a tenth of that.
CONTAINER_SPACING = 0.1


def _split(value):
    path, sep, rest = str(value).partition(":")
    return path, (rest if sep else "")


def is_user_file(value):
    """True for a string or path naming a mesh file (.stl, .obj, .ply; options or not)."""
    if not isinstance(value, (str, os.PathLike)):
        return False
    path, _ = _split(os.fspath(value))
    return path.lower().endswith(MESH_SUFFIXES)


def _mesh_leaf(value, spacing, extent_range=None):
    """(builder, grid leaf, path) of ``MESH[:scale=S,resolution=H]``: the mesh's coordinates
    times S sampled at H (default ``spacing``, None: the mesh's own default); with
    ``extent_range``, a largest extent outside it is refused with the scale that fixes it.
    PecletArgumentError naming "element"."""
    path, text = _split(os.fspath(value))
    opts = _options(value, text)
    if not os.path.isfile(path):
        raise PecletArgumentError("element", "a path to an existing mesh file", path)
    v, f = grids.load_mesh(path)
    scale = opts.get("scale", 1.0)
    if extent_range is not None:
        extent = float((v.max(axis=0) - v.min(axis=0)).max()) * scale
        lo, hi = extent_range
        if not lo <= extent <= hi:
            raise PecletArgumentError(
                "element", f"a mesh whose largest extent (times scale) is in [{lo:g}, {hi:g}] "
                "element units", value, f"extent {extent:.4g}: a file in other units? try "
                f"{path}:scale={scale / extent:.4g}")
    b = geom.SceneBuilder()
    root = grids.grid_from_mesh(b, (v, f), spacing=opts.get("resolution", spacing), scale=scale)
    return b, root, path


def mesh_container_tree(value):
    """(builder, root) of a container from a mesh file ``vessel.stl[:scale=S,resolution=H]``:
    the mesh's interior is the fluid region (element diameters after ``scale``), sampled at
    ``resolution`` (default :data:`CONTAINER_SPACING`). PecletArgumentError naming
    "container"."""
    try:
        b, root, _ = _mesh_leaf(value, CONTAINER_SPACING)
    except PecletArgumentError as e:
        raise PecletArgumentError("container", "a closed mesh file whose interior is the "
                                  "fluid region, MESH[:scale=S,resolution=H]", value,
                                  str(e)) from None
    return b, root


def _options(value, text, arg="element"):
    out = {}
    for tok in filter(None, (t.strip() for t in text.split(","))):
        k, eq, v = tok.partition("=")
        k = k.strip()
        if not eq or k not in _OPTIONS:
            raise PecletArgumentError(arg, f"MESH[:KEY=V,...] with KEY in "
                                      f"{sorted(_OPTIONS)}", value, f"bad item {tok!r}")
        try:
            x = float(v)
        except ValueError:
            raise PecletArgumentError(arg, f"{k} a number", value) from None
        lo, hi = _OPTIONS[k]
        if not (lo < x < hi):
            raise PecletArgumentError(arg, f"{k} > {lo:g} and finite", value)
        out[k] = x
    return out


def is_file_element(value):
    """True for an element naming a file: a mesh (:func:`is_user_file`) or an ``.npz`` (a grid
    or a flat encoding), not a library element."""
    return isinstance(value, (str, os.PathLike)) and (
        is_user_file(value) or os.fspath(value).endswith(".npz"))


def file_element_text(value, arg="element"):
    """The canonical text of an element given as a file, for a spec other processes read (an
    ensemble's realizations): a mesh ``PATH[:scale=S,resolution=H]`` (options checked) or an
    ``.npz`` (a grid or a flat encoding), its path made absolute. None when ``value`` is not a
    file form (a library element). PecletArgumentError naming ``arg`` when the file does not
    exist or an option is bad."""
    if not is_file_element(value):
        return None
    text = os.fspath(value)
    path, opts = (_split(text) if is_user_file(text) else (text, ""))
    _options(text, opts, arg)
    if not os.path.isfile(path):
        raise PecletArgumentError(arg, "a path to an existing mesh or .npz file", path)
    return os.path.abspath(path) + (":" + opts if opts else "")


def file_digest(text):
    """SHA-256 (hex) of the file an element text from :func:`file_element_text` names: its
    contents, so that an edited file is a different element. Read once per version of the
    file (its size and modification time) in a process."""
    path = text if text.endswith(".npz") else _split(text)[0]
    st = os.stat(path)
    return _digest(path, st.st_size, st.st_mtime_ns)


@functools.lru_cache(maxsize=64)
def _digest(path, size, mtime_ns):
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def user_file_element(value, make_element):
    """A mesh file's grid leaf as an element (module notes): ``make_element(builder, root,
    name)`` is called and its result returned."""
    b, root, path = _mesh_leaf(value, None, EXTENT_RANGE)
    return make_element(b, root, os.path.basename(path))


def grid_npz_element(path, make_element):
    """The grid leaf of a grid .npz (``values``, ``spacing``, ``origin``) as an element."""
    b = geom.SceneBuilder()
    root = grids.grid_from_npz(b, path)
    return make_element(b, root, os.path.basename(os.fspath(path)))


def is_grid_npz(path):
    """True if ``path`` is an .npz holding a saved grid (``values``, ``spacing``)."""
    try:
        with np.load(os.fspath(path), allow_pickle=False) as z:
            return "values" in z.files and "spacing" in z.files
    except (OSError, ValueError):
        return False
