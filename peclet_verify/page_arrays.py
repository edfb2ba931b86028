"""The per-body setters and the run settings of the page's API recorded, for adapters that build a foreign
engine's model from a whole scenario at once (stdlib + numpy only: a child process in the
engine's venv loads it by file path, like :mod:`peclet_verify.scenario`).

:class:`PageArrays` keeps ``positions`` (n, 3), ``shape_ids`` (n,), ``quaternions`` (n, 4;
x, y, z, w, body to world), ``velocities`` and ``angular_velocities`` (n, 3, world frame),
``inv_mass`` (n,) and ``inv_inertia`` (n, 3, body frame) in :attr:`arrays` as the scenario sets
them, and the settings ``gravity`` (3-tuple), ``dt`` and ``contact_capacity``; the adapter reads
them when it builds its model (examples/downstream/mujoco_dem, lammps_dem). Its own
``__init__`` sets their defaults after calling this one's."""
from __future__ import annotations

import numpy as np

__all__ = ["BOX", "PageArrays", "one_box", "rotation"]

#: leaf kind id of a box in the flat encoding (docs/architecture.md §2)
BOX = 3


def one_box(node_ints, node_reals, root, who):
    """(half extents (3,) times the leaf's scale, translation (3,), quaternion (x, y, z, w)) of
    a tree that is one box leaf, from the flat encoding (``node_ints`` rows of 3, ``node_reals``
    rows of 16); NotImplementedError naming ``who`` for any other tree."""
    ni = np.asarray(node_ints, int).reshape(-1, 3)
    nr = np.asarray(node_reals, float).reshape(-1, 16)
    kind, left, right = ni[int(root)]
    if kind != BOX or left >= 0 or right >= 0:
        raise NotImplementedError(f"{who}: only a single box leaf is mapped; got node kind "
                                  f"{int(kind)}")
    rec = nr[int(root)]
    return rec[:3] * rec[15], rec[8:11], rec[11:15]


def rotation(q):
    """Rotation matrix (3, 3), body to world, of the quaternion (x, y, z, w); normalised first."""
    x, y, z, w = np.asarray(q, float) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


class PageArrays:
    """The page API's per-body setters, each storing a float64 copy (ids: int) of its argument
    in :attr:`arrays` (reshaped to rows of 3 or 4 where the API has them), and its settings as
    attributes (``set_solver_iterations`` is ignored: an explicit engine has no iterations)."""

    def __init__(self):
        self.arrays = {}

    def _set(self, key, value, cols=None):
        a = np.array(value, float)
        self.arrays[key] = a if cols is None else a.reshape(-1, cols)

    def set_positions(self, positions):
        self._set("positions", positions, 3)

    def set_shape_ids(self, ids):
        self.arrays["shape_ids"] = np.asarray(ids, int).reshape(-1)

    def set_quaternions(self, quats):
        self._set("quaternions", quats, 4)

    def set_velocities(self, v):
        self._set("velocities", v, 3)

    def set_angular_velocities(self, w):
        self._set("angular_velocities", w, 3)

    def set_inv_mass(self, inv_mass):
        self._set("inv_mass", inv_mass)

    def set_inv_inertia(self, inv_inertia):
        self._set("inv_inertia", inv_inertia, 3)

    def set_gravity(self, gx, gy, gz):
        self.gravity = (float(gx), float(gy), float(gz))

    def set_solver_iterations(self, position, velocity):
        pass

    def set_contact_capacity(self, n):
        self.contact_capacity = int(n)

    def set_dt(self, dt):
        self.dt = float(dt)
