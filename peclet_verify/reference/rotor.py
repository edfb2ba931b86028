"""Reference solutions of the torque-free rigid rotor: the oracles the rotor step is tested on.

Slow or scipy-based on purpose (not the engine's path): the closed-form period of Euler's
equations (Landau & Lifshitz, Mechanics §37, via the complete elliptic integral), an
independent tight ODE solve with event location (scipy's DOP853), and the crossing-time
analysis that measures an integrator's period. :func:`integrate_free_rotor` runs the engine's
step (:func:`peclet.dem.rigid.advance_rotation`) and records the trajectory to compare.

Conventions as in :mod:`peclet.dem.rigid`: quaternions (x, y, z, w) active, body -> world;
omega in the world frame; ``inv_inertia_body`` the principal inverse moments.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from peclet.dem.rigid import advance_rotation, body_angular_momentum

__all__ = ["integrate_free_rotor", "free_rotor_period", "crossing_times",
           "period_from_crossings", "euler_reference_crossings"]


@njit(cache=True)
def integrate_free_rotor(q, omega_world, inv_inertia_body, dt, n_steps):
    """Run :func:`peclet.dem.rigid.advance_rotation` ``n_steps`` times from (q, omega_world).

    Returns ``(quats (n+1, 4), omegas_world (n+1, 3), L_body (n+1, 3))``, row 0 the initial
    state; ``L_body = I R^T omega`` is the principal-frame angular momentum.
    """
    quats = np.empty((n_steps + 1, 4))
    omegas = np.empty((n_steps + 1, 3))
    L_body = np.empty((n_steps + 1, 3))
    quats[0, :] = q
    omegas[0, :] = omega_world
    for i in range(n_steps + 1):
        if i > 0:
            qn, wn = advance_rotation(quats[i - 1], omegas[i - 1], inv_inertia_body, dt)
            quats[i, :] = qn
            omegas[i, :] = wn
        L_body[i, :] = body_angular_momentum(quats[i], omegas[i], inv_inertia_body)
    return quats, omegas, L_body


def free_rotor_period(inv_inertia_body, L_body):
    """Closed-form period of the body angular momentum of a free asymmetric rotor.

    Landau & Lifshitz, Mechanics §37: with ``I1 < I2 < I3``, ``M^2 = |L|^2`` and
    ``2E = sum L_i^2 / I_i``, the body components are Jacobi elliptic functions of
    ``tau = t * rate`` with parameter ``m = k^2`` and period ``4 K(m)`` in tau, where for
    ``M^2 > 2 E I2`` (orbit round the I3 axis)

        rate^2 = (I3 - I2)(M^2 - 2E I1) / (I1 I2 I3),  m = (I2 - I1)(2E I3 - M^2) / ((I3 - I2)(M^2 - 2E I1))

    and for ``M^2 < 2 E I2`` the roles of I1 and I3 swap. Returns the period ``4 K(m) / rate``
    in the time unit of the moments. ``inv_inertia_body`` must be three distinct positive
    values (any order); ``L_body`` the principal-frame angular momentum (same order).
    Raises ValueError on the separatrix (``M^2 = 2 E I2``, infinite period) or bad moments.
    """
    from scipy.special import ellipk

    iinv = np.asarray(inv_inertia_body, dtype=np.float64).reshape(3)
    L = np.asarray(L_body, dtype=np.float64).reshape(3)
    if not np.all(np.isfinite(iinv) & (iinv > 0.0)) or len(set(iinv.tolist())) != 3:
        raise ValueError("free_rotor_period: inv_inertia_body must be 3 distinct finite values > 0")
    order = np.argsort(1.0 / iinv)
    I1, I2, I3 = (1.0 / iinv)[order]
    M2 = float(L @ L)
    E2 = float(np.sum(L * L * iinv))
    if M2 > E2 * I2:
        rate2 = (I3 - I2) * (M2 - E2 * I1) / (I1 * I2 * I3)
        m = (I2 - I1) * (E2 * I3 - M2) / ((I3 - I2) * (M2 - E2 * I1))
    elif M2 < E2 * I2:
        rate2 = (I2 - I1) * (E2 * I3 - M2) / (I1 * I2 * I3)
        m = (I3 - I2) * (M2 - E2 * I1) / ((I2 - I1) * (E2 * I3 - M2))
    else:
        raise ValueError("free_rotor_period: L_body lies on the separatrix (M^2 = 2 E I2)")
    return float(4.0 * ellipk(m) / math.sqrt(rate2))


def crossing_times(t, x, dxdt, direction=0):
    """Times where the sampled signal x(t) crosses zero, from cubic Hermite interpolation.

    ``t`` (n,) increasing sample times, ``x`` and ``dxdt`` (n,) values and exact derivatives.
    Hermite interpolation is O(h^4) accurate, so the crossing times carry no O(h^2) bias of
    their own and the second-order error of an integrator is measured cleanly.
    ``direction`` +1 / -1 keeps only upward / downward crossings, 0 keeps both.
    """
    t = np.asarray(t, dtype=np.float64)
    x = np.asarray(x, dtype=np.float64)
    d = np.asarray(dxdt, dtype=np.float64)
    if direction not in (-1, 0, 1):
        raise ValueError("crossing_times: direction must be -1, 0 or +1")
    out = []
    idx = np.nonzero((x[:-1] * x[1:] < 0.0) | ((x[:-1] != 0.0) & (x[1:] == 0.0)))[0]
    for i in idx:
        if direction and np.sign(x[i + 1] - x[i]) != direction:
            continue
        h = t[i + 1] - t[i]
        x0, x1, m0, m1 = x[i], x[i + 1], d[i] * h, d[i + 1] * h

        def f(s):
            return ((2 * s**3 - 3 * s**2 + 1) * x0 + (s**3 - 2 * s**2 + s) * m0
                    + (-2 * s**3 + 3 * s**2) * x1 + (s**3 - s**2) * m1)

        lo, hi = 0.0, 1.0
        flo = f(lo)
        for _ in range(80):  # bisection: robust, and 80 halvings reach round-off
            mid = 0.5 * (lo + hi)
            fm = f(mid)
            if (fm < 0.0) == (flo < 0.0) and fm != 0.0:
                lo, flo = mid, fm
            else:
                hi = mid
        out.append(t[i] + 0.5 * (lo + hi) * h)
    return np.array(out)


def period_from_crossings(times):
    """Period from successive same-direction crossing times: least-squares slope of time
    against crossing index (uses every crossing, not just the first and last)."""
    times = np.asarray(times, dtype=np.float64)
    if times.size < 2:
        raise ValueError("period_from_crossings: need at least 2 crossing times")
    k = np.arange(times.size, dtype=np.float64)
    return float(np.polyfit(k, times, 1)[0])


def euler_reference_crossings(inv_inertia_body, L_body, t_end, component, direction=1):
    """Crossing times of ``L_body[component]`` through zero for Euler's equations
    ``dL/dt = L x (I^-1 L)`` integrated by scipy's DOP853 (rtol = atol = 1e-12) with event
    location. ``direction`` as in :func:`crossing_times` (+1 upward)."""
    from scipy.integrate import solve_ivp

    iinv = np.asarray(inv_inertia_body, dtype=np.float64).reshape(3)

    def rhs(_t, L):
        return np.cross(L, iinv * L)

    def event(_t, L):
        return L[component]

    event.direction = direction
    sol = solve_ivp(rhs, (0.0, t_end), np.asarray(L_body, dtype=np.float64), method="DOP853",
                    rtol=1e-12, atol=1e-12, events=event)
    return np.asarray(sol.t_events[0])
