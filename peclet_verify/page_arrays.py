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

__all__ = ["PageArrays"]


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
