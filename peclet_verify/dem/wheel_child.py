"""Child-side adapter: the upstream ``peclet-dem`` 1.1.0 wheel (``from peclet.dem import
Simulation``, XPBD, Kokkos/OpenMP, float32) speaking the page's API, served over the family
protocol (:mod:`peclet_verify.wire`). Run it as a script with the interpreter of the
environment that has the wheel (it needs numpy and the wheel only; ``wire.py`` and
``scenario.py`` are loaded by file path)::

    SubprocessDemBackend([venv_python, path_to_this_file], name="peclet-dem 1.1.0")

The dialect, all of it here and none of it in the certificates:

============================================  =============================================
page API                                       wheel 1.1.0
============================================  =============================================
``enable_periodicity(px, py, pz)``             ``set_periodic(px, py, pz)``
``step(dt)``                                   ``set_dt(dt)`` once, then ``step(1)``
``set_gravity(gx, gy, gz)``                    ``set_gravity([gx, gy, gz])``
``add_sphere_shape(r)``                        ``add_shape("sphere", r)``
``add_scene_shape(ni, nr, root, shell, R)``    ``add_scene_shape(ni, nr32, root, shell32,
                                               inv_inertia, R)`` (the unit-mass inverse
                                               inertia is taken from the first
                                               ``set_inv_inertia`` / ``set_inv_mass`` rows of
                                               a body of that shape: the registration is
                                               deferred to the first step)
``add_analytic_wall(..., e_n, mu)``            the same, float32 reals
``set_pair_material(a, b, e_n, e_t, mu)``      ``set_pair_material(a, b, e_n, mu)`` (no e_t)
``set_contact_capacity(n)``                    none: ignored (the hint is the particle
                                               capacity of the constructor)
``num_contacts()`` (contact points used)       ``num_manifolds`` (touching pairs)
arrays float64                                 float32 in, float32 out (converted)
============================================  =============================================

Threads: fixed by ``OMP_NUM_THREADS`` at start-up (SubprocessDemBackend starts one child per
thread count).
"""
import os
import sys

# the folder peclet_verify/ first: its wire modules load by file location
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import wheel_path  # noqa: E402  (by file location, like the wire modules)

wheel_path.drop_this_project()   # an inherited PYTHONPATH to our tree must not shadow the wheel
import numpy as np  # noqa: E402

import scenario as page_scenario  # noqa: E402  (by file location: no peclet_verify here)
import wire  # noqa: E402

F32 = np.float32


def _f32(a, cols=None):
    a = np.ascontiguousarray(np.asarray(a, dtype=np.float64).astype(F32))
    return a if cols is None else a.reshape(-1, cols)


class WheelPageSimulation:
    """The wheel's Simulation behind the page's API (see the module's table)."""

    def __init__(self, capacity):
        from peclet.dem import Simulation
        self.sim = Simulation(int(max(capacity, 1)))
        self._dt = None
        self._dt_set = None
        self._pending_scene = []      # scene shapes registered at the first step
        self._shape_ids = None
        self._inv_mass = None
        self._inv_inertia = None

    # configuration
    def set_domain(self, lo, hi):
        self.sim.set_domain(list(map(float, lo)), list(map(float, hi)))

    def enable_periodicity(self, px, py, pz):
        self.sim.set_periodic(bool(px), bool(py), bool(pz))

    def set_gravity(self, gx, gy, gz):
        self.sim.set_gravity([float(gx), float(gy), float(gz)])

    def set_material_params(self, e_n, e_t, mu):
        self.sim.set_material_params(float(e_n), float(e_t), float(mu))

    def set_solver_iterations(self, position, velocity):
        self.sim.set_solver_iterations(int(position), int(velocity))

    def set_dt(self, dt):
        self._dt = float(dt)

    def add_sphere_shape(self, radius):
        if self._pending_scene:
            raise NotImplementedError("wheel adapter: spheres after scene shapes")
        return self.sim.add_shape("sphere", float(radius))

    def add_scene_shape(self, node_ints, node_reals, root, shell_points, bounding_radius):
        self._pending_scene.append((np.ascontiguousarray(node_ints, np.int32),
                                    _f32(node_reals, 16), int(root), _f32(shell_points, 3),
                                    float(bounding_radius)))
        return self.sim.num_shapes + len(self._pending_scene) - 1

    def _register_scene_shapes(self):
        base = self.sim.num_shapes
        for k, (ni, nr, root, shell, rad) in enumerate(self._pending_scene):
            sid = base + k
            inv = [1.0, 1.0, 1.0]
            if self._shape_ids is not None and self._inv_inertia is not None:
                rows = np.nonzero(self._shape_ids == sid)[0]
                if len(rows):
                    i = rows[0]
                    m_inv = 1.0 if self._inv_mass is None else float(self._inv_mass[i])
                    # the wheel wants the UNIT-MASS inverse inertia: I^-1 * m
                    inv = (np.asarray(self._inv_inertia[i], float) / (m_inv or 1.0)).tolist()
            self.sim.add_scene_shape(ni, nr, root, shell, inv, rad)
        self._pending_scene = []

    def add_analytic_wall(self, node_ints, node_reals, root, invert, e_n, mu):
        return self.sim.add_analytic_wall(np.ascontiguousarray(node_ints, np.int32),
                                          _f32(node_reals, 16), int(root), bool(invert),
                                          float(e_n), float(mu))

    def set_pair_material(self, a, b, e_n, e_t, mu):
        if float(e_t) != 0.0:
            raise NotImplementedError("wheel 1.1.0 set_pair_material has no tangential "
                                      "restitution")
        self.sim.set_pair_material(int(a), int(b), float(e_n), float(mu))

    def set_material_ids(self, ids):
        self.sim.set_material_ids([int(i) for i in ids])

    # particles
    def set_positions(self, positions):
        self.sim.set_positions(_f32(positions, 3))

    def set_shape_ids(self, ids):
        self._shape_ids = np.asarray(ids, np.int32)
        self.sim.set_shape_ids(np.ascontiguousarray(self._shape_ids))

    def set_quaternions(self, quats):
        q = np.asarray(quats, float).reshape(-1, 4)
        self.sim.set_quaternions(_f32(q / np.linalg.norm(q, axis=1)[:, None], 4))

    def set_velocities(self, v):
        self.sim.set_velocities(_f32(v, 3))

    def set_angular_velocities(self, w):
        self.sim.set_angular_velocities(_f32(w, 3))

    def set_inv_mass(self, inv_mass):
        self._inv_mass = np.asarray(inv_mass, float)
        self.sim.set_inv_mass(_f32(inv_mass))

    def set_inv_inertia(self, inv_inertia):
        self._inv_inertia = np.asarray(inv_inertia, float).reshape(-1, 3)
        self.sim.set_inv_inertia(_f32(inv_inertia, 3))

    # stepping: step(dt) of the page = set_dt(dt) + step(1) of the wheel
    def step(self, dt=None):
        dt = self._dt if dt is None else float(dt)
        if dt is None:
            raise ValueError("dt: given, or set with set_dt(dt) before")
        if self._pending_scene:
            self._register_scene_shapes()
        if dt != self._dt_set:
            self.sim.set_dt(dt)
            self._dt_set = dt
        self.sim.step(1)

    # getters (float32 -> float64)
    def get_positions(self):
        return np.asarray(self.sim.get_positions(), np.float64).reshape(-1, 3)

    def get_quaternions(self):
        return np.asarray(self.sim.get_quaternions(), np.float64).reshape(-1, 4)

    def get_velocities(self):
        return np.asarray(self.sim.get_velocities(), np.float64).reshape(-1, 3)

    def get_angular_velocities(self):
        return np.asarray(self.sim.get_angular_velocities(), np.float64).reshape(-1, 3)

    def num_contacts(self):
        return int(self.sim.num_manifolds)


class WheelDem:
    name = "peclet-dem 1.1.0 (wheel)"

    thread_counts = (1, 2)

    def run(self, scenario, threads):
        return page_scenario.run_scenario(WheelPageSimulation, scenario)


if __name__ == "__main__":
    wire.serve(dem=WheelDem())
