"""Every pack peclet writes, as the flow reads it: a :class:`~peclet.packing.bed.freeze.Pack`
and the container its flow domain comes from.

- ``peclet pack`` / ``peclet pall-ring`` files (``pack.npz``, ``pall_ring_pack.npz``): a box
  pack (periodic in x and z, floor at y = 0) or, when the ``results.json`` beside it names one,
  a column section (:func:`peclet.flow.permeability.pack_container`);
- ``peclet pack --protocol grow`` files (``grown.npz``: positions, quaternions (x, y, z, w),
  ``box`` (3,) the cube's sides, the element's flat tree with ``root``, ``volume`` and ``d``,
  its diameter; peclet.packing.experiments.grow): a triply periodic cell
  (:class:`~peclet.flow.domain.PeriodicCell`). Lengths are divided by ``d`` into element
  diameters (the tree by a reframed copy of its root with scale 1 / d); the bounding radius
  is the largest distance from the centre of the element's surface mesh (peclet.core.geom.mesh,
  plus one mesh cell: 0.51 D for a sphere); positions are wrapped into the cell.

:func:`load_flow_pack` reads either and says which it found (``source``).
"""
from __future__ import annotations

import os
import zipfile

import numpy as np

from peclet.core.validation import PecletArgumentError

from .domain import PeriodicCell

__all__ = ["GROWN_FIELDS", "load_flow_pack", "grown_pack"]

#: The fields of a grown bed's file (peclet.packing.experiments.grow.write_outputs).
GROWN_FIELDS = ("positions", "quaternions", "box", "node_ints", "node_reals", "root", "volume",
                "d")


def _bounding_radius(builder, root, n=72):
    """Largest distance from the origin of ``root``'s surface mesh plus one mesh cell: a mesh
    of ``n`` points a side over [-1.5, 1.5]^3 D (cells of 0.042 D: a ring's 0.12 D wall is
    seen), then one over the box that holds what it found."""
    from peclet.core.geom.mesh import surface_mesh
    r = 1.5
    for _ in range(2):
        try:
            verts = surface_mesh(builder, root, [-r] * 3, [r] * 3, n, close=False)[0]
        except ValueError as exc:
            raise PecletArgumentError("pack", "an element whose surface the flow can mesh "
                                      "within 1.5 D of its centre", "grown.npz",
                                      str(exc)) from None
        cell = 2.0 * r / (n - 1)
        found = float(np.sqrt((np.asarray(verts) ** 2).sum(axis=1)).max())
        if found > 1.5 - 2.0 * cell:
            raise PecletArgumentError("pack", "an element within 1.5 D of its centre (D its "
                                      "diameter)", "grown.npz", f"surface at {found:.3g} D")
        r = found + cell
    return r


def grown_pack(z):
    """(Pack, PeriodicCell) of a grown bed's arrays ``z`` (a mapping with
    :data:`GROWN_FIELDS`)."""
    from peclet.core import geom
    from peclet.packing.bed.freeze import Pack
    d = float(z["d"])
    box = np.asarray(z["box"], np.float64).reshape(-1)
    if not (np.isfinite(d) and d > 0) or box.shape != (3,) or not np.all(box > 0):
        raise PecletArgumentError("pack", "a grown bed with d > 0 and a box of 3 sides > 0",
                                  f"d = {d}, box = {box.tolist()}")
    b = geom.SceneBuilder.decode(np.asarray(z["node_ints"]), np.asarray(z["node_reals"]))
    root = int(z["root"])
    if d != 1.0:
        root = b.add_reframed(root, translation=[0.0, 0.0, 0.0], rotation=[0.0, 0.0, 0.0, 1.0],
                              scale=1.0 / d)
    ni, nr, _, _ = b.encode()
    box = box / d
    pos = np.mod(np.asarray(z["positions"], np.float64) / d, box)
    pk = Pack(positions=pos, quaternions=np.asarray(z["quaternions"], np.float64),
              box=np.array([box[0], box[2]]), ring_volume=float(z["volume"]) / d ** 3,
              node_ints=ni, node_reals=nr, home_root=root,
              bounding_radius=_bounding_radius(b, root), shell=np.zeros((0, 3)), mass=np.nan,
              inv_inertia=np.full(3, np.nan))
    return pk, PeriodicCell(float(box[1]))


def load_flow_pack(path):
    """(Pack, container, source) of a pack file: a grown bed's ``grown.npz`` gives its
    :class:`PeriodicCell` (source "grown bed (triply periodic)"); any other file is read by
    :func:`~peclet.packing.bed.freeze.load_pack` with container None (the caller's
    :func:`~peclet.flow.permeability.pack_container` then reads the one recorded beside it).
    Anything else: PecletArgumentError naming ``pack``."""
    from peclet.packing.bed.freeze import Pack, load_pack
    if isinstance(path, Pack):
        return path, None, "argument"
    if not isinstance(path, (str, bytes, os.PathLike)) or not os.path.isfile(path):
        raise PecletArgumentError("pack", "a peclet pack file (.npz)", path)
    try:
        with np.load(path, allow_pickle=False) as z:
            if all(k in z.files for k in GROWN_FIELDS) and "home_root" not in z.files:
                arrays = {k: z[k] for k in GROWN_FIELDS}
            else:
                arrays = None
    except (ValueError, OSError, EOFError, zipfile.BadZipFile, AttributeError):
        arrays = None
    if arrays is not None:
        pk, cell = grown_pack(arrays)
        return pk, cell, "grown bed (triply periodic: peclet pack --protocol grow)"
    return load_pack(path), None, "pack file"
