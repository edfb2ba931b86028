"""Kinematic walls: each wall's pose and rigid velocity (the wall-motion seam of the step).

A wall's tree is authored in the world frame; its pose ``(t, q)`` carries the tree's points to
the world as ``p_world = R(q) p_tree + t`` (quaternion (x, y, z, w), active), identity at
registration. Its rigid velocity ``(v, omega, c)`` gives the surface velocity at a world point
``p`` as ``v + omega x (p - c)``: ``c`` is the world point the wall turns about (the drum's
axis, the impeller's hub). Every step:

- the narrow phase evaluates the wall at its pose at the start of the step (the tree is read at
  ``R^T (p - t)``; the reuse of probe lists between steps sees the wall's motion through the
  relative pose, exactly as it sees a body's);
- the speculative margin grows by twice the largest surface speed a wall has at any body
  (bounding sphere included) times dt, so no approach of a moving wall goes unseen;
- the velocity solve takes the wall's surface velocity at each contact point as body b's
  velocity (friction drags grains along, restitution is relative to the moving surface);
- after the step the pose advances by the velocity: ``q <- exp(omega dt) q``,
  ``t <- c + exp(omega dt) (t - c) + v dt``, ``c <- c + v dt``. A wall driven by
  :meth:`set_transform` every step simply overrides that.

A wall that never moved keeps the identity pose and zero velocity, and every kernel then does
exactly the arithmetic of a static wall (the same bits).
"""
from __future__ import annotations

import math

import numpy as np

from peclet.core.geom.transforms import quat_multiply, quat_normalize, quats_to_matrices
from peclet.core.validation import PecletArgumentError, check_array, check_int
from peclet.dem.limits import MAX_SPEED, check_magnitudes

__all__ = ["WallMotion", "UNIT_TOL"]

#: A wall quaternion must be unit to this tolerance (it is then normalised); a farther one is
#: an error rather than a silent rescale of the user's rotation.
UNIT_TOL = 1e-6


def _rotvec_quat(w, dt):
    """The unit quaternion (x, y, z, w) of the rotation by ``w * dt`` (a rotation vector)."""
    ang = math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]) * dt
    if ang == 0.0:
        return np.array([0.0, 0.0, 0.0, 1.0])
    s = math.sin(0.5 * ang) / (ang / dt)
    return np.array([w[0] * s, w[1] * s, w[2] * s, math.cos(0.5 * ang)])


class WallMotion:
    """Poses and velocities of ``n`` walls: ``pos`` (n, 3), ``quat`` (n, 4), ``vel``,
    ``omega``, ``center`` (n, 3), all float64, world frame."""

    def __init__(self):
        self.pos = np.zeros((0, 3))
        self.quat = np.zeros((0, 4))
        self.vel = np.zeros((0, 3))
        self.omega = np.zeros((0, 3))
        self.center = np.zeros((0, 3))

    @property
    def n(self):
        return len(self.pos)

    def add(self):
        """One more wall, at the identity pose and at rest."""
        self.pos = np.vstack([self.pos, np.zeros((1, 3))])
        self.quat = np.vstack([self.quat, [[0.0, 0.0, 0.0, 1.0]]])
        for k in ("vel", "omega", "center"):
            setattr(self, k, np.vstack([getattr(self, k), np.zeros((1, 3))]))

    def index(self, wall):
        """``wall`` checked as a registered wall index."""
        if self.n == 0:
            raise PecletArgumentError("wall", "the index of a wall added with add_analytic_wall "
                                      "(none is registered)", wall)
        return check_int("wall", wall, 0, self.n - 1)

    def set_transform(self, wall, translation, quaternion):
        """Pose of ``wall``: ``translation`` (3 finite numbers) and ``quaternion`` (x, y, z, w),
        unit to within :data:`UNIT_TOL` (then normalised)."""
        i = self.index(wall)
        t = check_array("translation", translation, (3,))
        q = check_array("quaternion", quaternion, (4,))
        nq = float(np.sqrt((q * q).sum()))
        if not abs(nq - 1.0) <= UNIT_TOL:
            raise PecletArgumentError("quaternion", f"a unit quaternion (x, y, z, w), |q| within "
                                      f"{UNIT_TOL:g} of 1", q.tolist(), f"|q| = {nq:.9g}")
        check_magnitudes("translation", t, t.tolist(), "coordinates")
        self.pos[i] = t
        self.quat[i] = quat_normalize(q)

    def set_velocity(self, wall, linear, angular, center=(0.0, 0.0, 0.0)):
        """Rigid velocity of ``wall``: ``linear`` (length/time), ``angular`` (rad/time, a
        world-frame vector) about the world point ``center``; each 3 finite numbers, the
        speeds of norm <= 1e100 and the centre's coordinates of magnitude <= 1e100
        (:mod:`peclet.dem.limits`). A surface speed beyond the step's speed bound at a body is
        refused when a step starts (:meth:`check_speeds`)."""
        i = self.index(wall)
        v = check_array("linear", linear, (3,))
        w = check_array("angular", angular, (3,))
        c = check_array("center", center, (3,))
        for name, a, unit in (("linear", v, "length/time"), ("angular", w, "rad/time")):
            norm = float(np.hypot(np.hypot(a[0], a[1]), a[2]))
            if norm > MAX_SPEED:
                raise PecletArgumentError(name, f"a vector of norm <= {MAX_SPEED:g} ({unit}; "
                                          "peclet.dem.limits)", a.tolist(), f"norm {norm:g}")
        check_magnitudes("center", c, c.tolist(), "coordinates")
        self.vel[i], self.omega[i], self.center[i] = v, w, c

    def moving(self):
        """Whether any wall has a non-zero velocity."""
        return bool(np.any(self.vel != 0.0) or np.any(self.omega != 0.0))

    def rotations(self):
        """(n, 3, 3) tree -> world rotations."""
        return quats_to_matrices(self.quat) if self.n else np.zeros((0, 3, 3))

    def surface_velocity(self, wall, points):
        """Surface velocity (k, 3) of walls ``wall`` (k,) at world ``points`` (k, 3)."""
        r = points - self.center[wall]
        return self.vel[wall] + np.cross(self.omega[wall], r)

    def moving_walls(self):
        """(W,) bool: the walls with a non-zero linear or angular velocity."""
        return np.any(self.vel != 0.0, axis=1) | np.any(self.omega != 0.0, axis=1)

    def surface_speeds(self, pos, radii):
        """(N, W): the largest surface speed of each wall over each body's bounding sphere,
        ``|v + omega x (x - c)| + |omega| r`` (zero for a wall that does not move)."""
        out = np.zeros((len(pos), self.n))
        for i in range(self.n):
            if not (np.any(self.vel[i] != 0.0) or np.any(self.omega[i] != 0.0)):
                continue
            u = self.vel[i] + np.cross(self.omega[i], pos - self.center[i])
            out[:, i] = np.sqrt((u * u).sum(axis=1)) + float(np.linalg.norm(self.omega[i])) * radii
        return out

    def check_speeds(self, pos, radii, bound):
        """Refuse (PecletArgumentError naming the wall's ``set_wall_velocity``) a wall whose
        surface speed at some body (bounding sphere included, :meth:`surface_speeds`) exceeds
        ``bound``, the step's speed limit (the guard's, 1e3 domain sizes per unit time): the
        bodies it touches would be stopped by the guard anyway, after a step's work."""
        if not len(pos):
            return
        with np.errstate(over="ignore", invalid="ignore"):
            s = self.surface_speeds(pos, radii)
        for i in range(self.n):
            top = float(s[:, i].max()) if len(s) else 0.0
            if not top <= bound:
                k = int(np.argmax(np.nan_to_num(s[:, i], nan=np.inf)))
                raise PecletArgumentError(
                    f"wall {i}'s velocity (set_wall_velocity)", f"a surface speed at the "
                    f"bodies <= the step's speed bound {bound:.6g} (1e3 domain sizes per unit "
                    "time)", (self.vel[i].tolist(), self.omega[i].tolist()),
                    f"{top:.6g} at body {k}, centre {self.center[i].tolist()}")

    def advance(self, dt):
        """Move every moving wall by its velocity over ``dt`` (see the module notes)."""
        for i in range(self.n):
            v, w = self.vel[i], self.omega[i]
            if not (np.any(v != 0.0) or np.any(w != 0.0)):
                continue
            dq = _rotvec_quat(w, dt)
            c = self.center[i]
            R = quats_to_matrices(dq[None, :])[0]
            self.pos[i] = c + R @ (self.pos[i] - c) + v * dt
            self.quat[i] = quat_normalize(quat_multiply(dq, self.quat[i]))
            self.center[i] = c + v * dt

    def arrays(self):
        """(n, 16) rows (t, q, v, omega, c) for a save."""
        return np.hstack([self.pos, self.quat, self.vel, self.omega, self.center]) \
            if self.n else np.zeros((0, 16))

    def load(self, rows):
        """Restore from :meth:`arrays`'s rows (checked by the caller: finite, unit q)."""
        rows = np.asarray(rows, np.float64)
        self.pos, self.quat = rows[:, 0:3].copy(), rows[:, 3:7].copy()
        self.vel, self.omega, self.center = (rows[:, 7:10].copy(), rows[:, 10:13].copy(),
                                             rows[:, 13:16].copy())
