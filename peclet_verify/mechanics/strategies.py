"""Hypothesis strategies of the mechanics family: the closed-form cases a DEM engine must
reproduce (two spheres colliding, a sphere sliding to rolling, a cube on an incline, a free
asymmetric body), each a frozen dataclass whose ``scenario()`` is its page-API run and whose
``repr`` rebuilds it. Values are drawn on integer grids (a failure shrinks in few steps).
Units: m, s, kg; gravity 9.81 m/s^2 along -y.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from hypothesis import strategies as st

from ..dem.strategies import G, box_encoding
from ..scenario import Scenario

__all__ = ["Collision", "collisions", "Roll", "rolls", "cube_shell", "Incline", "inclines",
           "Rotor", "rotors"]


def unit(v):
    v = np.asarray(v, float)
    n = np.linalg.norm(v)
    return np.array([1.0, 0.0, 0.0]) if n == 0 else v / n


@dataclass(frozen=True)
class Collision:
    """Two spheres head-on along ``axis`` without gravity: radii, masses, approach speeds (each
    towards the other), restitution e and friction mu."""

    radii: tuple
    masses: tuple
    speeds: tuple
    axis: tuple
    e: float
    mu: float
    dt: float = 1e-3

    def scenario(self):
        n = unit(self.axis)
        r1, r2 = self.radii
        v1, v2 = self.speeds
        closing = v1 + v2
        gap = 20 * self.dt * closing         # contact after ~20 steps
        x2 = (r1 + r2 + gap) * n
        calls = [("set_gravity", (0.0, 0.0, 0.0)),
                 ("set_material_params", (self.e, 0.0, self.mu)),
                 ("set_solver_iterations", (10, 8)),
                 ("add_sphere_shape", (r1,)), ("add_sphere_shape", (r2,)),
                 ("set_positions", ([[0.0, 0.0, 0.0], x2.tolist()],)),
                 ("set_shape_ids", ([0, 1],)),
                 ("set_velocities", ([(v1 * n).tolist(), (-v2 * n).tolist()],)),
                 ("set_inv_mass", ([1.0 / self.masses[0], 1.0 / self.masses[1]],)),
                 ("set_inv_inertia", ([[2.5 / (self.masses[0] * r1 ** 2)] * 3,
                                       [2.5 / (self.masses[1] * r2 ** 2)] * 3],))]
        return Scenario(2, calls, self.dt, 60, record=("velocities",),
                        label=f"binary collision, e = {self.e!r}: separation / approach "
                              f"speed must be e", meta={"n_bodies": 2})


def collisions() -> st.SearchStrategy:
    """Radii 0.1 .. 0.6 m, masses 0.2 .. 5 kg, speeds 0.25 .. 3 m/s, e in [0, 1] (1/64
    steps), mu in [0, 1], axis any direction (integer components)."""
    return st.builds(
        lambda r1, r2, m1, m2, s1, s2, ax, e, mu: Collision(
            (r1 / 20, r2 / 20), (m1 / 5, m2 / 5), (s1 / 4, s2 / 4),
            tuple(float(c) for c in ax) if any(ax) else (1.0, 0.0, 0.0), e / 64, mu / 8),
        st.integers(2, 12), st.integers(2, 12), st.integers(1, 25), st.integers(1, 25),
        st.integers(1, 12), st.integers(1, 12),
        st.tuples(st.integers(-4, 4), st.integers(-4, 4), st.integers(-4, 4)),
        st.integers(0, 64), st.integers(0, 8))


# ---------------------------------------------------------------------------- slide to roll
@dataclass(frozen=True)
class Roll:
    """A solid sphere (radius, mass) set down sliding at v0 (no spin) on a floor with friction
    mu (wall and body), e = 0."""

    radius: float
    mass: float
    v0: float
    mu: float
    dt: float = 2e-3

    @property
    def t_roll(self):
        return 2.0 * self.v0 / (7.0 * self.mu * G)

    def scenario(self):
        r = self.radius
        ni, nr, root = box_encoding((50.0, 1.0, 50.0), (0.0, -1.0, 0.0))
        steps = int(math.ceil((self.t_roll + 0.1) / self.dt))
        calls = [("set_gravity", (0.0, -G, 0.0)),
                 ("set_material_params", (0.0, 0.0, self.mu)),
                 ("set_solver_iterations", (10, 8)),
                 ("add_sphere_shape", (r,)),
                 ("add_analytic_wall", (ni, nr, root, False, 0.0, self.mu)),
                 ("set_positions", ([[0.0, r, 0.0]],)), ("set_shape_ids", ([0],)),
                 ("set_velocities", ([[self.v0, 0.0, 0.0]],)),
                 ("set_inv_mass", ([1.0 / self.mass],)),
                 ("set_inv_inertia", ([[2.5 / (self.mass * r * r)] * 3],))]
        return Scenario(1, calls, self.dt, steps, record=("velocities", "angular_velocities"),
                        label=f"slide to roll: v must reach 5/7 v0 = {5 * self.v0 / 7!r} "
                              f"from t = {self.t_roll:.4g} s", meta={"n_bodies": 1})


def rolls() -> st.SearchStrategy:
    """Radius 0.1 .. 1 m, mass 0.5 .. 5 kg, v0 0.5 .. 3 m/s, mu 0.2 .. 0.8 (the roll starts
    within 0.44 s)."""
    return st.builds(lambda r, m, v, mu: Roll(r / 10, m / 2, v / 4, mu / 20),
                     st.integers(1, 10), st.integers(1, 10), st.integers(2, 12),
                     st.integers(4, 16))


# ---------------------------------------------------------------------------- incline
def cube_shell(half, k=5):
    """Surface probes of a cube of half side ``half``: a k x k grid on every face (edges and
    corners included), duplicates removed."""
    u = np.linspace(-half, half, k)
    a, b = np.meshgrid(u, u, indexing="ij")
    pts = []
    for ax in range(3):
        o1, o2 = [i for i in range(3) if i != ax]
        for s in (-half, half):
            p = np.zeros((k * k, 3))
            p[:, ax] = s
            p[:, o1] = a.ravel()
            p[:, o2] = b.ravel()
            pts.append(p)
    return np.unique(np.round(np.concatenate(pts), 12), axis=0)


@dataclass(frozen=True)
class Incline:
    """A cube (half side ``half``, mass 1, a box CSG scene shape) released at rest on a plane
    inclined at ``theta_deg``, friction mu (wall and body), e = 0; ``t_end`` seconds."""

    half: float
    theta_deg: float
    mu: float
    dt: float = 1e-3
    t_end: float = 0.4

    @property
    def sticks(self):
        return math.tan(math.radians(self.theta_deg)) < self.mu

    def scenario(self):
        from peclet.core.geom.transforms import matrix_to_quat
        th = math.radians(self.theta_deg)
        c, s = math.cos(th), math.sin(th)
        R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        q = matrix_to_quat(R).tolist()
        h = self.half
        wall = box_encoding((20.0, 1.0, 20.0), (R @ [0.0, -1.0, 0.0]).tolist(), q)
        cube = box_encoding((h, h, h))
        shell = cube_shell(h)
        x0 = (R @ np.array([0.0, h, 0.0])).tolist()
        calls = [("set_gravity", (0.0, -G, 0.0)),
                 ("set_material_params", (0.0, 0.0, self.mu)),
                 ("set_solver_iterations", (10, 8)),
                 ("add_scene_shape", (cube[0], cube[1], cube[2], shell.tolist(),
                                      math.sqrt(3.0) * h)),
                 ("add_analytic_wall", (wall[0], wall[1], wall[2], False, 0.0, self.mu)),
                 ("set_positions", ([x0],)), ("set_shape_ids", ([0],)),
                 ("set_quaternions", ([q],)), ("set_inv_mass", ([1.0],)),
                 ("set_inv_inertia", ([[1.5 / h ** 2] * 3],))]
        steps = int(round(self.t_end / self.dt))
        return Scenario(1, calls, self.dt, steps, record=("positions",), record_every=1,
                        label=f"cube on an incline of {self.theta_deg!r} deg (tan = "
                              f"{math.tan(th):.4f}), mu = {self.mu!r}: must "
                              f"{'stick' if self.sticks else 'slide with a = g (sin - mu cos)'}",
                        meta={"n_bodies": 1})


def inclines() -> st.SearchStrategy:
    """Half side 0.2 .. 0.6 m, theta 10 .. 35 deg; mu = tan(theta) x f with f in [0.5, 0.85]
    (slides) or [1.15, 2] (sticks): at least 15 % away from the threshold."""
    def build(h, th, stick, f):
        t = math.tan(math.radians(th))
        mu = t * ((115 + f) / 100 if stick else (85 - f * 35 / 85) / 100)
        return Incline(h / 10, float(th), round(mu, 6))
    return st.builds(build, st.integers(2, 6), st.integers(10, 35), st.booleans(),
                     st.integers(0, 85))


# ---------------------------------------------------------------------------- free rotor
@dataclass(frozen=True)
class Rotor:
    """A torque-free body with principal moments ``moments`` (distinct), spinning mostly about
    the intermediate axis (body angular velocity ``omega_body``), orientation ``quat``."""

    moments: tuple
    omega_body: tuple
    quat: tuple
    per_period: int = 400
    periods: float = 2.4

    def reference_period(self):
        from ..reference.rotor import free_rotor_period
        iinv = 1.0 / np.asarray(self.moments, float)
        return free_rotor_period(iinv, np.asarray(self.moments) * np.asarray(self.omega_body))

    def scenario(self):
        from peclet.core.geom import quat_to_matrix
        T = self.reference_period()
        dt = T / self.per_period
        R = quat_to_matrix(np.asarray(self.quat, float))
        w_world = (R @ np.asarray(self.omega_body, float)).tolist()
        calls = [("set_gravity", (0.0, 0.0, 0.0)),
                 ("add_sphere_shape", (0.5,)),
                 ("set_positions", ([[0.0, 0.0, 0.0]],)), ("set_shape_ids", ([0],)),
                 ("set_quaternions", ([list(self.quat)],)),
                 ("set_angular_velocities", ([w_world],)),
                 ("set_inv_mass", ([1.0],)),
                 ("set_inv_inertia", ([[1.0 / m for m in self.moments]],))]
        return Scenario(1, calls, dt, int(math.ceil(self.periods * self.per_period)),
                        record=("quaternions", "angular_velocities"), record_every=1,
                        label=f"free rigid body, moments {self.moments}: energy and angular "
                              f"momentum conserved, flip period {T:.6g} s",
                        meta={"n_bodies": 1})


def rotors() -> st.SearchStrategy:
    """Moments I1 < I2 < I3 of a body that can exist (I3 < I1 + I2, the triangle inequality
    every rigid body's principal moments obey): I2 = I1 (1 + a), a in [0.25, 2], I3 = I2 +
    c I1, c in [0.1, 0.8]; |omega| 2 .. 20 rad/s about the intermediate axis tilted by
    1 .. 10 % towards the others, any orientation (integer axis, angle in 1/64 turns)."""
    def build(i1, a, c, w, e1, e3, ax, k):
        I1 = i1 / 4
        I2 = I1 * (1 + a / 4)
        I3 = I2 + I1 * c / 10
        om = (w * e1 / 100, float(w), w * e3 / 100)
        axis = unit(ax if any(ax) else (0, 0, 1))
        half = math.pi * k / 64
        q = (*(math.sin(half) * axis), math.cos(half))
        return Rotor((I1, I2, I3), om, tuple(float(v) for v in q))
    return st.builds(build, st.integers(1, 8), st.integers(1, 8), st.integers(1, 8),
                     st.integers(2, 20), st.integers(1, 10), st.integers(1, 10),
                     st.tuples(st.integers(-4, 4), st.integers(-4, 4), st.integers(-4, 4)),
                     st.integers(0, 63))
