"""MuJoCo behind the page's API, served over peclet's family protocol (a child process run
with the interpreter of a venv that has ``mujoco``; it needs numpy and mujoco only).

    PECLET_VERIFY_DIR=... python mujoco_child.py

``PECLET_VERIFY_DIR`` (environment) is the folder of peclet_verify, whose ``wire.py``
and ``scenario.py`` are loaded by file path (this interpreter has no peclet). The scenario's
calls are collected and the MJCF model is compiled at the first step (MuJoCo models are
compiled, not grown).

The dialect, all of it here and none of it in the certificates:

=========================================  ==================================================
page API                                   MuJoCo 3/4 (``mujoco`` Python bindings)
=========================================  ==================================================
``Simulation(capacity)``                   ignored (a model holds exactly its bodies)
``set_domain``                             ignored (MuJoCo has no domain)
``enable_periodicity``                     refused unless all False (no periodic boundaries)
``set_gravity``, ``set_dt``, ``step(dt)``  ``<option gravity timestep>``, ``mj_step``
``set_solver_iterations``                  ignored: MuJoCo's Newton solver (100 iterations,
                                           tolerance 1e-8) solves the contacts
``set_material_params(e_n, e_t, mu)``      every geom: ``friction="mu 0 0"``, condim 3,
                                           elliptic cones; ``solref="2 dt, zeta"`` with the
                                           damping ratio zeta = -ln e / sqrt(pi^2 + ln^2 e)
                                           of a damped spring whose rebound is e (MuJoCo has
                                           no restitution coefficient; e = 0: zeta = 1);
                                           e_t must be 0
``add_sphere_shape(r)``                    a sphere geom
``add_scene_shape(...)``                   a box geom when the tree is ONE box leaf (the only
                                           CSG a scenario gives a body); anything else refused
``add_analytic_wall(..., invert, e, mu)``  one box leaf: a static box geom; ``invert`` (solid
                                           outside: a container) six slabs around the box.
                                           Its e and mu must equal the bodies' (MuJoCo mixes
                                           the two geoms' parameters, it has no per-pair
                                           material without explicit pairs)
``set_pair_material``                      refused
``set_inv_mass``, ``set_inv_inertia``      ``<inertial mass diaginertia>`` (body frame)
positions, quaternions, velocities         free joints: qpos (quaternion w, x, y, z), qvel
                                           (angular velocity in the BODY frame: converted)
``set_contact_capacity(n)``                the size of MuJoCo's fixed arena
                                           (``<size memory>``), which holds the contacts and
                                           their constraint rows: 4 KiB a contact, 2 KiB a
                                           body, 8 KiB fixed (measured ``maxuse_arena``:
                                           1.3-2.8 KiB a contact, 1.8 KiB a body, spheres on
                                           a plane). MuJoCo never grows it: a step that needs
                                           more raises ``mj_stackAlloc: out of memory`` or
                                           drops the constraints with a warning
``num_contacts()``                         ``data.ncon``
=========================================  ==================================================

Integrator: RK4 (MuJoCo's most accurate; the free rigid body's conservation needs it).
Threads: ``mj_step`` runs on one thread; the engine declares ``thread_counts = (1,)``.
"""
import math
import os
import sys

import numpy as np

if __name__ == "__main__":
    sys.path.insert(0, os.environ["PECLET_VERIFY_DIR"])
import scenario as page_scenario  # noqa: E402  (by file location, from PECLET_VERIFY_DIR)
import wire  # noqa: E402
from page_arrays import PageArrays, one_box  # noqa: E402
from page_arrays import rotation as _rot  # noqa: E402

ARENA_FIXED, ARENA_PER_BODY, ARENA_PER_CONTACT = 8192, 2048, 4096


def _wxyz(q):
    return _vec([q[3], q[0], q[1], q[2]])


def _vec(v):
    return " ".join(repr(float(x)) for x in v)


def damping_ratio(e):
    """The damping ratio of a linear spring-damper whose rebound speed ratio is ``e``."""
    if e <= 0.0:
        return 1.0
    le = math.log(min(e, 1.0 - 1e-9))
    return -le / math.sqrt(math.pi ** 2 + le * le)


class MujocoPageSimulation(PageArrays):
    """The page's ``Simulation`` API on MuJoCo (see the module's table)."""

    def __init__(self, capacity):
        self.gravity = (0.0, 0.0, 0.0)
        self.e, self.mu = 0.0, 0.0
        self.dt = None
        self.shapes = []                 # ("sphere", r) or ("box", half, t, q)
        self.walls = []                  # (half, t, q, invert, e, mu)
        self.contact_capacity = None
        super().__init__()                  # the per-body arrays (peclet_verify.page_arrays)
        self.model = self.data = None

    # configuration
    def set_domain(self, lo, hi):
        pass

    def enable_periodicity(self, px, py, pz):
        if px or py or pz:
            raise NotImplementedError("MuJoCo has no periodic boundaries")

    def set_material_params(self, e_n, e_t, mu):
        if float(e_t) != 0.0:
            raise NotImplementedError("MuJoCo adapter: no tangential restitution")
        self.e, self.mu = float(e_n), float(mu)

    def add_sphere_shape(self, radius):
        self.shapes.append(("sphere", float(radius)))
        return len(self.shapes) - 1

    def add_scene_shape(self, node_ints, node_reals, root, shell_points, bounding_radius):
        self.shapes.append(("box",) + one_box(node_ints, node_reals, root, "MuJoCo adapter"))
        return len(self.shapes) - 1

    def add_analytic_wall(self, node_ints, node_reals, root, invert, e_n, mu):
        self.walls.append(one_box(node_ints, node_reals, root, "MuJoCo adapter") + (bool(invert), float(e_n),
                                                                    float(mu)))
        return len(self.walls) - 1

    def set_pair_material(self, a, b, e_n, e_t, mu):
        raise NotImplementedError("MuJoCo adapter: no per-pair materials")

    def set_material_ids(self, ids):
        raise NotImplementedError("MuJoCo adapter: no per-body materials")

    # the model
    def _geom_material(self):
        zeta = damping_ratio(self.e)
        return (f'friction="{self.mu!r} 0 0" condim="3" '
                f'solref="{2.0 * self.dt!r} {zeta!r}"')

    def _wall_geoms(self):
        out = []
        for half, t, q, invert, e, mu in self.walls:
            if (e, mu) != (self.e, self.mu):
                raise NotImplementedError("MuJoCo adapter: a wall's e and mu must equal the "
                                          "bodies' (MuJoCo mixes the geoms' parameters)")
            if not invert:
                out.append((half, t, q))
                continue
            R, W = _rot(q), float(max(half))
            for ax in range(3):
                for sign in (-1.0, 1.0):
                    size = np.asarray(half, float) + W
                    size[ax] = 0.5 * W
                    centre = np.zeros(3)
                    centre[ax] = sign * (half[ax] + 0.5 * W)
                    out.append((size, t + R @ centre, q))
        mat = self._geom_material()
        return "".join(f'<geom type="box" size="{_vec(h)}" pos="{_vec(t)}" quat="{_wxyz(q)}" '
                       f'{mat}/>' for h, t, q in out)

    def _body(self, i):
        a = self.arrays
        shape = self.shapes[int(a["shape_ids"][i])]
        mass = 1.0 / float(a["inv_mass"][i]) if "inv_mass" in a else 1.0
        inertia = 1.0 / a["inv_inertia"][i] if "inv_inertia" in a else np.full(3, mass)
        if shape[0] == "sphere":
            geom = f'<geom type="sphere" size="{shape[1]!r}" {self._geom_material()}/>'
        else:
            _, half, t, q = shape
            geom = (f'<geom type="box" size="{_vec(half)}" pos="{_vec(t)}" quat="{_wxyz(q)}" '
                    f'{self._geom_material()}/>')
        return (f'<body name="b{i}"><freejoint/><inertial pos="0 0 0" mass="{mass!r}" '
                f'diaginertia="{_vec(inertia)}"/>{geom}</body>')

    def _build(self):
        import mujoco
        if self.dt is None:
            raise ValueError("dt: given to step(dt), or set with set_dt(dt) before")
        n = len(self.arrays["positions"])
        size = ""
        if self.contact_capacity is not None:
            arena = ARENA_FIXED + ARENA_PER_BODY * n + ARENA_PER_CONTACT * self.contact_capacity
            size = f'<size memory="{arena}"/>'
        xml = (f'<mujoco><option timestep="{self.dt!r}" gravity="{_vec(self.gravity)}" '
               f'integrator="RK4" cone="elliptic"/>{size}<worldbody>{self._wall_geoms()}'
               + "".join(self._body(i) for i in range(n)) + "</worldbody></mujoco>")
        self.model = mujoco.MjModel.from_xml_string(xml)
        self.data = mujoco.MjData(self.model)
        a = self.arrays
        q = a.get("quaternions", np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)))
        q = q / np.linalg.norm(q, axis=1)[:, None]
        qpos = self.data.qpos.reshape(n, 7)
        qpos[:, :3] = a["positions"]
        qpos[:, 3:] = q[:, [3, 0, 1, 2]]
        qvel = self.data.qvel.reshape(n, 6)
        qvel[:, :3] = a.get("velocities", np.zeros((n, 3)))
        w = a.get("angular_velocities", np.zeros((n, 3)))
        qvel[:, 3:] = np.einsum("kji,kj->ki", np.stack([_rot(x) for x in q]), w)  # R^T w

    def step(self, dt=None):
        import mujoco
        if dt is not None:
            if self.model is not None and float(dt) != self.dt:
                raise NotImplementedError("MuJoCo adapter: dt fixed once the model is built")
            self.dt = float(dt)
        if self.model is None:
            self._build()
        mujoco.mj_step(self.model, self.data)

    # getters (before the first step, the state as set: the model needs dt to be built)
    def _initial(self, key, default):
        n = len(self.arrays["positions"])
        return np.array(self.arrays.get(key, np.tile(default, (n, 1))), float)

    def _state(self):
        n = self.model.nbody - 1
        return self.data.qpos.reshape(n, 7), self.data.qvel.reshape(n, 6)

    def get_positions(self):
        if self.model is None:
            return self._initial("positions", [0.0, 0.0, 0.0])
        return np.array(self._state()[0][:, :3])

    def get_quaternions(self):
        if self.model is None:
            return self._initial("quaternions", [0.0, 0.0, 0.0, 1.0])
        return np.array(self._state()[0][:, [4, 5, 6, 3]])

    def get_velocities(self):
        if self.model is None:
            return self._initial("velocities", [0.0, 0.0, 0.0])
        return np.array(self._state()[1][:, :3])

    def get_angular_velocities(self):
        if self.model is None:
            return self._initial("angular_velocities", [0.0, 0.0, 0.0])
        qpos, qvel = self._state()
        R = np.stack([_rot(q) for q in qpos[:, [4, 5, 6, 3]]])
        return np.einsum("kij,kj->ki", R, qvel[:, 3:])

    def num_contacts(self):
        return int(self.data.ncon) if self.data is not None else 0


class MujocoDem:
    name = "MuJoCo (RK4, elliptic cones)"
    thread_counts = (1,)

    def __init__(self):
        import mujoco
        self.name = f"MuJoCo {mujoco.__version__} (RK4, elliptic cones)"

    def run(self, scenario, threads):
        return page_scenario.run_scenario(MujocoPageSimulation, scenario)


if __name__ == "__main__":
    wire.serve(dem=MujocoDem())
