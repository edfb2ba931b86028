"""Closed-form mechanics certificates of any :class:`~peclet_verify.dem.backend.DemBackend`:
binary restitution, slide to roll, incline stick/slip and the free rigid body. Each takes a
backend and one case of :mod:`peclet_verify.mechanics.strategies`, runs its page-API scenario
(:func:`~peclet_verify.dem.properties.run_checked`: the answer is checked first) and returns
a :class:`~peclet_verify.search.PropertyResult`. Tolerances are keyword arguments, the
basis of each default in its docstring; the physics follows validation/sanity.py.
"""
from __future__ import annotations

import math

import numpy as np

from .. import registry as REG
from ..dem.properties import run_checked
from ..loading import backend_name
from ..search import bad_answer, make_result
from .strategies import G, Collision, Incline, Roll, Rotor, unit

__all__ = ["binary_restitution", "slide_to_roll", "incline", "free_rigid_body"]


def _run(backend, name, case):
    """``(scenario, trajectory, None)`` of ``case``'s page-API run at one thread, or
    ``(scenario, None, failed result)`` when the engine's answer is unusable (the certificate
    ``name`` fails with the answer shown)."""
    sc = case.scenario()
    traj, why = run_checked(backend, sc, 1)
    return sc, traj, (bad_answer(name, REG.figure(name), "max", why) if why else None)


def binary_restitution(backend, c: Collision, tol=1e-4, momentum_rtol=1e-6):
    """Separation speed / approach speed along the line of centres equals e (within ``tol``,
    absolute: an impulse solve of one two-body contact is exact, peclet's error is ~1e-15;
    1e-4 leaves room for single precision), and momentum is conserved (``momentum_rtol`` of
    the larger momentum). Figure: |ratio - e|."""
    name = "binary_restitution"
    fig = REG.figure(name)
    sc, traj, unusable = _run(backend, name, c)
    if unusable:
        return unusable
    n = unit(c.axis)
    v = traj["velocities"][-1]
    approach = c.speeds[0] + c.speeds[1]
    sep = float((v[1] - v[0]) @ n)
    ratio = sep / approach
    m = np.asarray(c.masses, float)
    p0 = m[0] * c.speeds[0] * n - m[1] * c.speeds[1] * n
    dp = float(np.linalg.norm((m[:, None] * v).sum(axis=0) - p0))
    pscale = float(max(m * np.asarray(c.speeds)))
    err = abs(ratio - c.e)
    ok = err <= tol and dp <= momentum_rtol * pscale
    text = (f"{backend_name(backend)}: separation / approach = {sep:.9g} / {approach:.9g} = "
            f"{ratio:.9g}, expected e = {c.e!r} (|diff| {err:.3e}, tol {tol:g}); momentum "
            f"change {dp:.3e} (allowed {momentum_rtol * pscale:.3e})")
    return make_result(name, ok, err, fig, "max", text, ratio=ratio, momentum_error=dp)


def slide_to_roll(backend, roll: Roll, rtol=1e-4):
    """After the slip stops (t = 2 v0 / (7 mu g), run 0.1 s past it) the sphere rolls at
    v = 5/7 v0 with omega r = v: both within ``rtol`` x v0 (peclet: 1e-9, exact sliding
    friction impulses; 1e-4 leaves room for single precision). Figure: worst relative error."""
    name = "slide_to_roll"
    fig = REG.figure(name)
    sc, traj, unusable = _run(backend, name, roll)
    if unusable:
        return unusable
    v = traj["velocities"][-1, 0]
    w = traj["angular_velocities"][-1, 0]
    vx = float(v[0])
    wr = float(-w[2] * roll.radius)
    e_v = abs(vx - 5.0 * roll.v0 / 7.0) / roll.v0
    e_roll = abs(vx - wr) / roll.v0
    worst = max(e_v, e_roll)
    text = (f"{backend_name(backend)}: final v = {vx:.9g} m/s, expected 5/7 v0 = "
            f"{5 * roll.v0 / 7:.9g} (rel error {e_v:.2e}); omega r = {wr:.9g} (slip "
            f"{e_roll:.2e} of v0); tol {rtol:g}")
    return make_result(name, worst <= rtol, worst, fig, "max", text, v=vx, omega_r=wr)


def incline(backend, inc: Incline, settle=0.1, creep_tol=1e-6, a_rtol=1e-3):
    """tan(theta) < mu: the cube sticks (after ``settle`` s its displacement down the slope
    changes by at most ``creep_tol`` x half side; in all at most the free slide of 3 steps,
    g sin(theta) (3 dt)^2 / 2, for a friction that starts cold). tan(theta) > mu: it slides
    with a = g (sin theta - mu cos theta) (least squares over t >= ``settle``, within
    ``a_rtol``; peclet 1e-6). Figure: the worst error over its allowance (<= 1 passes)."""
    name = "incline"
    fig = REG.figure(name)
    sc, traj, unusable = _run(backend, name, inc)
    if unusable:
        return unusable
    th = math.radians(inc.theta_deg)
    down = np.array([-math.cos(th), -math.sin(th), 0.0])
    x = traj["positions"][:, 0, :]
    d = (x - x[0]) @ down
    t = np.asarray(sc.record_steps(), float) * inc.dt
    k = int(np.searchsorted(t, settle - 1e-12))
    if inc.sticks:
        creep = abs(d[-1] - d[k])
        slip = abs(d[-1])
        cold = 0.5 * G * math.sin(th) * (3 * inc.dt) ** 2
        ratio = max(creep / (creep_tol * inc.half), slip / cold)
        text = (f"{backend_name(backend)}: tan(theta) = {math.tan(th):.4f} < mu = {inc.mu}: must "
                f"stick, but it moved {creep:.3e} m after {settle} s (allowed "
                f"{creep_tol * inc.half:.1e}) and {slip:.3e} m in all (allowed {cold:.2e})")
        return make_result(name, ratio <= 1.0, ratio, fig, "max", text, creep=creep, slip=slip)
    a_exp = G * (math.sin(th) - inc.mu * math.cos(th))
    m = t >= settle
    A = np.column_stack([np.ones(m.sum()), t[m], 0.5 * t[m] ** 2])
    a = float(np.linalg.lstsq(A, d[m], rcond=None)[0][2])
    err = abs(a - a_exp) / a_exp
    text = (f"{backend_name(backend)}: tan(theta) = {math.tan(th):.4f} > mu = {inc.mu}: slides "
            f"with a = {a:.9g} m/s^2, expected g (sin - mu cos) = {a_exp:.9g} (rel error "
            f"{err:.2e}, tol {a_rtol:g})")
    return make_result(name, err <= a_rtol, err / a_rtol, fig, "max", text, a=a, a_expected=a_exp)


def free_rigid_body(backend, rot: Rotor, conservation_rtol=1e-6, period_rtol=1e-2):
    """No contact, no gravity: the kinetic energy and the world angular momentum are conserved
    (relative drift <= ``conservation_rtol``; peclet ~1e-12, an implicit-midpoint rotor), and
    the intermediate-axis flip period, from the upward zero crossings of the body angular
    momentum's intermediate component (cubic Hermite, exact derivatives from Euler's
    equations), equals the closed form of Euler's equations
    (:func:`peclet_verify.reference.rotor.free_rotor_period`) within ``period_rtol`` (the
    run takes 400 steps per period; a second-order integrator is ~1e-4 off). Figure: the
    worst error over its allowance."""
    from peclet.core.geom import quat_to_matrix
    from ..reference.rotor import crossing_times, period_from_crossings
    name = "free_rigid_body"
    fig = REG.figure(name)
    T = rot.reference_period()
    sc, traj, unusable = _run(backend, name, rot)
    if unusable:
        return unusable
    I = np.asarray(rot.moments, float)
    qs, ws = traj["quaternions"][:, 0], traj["angular_velocities"][:, 0]
    Rs = np.stack([quat_to_matrix(q / np.linalg.norm(q)) for q in qs])
    wb = np.einsum("kji,kj->ki", Rs, ws)            # R^T omega
    Lb = I * wb
    Lw = np.einsum("kij,kj->ki", Rs, Lb)
    E = 0.5 * np.sum(I * wb * wb, axis=1)
    dL = float(np.linalg.norm(Lw - Lw[0], axis=1).max() / np.linalg.norm(Lw[0]))
    dE = float(np.abs(E - E[0]).max() / E[0])
    t = np.asarray(sc.record_steps(), float) * sc.dt
    dLdt = np.cross(Lb, Lb / I)
    ups = crossing_times(t, Lb[:, 1], dLdt[:, 1], direction=+1)
    if len(ups) < 2:
        ratio_p = math.inf
        text_p = (f"the intermediate component of L crossed zero upwards {len(ups)} time(s) in "
                  f"{t[-1]:.4g} s, expected 2 (period {T:.6g} s): no flip")
        Tm = float("nan")
    else:
        Tm = period_from_crossings(ups)
        ratio_p = abs(Tm - T) / T / period_rtol
        text_p = (f"flip period {Tm:.9g} s, Euler's equations {T:.9g} s (rel error "
                  f"{abs(Tm - T) / T:.2e}, tol {period_rtol:g})")
    worst = max(dL / conservation_rtol, dE / conservation_rtol, ratio_p)
    text = (f"{backend_name(backend)}: angular momentum drift {dL:.2e}, energy drift {dE:.2e} (tol "
            f"{conservation_rtol:g}); {text_p}")
    return make_result(name, worst <= 1.0, worst, fig, "max", text, momentum_drift=dL,
                   energy_drift=dE, period=Tm, period_reference=T)
