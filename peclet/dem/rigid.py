"""Rigid-body rotation: mass-property helpers and a conservative torque-free rotor step.

The quaternion formulas themselves live in :mod:`peclet.core.geom.transforms` (one home);
the rotor's test oracles (closed-form period, an ODE reference) in
:mod:`peclet_verify.reference.rotor`.

Conventions (docs/architecture.md §6):

- Quaternions are ``(x, y, z, w)``, unit, and act as an *active* rotation from the body's
  principal frame to the world frame: ``v_world = R(q) v_body``.
- Angular velocity ``omega`` is stored in the WORLD frame, in rad per unit time.
- Inverse inertia ``inv_inertia_body`` is the diagonal of the inverse inertia tensor in the
  principal frame, ``(1/I1, 1/I2, 1/I3)``. A zero entry means an infinite moment about that
  axis (a *locked* axis); all three zero means a body that never rotates.

The step (:func:`advance_rotation`) is the implicit midpoint rule on the BODY angular momentum
of Euler's equations ``dL/dt = L x (I^-1 L)`` followed by the orientation update
``R_{n+1} = R_n cay(dt W)``, ``W = hat(omega_mid)``. The midpoint step can be written
``L_{n+1} = cay(-dt W) L_n``, so ``R_{n+1} L_{n+1} = R_n L_n``: the world angular momentum is
conserved exactly, and, being the midpoint rule, |L| and the kinetic energy (the two quadratic
invariants) are too, up to round-off. The method is symmetric, hence second order.

Locked axes: the lock supplies whatever torque keeps that body-frame component of omega at
zero, and we take the angular momentum about a locked axis as zero at every step (the state
stores omega, which cannot carry it). Euler's equations then leave the free body-frame
components of omega constant: a partially locked body spins uniformly about a body-fixed axis,
its kinetic energy is conserved and its world angular momentum is not (the lock's torque).

Every kernel is ``@njit(cache=True)``, float64, without fastmath; the batch kernel writes only
its own body's slots, so results are bitwise identical at any thread count.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from peclet.core.geom.transforms import (multiply_xyzw, normalize_xyzw, quat_rotate,
                                         quat_rotate_inv, quat_to_matrix, rotate_xyz)
from peclet.core.validation import PecletArgumentError

#: Upper bound on fixed-point iterations of the implicit midpoint step. The map contracts by
#: roughly ``rho = dt |L| max(I^-1) / 2`` per iteration, so a DEM step (dt |omega| << 1) reaches
#: machine precision in well under ten. 24 iterations reach it for rho < ~0.2; beyond that
#: (a rotation of order a radian per step) Newton's method takes over, bounded by
#: MAX_NEWTON_ITERATIONS.
MAX_FIXED_POINT_ITERATIONS = 24
MAX_NEWTON_ITERATIONS = 32

#: The fixed point (or Newton) is declared converged when an iteration changes the midpoint angular
#: velocity by no more than this many ulps of its largest component.
_CONVERGED_ULPS = 4.0
_EPS = 2.220446049250313e-16


# --------------------------------------------------------------------------------------------
# Mass-property helpers
# --------------------------------------------------------------------------------------------

@njit(cache=True)
def world_inv_inertia(q, inv_inertia_body):
    """World-frame inverse inertia tensor ``R diag(inv_inertia_body) R^T`` (3, 3)."""
    R = quat_to_matrix(q)
    out = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            s = 0.0
            for k in range(3):
                s += R[i, k] * inv_inertia_body[k] * R[j, k]
            out[i, j] = s
    return out


@njit(cache=True)
def _body_momentum(omega_body, inv_inertia_body):
    # L = I omega on the free axes; a locked axis (zero inverse moment) carries no momentum by
    # the convention of the module docstring.
    L = np.zeros(3)
    for k in range(3):
        if inv_inertia_body[k] > 0.0:
            L[k] = omega_body[k] / inv_inertia_body[k]
    return L


@njit(cache=True)
def kinetic_energy_rot(q, omega_world, inv_inertia_body):
    """Rotational kinetic energy ``0.5 omega_b . I omega_b`` (omega_b = R^T omega_world).

    Locked axes (zero inverse moment) contribute nothing: their body angular velocity is zero
    by contract (:func:`advance_rotation` enforces it).
    """
    wb = quat_rotate_inv(q, omega_world)
    L = _body_momentum(wb, inv_inertia_body)
    return 0.5 * (L[0] * wb[0] + L[1] * wb[1] + L[2] * wb[2])


@njit(cache=True)
def body_angular_momentum(q, omega_world, inv_inertia_body):
    """Principal-frame angular momentum ``I R^T omega_world`` (3,); locked axes carry none."""
    return _body_momentum(quat_rotate_inv(q, omega_world), inv_inertia_body)


@njit(cache=True)
def angular_momentum_world(q, omega_world, inv_inertia_body):
    """World-frame angular momentum ``R I R^T omega_world`` (3,) about the centre of mass.

    Locked axes (zero inverse moment) contribute nothing (see the module docstring).
    """
    wb = quat_rotate_inv(q, omega_world)
    return quat_rotate(q, _body_momentum(wb, inv_inertia_body))


# --------------------------------------------------------------------------------------------
# The torque-free step
# --------------------------------------------------------------------------------------------

@njit(cache=True)
def _cayley_quat(wx, wy, wz, dt):
    # cay(dt hat(w)) is the rotation by angle 2 atan(dt |w| / 2) about w: its quaternion is
    # (dt w / 2, 1) normalised, exactly.
    h = 0.5 * dt
    px, py, pz = h * wx, h * wy, h * wz
    n = math.sqrt(1.0 + px * px + py * py + pz * pz)
    return px / n, py / n, pz / n, 1.0 / n


@njit(cache=True)
def _midpoint_newton(L0, d, dt, w):
    # Newton on G(m) = m - L0 - (dt/2) m x (D m) for the midpoint momentum m = (L_n + L_{n+1})/2,
    # D = diag(d), starting from m = L0. J = I - (dt/2)(hat(m) D - hat(D m)). Writes w = D m
    # when it converges and leaves w untouched otherwise. 3x3 solve by Cramer's rule (fixed
    # operation order: deterministic, no LAPACK).
    h = 0.5 * dt
    m = L0.copy()
    G = np.empty(3)
    step = np.empty(3)
    J = np.empty((3, 3))
    for _ in range(MAX_NEWTON_ITERATIONS):
        a0, a1, a2 = d[0] * m[0], d[1] * m[1], d[2] * m[2]
        G[0] = m[0] - L0[0] - h * (m[1] * a2 - m[2] * a1)
        G[1] = m[1] - L0[1] - h * (m[2] * a0 - m[0] * a2)
        G[2] = m[2] - L0[2] - h * (m[0] * a1 - m[1] * a0)
        # hat(m) D - hat(D m), entry by entry.
        J[0, 0] = 1.0
        J[0, 1] = -h * (-m[2] * d[1] + a2)
        J[0, 2] = -h * (m[1] * d[2] - a1)
        J[1, 0] = -h * (m[2] * d[0] - a2)
        J[1, 1] = 1.0
        J[1, 2] = -h * (-m[0] * d[2] + a0)
        J[2, 0] = -h * (-m[1] * d[0] + a1)
        J[2, 1] = -h * (m[0] * d[1] - a0)
        J[2, 2] = 1.0
        det = (J[0, 0] * (J[1, 1] * J[2, 2] - J[1, 2] * J[2, 1])
               - J[0, 1] * (J[1, 0] * J[2, 2] - J[1, 2] * J[2, 0])
               + J[0, 2] * (J[1, 0] * J[2, 1] - J[1, 1] * J[2, 0]))
        if det == 0.0 or not (abs(det) < np.inf):
            return
        change = 0.0
        scale = 0.0
        for c in range(3):
            # Cramer: replace column c of J by G.
            M = J.copy()
            for r in range(3):
                M[r, c] = G[r]
            dc = (M[0, 0] * (M[1, 1] * M[2, 2] - M[1, 2] * M[2, 1])
                  - M[0, 1] * (M[1, 0] * M[2, 2] - M[1, 2] * M[2, 0])
                  + M[0, 2] * (M[1, 0] * M[2, 1] - M[1, 1] * M[2, 0])) / det
            change = max(change, abs(dc))
            scale = max(scale, abs(m[c]))
            step[c] = dc
        for c in range(3):
            m[c] -= step[c]
        if not (change < np.inf):
            return
        if change <= _CONVERGED_ULPS * _EPS * scale:
            for c in range(3):
                w[c] = d[c] * m[c]
            return


@njit(cache=True)
def _advance_into(q, omega_world, inv_inertia_body, dt, q_out, omega_out):
    # One body; writes q_out (4,) and omega_out (3,) (which may alias q and omega_world: all
    # inputs are read first) and returns True, or returns False without writing when q is zero
    # or the state is not finite. The single implementation behind both the scalar and the batch
    # API, so the two give the same bits. Scalar arithmetic only, no heap allocation, except in
    # the rare Newton fallback.
    d0, d1, d2 = inv_inertia_body[0], inv_inertia_body[1], inv_inertia_body[2]
    qx, qy, qz, qw = q[0], q[1], q[2], q[3]
    if d0 == 0.0 and d1 == 0.0 and d2 == 0.0:
        ox, oy, oz = omega_world[0], omega_world[1], omega_world[2]
        q_out[0], q_out[1], q_out[2], q_out[3] = qx, qy, qz, qw
        omega_out[0], omega_out[1], omega_out[2] = ox, oy, oz
        return True
    bx, by, bz = rotate_xyz(-qx, -qy, -qz, qw, omega_world[0], omega_world[1], omega_world[2])
    if d0 == 0.0 or d1 == 0.0 or d2 == 0.0:
        # Free components of the body angular velocity are constant (module docstring).
        wx = bx if d0 > 0.0 else 0.0
        wy = by if d1 > 0.0 else 0.0
        wz = bz if d2 > 0.0 else 0.0
        nx, ny, nz = wx, wy, wz
        px, py, pz, pw = _cayley_quat(wx, wy, wz, dt)
    else:
        L0x, L0y, L0z = bx / d0, by / d1, bz / d2
        # Fixed point on the midpoint angular velocity w = I^-1 (L_n + cay(-dt W) L_n) / 2.
        # Writing L_{n+1} through the Cayley rotation keeps |L| exact even before convergence.
        wx, wy, wz = bx, by, bz
        converged = False
        for _ in range(MAX_FIXED_POINT_ITERATIONS):
            px, py, pz, pw = _cayley_quat(wx, wy, wz, dt)
            L1x, L1y, L1z = rotate_xyz(-px, -py, -pz, pw, L0x, L0y, L0z)
            vx = d0 * (0.5 * (L0x + L1x))
            vy = d1 * (0.5 * (L0y + L1y))
            vz = d2 * (0.5 * (L0z + L1z))
            change = max(abs(vx - wx), abs(vy - wy), abs(vz - wz))
            scale = max(abs(vx), abs(vy), abs(vz))
            wx, wy, wz = vx, vy, vz
            if change <= _CONVERGED_ULPS * _EPS * scale:
                converged = True
                break
        if not converged:
            # Only when dt |omega| is of order one (a rotation of about a radian per step) does
            # the fixed point stop contracting; Newton still finds the midpoint root there.
            L0 = np.empty(3)
            L0[0], L0[1], L0[2] = L0x, L0y, L0z
            w = np.empty(3)
            w[0], w[1], w[2] = wx, wy, wz
            _midpoint_newton(L0, inv_inertia_body, dt, w)
            wx, wy, wz = w[0], w[1], w[2]
        # L_{n+1} and the orientation are built from the same, final w, so that
        # R_{n+1} L_{n+1} = R_n L_n holds to round-off.
        px, py, pz, pw = _cayley_quat(wx, wy, wz, dt)
        L1x, L1y, L1z = rotate_xyz(-px, -py, -pz, pw, L0x, L0y, L0z)
        nx, ny, nz = d0 * L1x, d1 * L1y, d2 * L1z
    # q_new = q p (the body-frame increment acts first), renormalised.
    rx, ry, rz, rw = multiply_xyzw(qx, qy, qz, qw, px, py, pz, pw)
    rx, ry, rz, rw, ok = normalize_xyzw(rx, ry, rz, rw)
    if not (ok and abs(nx) + abs(ny) + abs(nz) < np.inf):
        return False  # the caller raises: an exception cannot leave a prange body cleanly
    ox, oy, oz = rotate_xyz(rx, ry, rz, rw, nx, ny, nz)
    q_out[0], q_out[1], q_out[2], q_out[3] = rx, ry, rz, rw
    omega_out[0], omega_out[1], omega_out[2] = ox, oy, oz
    return True


@njit(cache=True)
def _check_step_args(inv_inertia, dt):
    if not (abs(dt) < np.inf):
        raise PecletArgumentError("dt", "a finite number", dt)
    for v in inv_inertia.ravel():
        if not (v >= 0.0 and v < np.inf):
            raise PecletArgumentError("inv_inertia_body", "entries that are finite and >= 0", v)


@njit(cache=True)
def advance_rotation(q, omega_world, inv_inertia_body, dt):
    """Torque-free rotation of one rigid body over ``dt``.

    Parameters: ``q`` (4,) unit quaternion (x, y, z, w), body(principal) -> world;
    ``omega_world`` (3,) angular velocity in the world frame [rad / time];
    ``inv_inertia_body`` (3,) principal inverse moments [1 / (mass length^2)], each finite and
    >= 0 (0 = locked axis); ``dt`` finite time step.

    Returns ``(q_new, omega_world_new)``. Implicit midpoint on the body angular momentum, solved
    by fixed-point iteration to machine precision, then the Cayley orientation update (module
    docstring): world angular momentum, |L| and kinetic energy are conserved to round-off and
    the step is second order. A locked axis keeps a zero body angular velocity; all three locked
    returns q and omega unchanged. Regime: the fixed point contracts while dt |omega| is well
    below one radian (any sensible DEM step); beyond that Newton's method solves the midpoint
    equation, and where that equation has no real root (seen at dt |omega| ~ 5) the last
    iterate is used: world angular momentum and |L| are then still exact, the energy is not.
    Raises PecletArgumentError for a non-finite dt, a negative or non-finite inverse moment,
    or a zero / non-finite q or non-finite omega.
    """
    _check_step_args(inv_inertia_body, dt)
    q_out = np.empty(4)
    omega_out = np.empty(3)
    if not _advance_into(q, omega_world, inv_inertia_body, dt, q_out, omega_out):
        raise PecletArgumentError("q", "a finite non-zero quaternion (x, y, z, w), with "
                                  "omega_world finite", (q[0], q[1], q[2], q[3]))
    return q_out, omega_out


@njit(cache=True, parallel=True)
def advance_rotations(quats, omegas, inv_inertia, dt):
    """In-place :func:`advance_rotation` of N bodies: ``quats`` (N, 4), ``omegas`` (N, 3) world,
    ``inv_inertia`` (N, 3) principal inverse moments. Parallel over bodies; each body writes only
    its own rows, so the result is bitwise identical at any thread count and equal to the
    scalar function's. Raises PecletArgumentError for mismatched shapes, bad dt / inverse
    moments, or a zero / non-finite quaternion or non-finite omega (naming the first such body
    as the error's ``value``; that body is left unchanged, the others are advanced).
    """
    n = quats.shape[0]
    if quats.shape[1] != 4 or omegas.shape[0] != n or omegas.shape[1] != 3 \
            or inv_inertia.shape[0] != n or inv_inertia.shape[1] != 3:
        raise PecletArgumentError("quats", "an (N, 4) array, with omegas and inv_inertia (N, 3)",
                                  n)
    _check_step_args(inv_inertia, dt)
    ok = np.empty(n, dtype=np.bool_)
    for i in prange(n):
        ok[i] = _advance_into(quats[i], omegas[i], inv_inertia[i], dt, quats[i], omegas[i])
    for i in range(n):
        if not ok[i]:
            # Bodies before and after i were advanced; body i is left as it was.
            raise PecletArgumentError("quats", "rows that are finite non-zero quaternions "
                                      "(x, y, z, w), with omegas finite", i, "first bad body")


#: Below this many bodies :func:`advance_all` runs serially: a body costs ~0.2 us, and on a
#: loaded 2-core machine a parallel launch was measured at several milliseconds.
PARALLEL_ROTATION_MIN = 50000


@njit(cache=True)
def _advance_serial(quats, omegas, inv_inertia, dt):
    for i in range(quats.shape[0]):
        qn, wn = advance_rotation(quats[i], omegas[i], inv_inertia[i], dt)
        for k in range(4):          # element copies: a slice assignment compiles a
            quats[i, k] = qn[k]     # shape-mismatch message (seconds of a cold start)
        for k in range(3):
            omegas[i, k] = wn[k]


def advance_all(quats, omegas, inv_inertia, dt):
    """Torque-free rotation of every body in place: :func:`advance_rotations` for many bodies,
    a serial loop of :func:`advance_rotation` for few. Both run the same per-body kernel, so
    the choice never changes a bit."""
    if len(quats) >= PARALLEL_ROTATION_MIN:
        advance_rotations(quats, omegas, inv_inertia, dt)
    else:
        _advance_serial(quats, omegas, inv_inertia, dt)
