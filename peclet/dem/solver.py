"""Contact solvers: projected Gauss-Seidel on velocities, and a non-penetration projection.

Conventions: a contact i joins body ``a[i]`` and body ``b[i]`` (``b < 0`` = a static wall);
``normal`` points from b to a; ``ra``/``rb`` are the contact point relative to each body's
centre of mass (b's image, for periodic pairs). Impulses act on a along +n, on b along -n.

Velocity solve (per contact, accumulated impulses, serial and in a fixed order, with the
sweep direction alternating between iterations -- symmetric Gauss-Seidel propagates through
deep stacks in both directions):

- normal: ``lambda_n >= 0`` and the relative normal velocity ``v_n >= vmin``, where
  ``vmin = -gap/dt`` for a speculative contact (gap > 0, it may close but not cross),
  ``0`` for a touching one, and ``-e v_n^-`` for a colliding one (approach faster than the
  resting threshold and reached within this step, to within the slop) when e > 0;
- friction: the tangential relative velocity is driven to ``-beta v_t^-`` (Walton's
  tangential restitution) for a colliding contact and to 0 otherwise, inside the Coulomb cone
  ``|lambda_t| <= mu lambda_n`` (a disc in the tangent plane, not a pyramid).

Position projection: non-linear Gauss-Seidel on the predicted end-of-step gaps
``gap + dt v_n`` with accumulated, non-negative corrections; each correction moves AND rotates
both bodies with the same effective mass as the velocity constraint (not translation only), and
never touches the velocities.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from peclet.core.geom.transforms import quat_multiply, quat_normalize
from peclet.dem.rigid import world_inv_inertia


class Constraints(NamedTuple):
    """The contacts of a step as the solvers see them: bodies ``a``, ``b`` (n,) (b < 0 a
    wall), unit ``normal``, tangents ``t1``, ``t2`` (n, 3), lever arms ``ra``, ``rb`` (n, 3)
    (zero for a wall), signed ``gap`` (n,), restitution ``e``, tangential restitution
    ``beta`` and friction ``mu`` (n,), and ``vw`` (n, 3) the velocity of b's surface at the
    contact point when b is a moving wall (zero otherwise: the relative velocity is then
    exactly that of a static wall)."""
    a: np.ndarray
    b: np.ndarray
    normal: np.ndarray
    t1: np.ndarray
    t2: np.ndarray
    ra: np.ndarray
    rb: np.ndarray
    gap: np.ndarray
    e: np.ndarray
    beta: np.ndarray
    mu: np.ndarray
    vw: np.ndarray


@njit(cache=True, inline="always")
def _cross(a0, a1, a2, b0, b1, b2):
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True, inline="always")
def _ang_term(I, r, d):
    """(r x d) . I (r x d) and I (r x d)."""
    c0, c1, c2 = _cross(r[0], r[1], r[2], d[0], d[1], d[2])
    u0 = I[0, 0] * c0 + I[0, 1] * c1 + I[0, 2] * c2
    u1 = I[1, 0] * c0 + I[1, 1] * c1 + I[1, 2] * c2
    u2 = I[2, 0] * c0 + I[2, 1] * c1 + I[2, 2] * c2
    return c0 * u0 + c1 * u1 + c2 * u2


@njit(cache=True, inline="always")
def _eff_mass(a, b, ra, rb, d, inv_mass, invI):
    k = inv_mass[a] + _ang_term(invI[a], ra, d)
    if b >= 0:
        k += inv_mass[b] + _ang_term(invI[b], rb, d)
    return k


@njit(cache=True, inline="always")
def _rel_vel(a, b, ra, rb, v, w, out):
    c0, c1, c2 = _cross(w[a, 0], w[a, 1], w[a, 2], ra[0], ra[1], ra[2])
    out[0] = v[a, 0] + c0
    out[1] = v[a, 1] + c1
    out[2] = v[a, 2] + c2
    if b >= 0:
        c0, c1, c2 = _cross(w[b, 0], w[b, 1], w[b, 2], rb[0], rb[1], rb[2])
        out[0] -= v[b, 0] + c0
        out[1] -= v[b, 1] + c1
        out[2] -= v[b, 2] + c2


@njit(cache=True, inline="always")
def _minus_wall(vr, vw, i):
    """The relative velocity against a moving wall's surface: vr -= vw[i] (exactly vr for a
    static wall, vw = 0)."""
    vr[0] -= vw[i, 0]
    vr[1] -= vw[i, 1]
    vr[2] -= vw[i, 2]


@njit(cache=True, inline="always")
def _apply(a, b, ra, rb, P, lin, ang, inv_mass, invI):
    """lin[a] += m_a^-1 P, ang[a] += I_a^-1 (ra x P); the opposite on b."""
    c0, c1, c2 = _cross(ra[0], ra[1], ra[2], P[0], P[1], P[2])
    for e in range(3):
        lin[a, e] += inv_mass[a] * P[e]
        ang[a, e] += invI[a, e, 0] * c0 + invI[a, e, 1] * c1 + invI[a, e, 2] * c2
    if b >= 0:
        c0, c1, c2 = _cross(rb[0], rb[1], rb[2], P[0], P[1], P[2])
        for e in range(3):
            lin[b, e] -= inv_mass[b] * P[e]
            ang[b, e] -= invI[b, e, 0] * c0 + invI[b, e, 1] * c1 + invI[b, e, 2] * c2


@njit(cache=True)
def tangent_basis(normal):
    """Two unit tangents (n, 3) each, a fixed function of the normal."""
    n = normal.shape[0]
    t1 = np.empty((n, 3))
    t2 = np.empty((n, 3))
    for i in range(n):
        nx, ny, nz = normal[i, 0], normal[i, 1], normal[i, 2]
        if abs(nx) < 0.57:
            a0, a1, a2 = 0.0, nz, -ny        # n x e_x
        else:
            a0, a1, a2 = -nz, 0.0, nx        # n x e_y
        s = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
        t1[i, 0] = a0 / s
        t1[i, 1] = a1 / s
        t1[i, 2] = a2 / s
        b0, b1, b2 = _cross(nx, ny, nz, t1[i, 0], t1[i, 1], t1[i, 2])
        t2[i, 0] = b0
        t2[i, 1] = b1
        t2[i, 2] = b2
    return t1, t2


@njit(cache=True)
def solve_velocities(con, lam, v, w, inv_mass, invI, dt, rest_threshold, slop, iterations):
    """Projected Gauss-Seidel over the :class:`Constraints` ``con``, in place on ``v``, ``w``
    (N, 3) and the accumulated impulses ``lam`` (n, 3) = (lambda_n, lambda_t1, lambda_t2),
    which enter as the warm start. ``inv_mass`` (N,), ``invI`` (N, 3, 3) world inverse inertia.
    Returns the normal relative velocity of every contact after the solve (n,)."""
    ca, cb, normal, t1, t2, ra, rb = con.a, con.b, con.normal, con.t1, con.t2, con.ra, con.rb
    gap, e_n, beta, mu, vw = con.gap, con.e, con.beta, con.mu, con.vw
    n = ca.shape[0]
    kn = np.empty(n)
    kt1 = np.empty(n)
    kt2 = np.empty(n)
    vmin = np.empty(n)
    tt1 = np.empty(n)
    tt2 = np.empty(n)
    vr = np.empty(3)
    P = np.empty(3)
    for i in range(n):
        a = ca[i]
        b = cb[i]
        kn[i] = _eff_mass(a, b, ra[i], rb[i], normal[i], inv_mass, invI)
        kt1[i] = _eff_mass(a, b, ra[i], rb[i], t1[i], inv_mass, invI)
        kt2[i] = _eff_mass(a, b, ra[i], rb[i], t2[i], inv_mass, invI)
        _rel_vel(a, b, ra[i], rb[i], v, w, vr)
        _minus_wall(vr, vw, i)
        vn = vr[0] * normal[i, 0] + vr[1] * normal[i, 1] + vr[2] * normal[i, 2]
        base = -(gap[i] - slop) / dt if gap[i] > slop else 0.0
        # reached within this step, to within the slop: a contact that would end the step
        # in [0, slop) is an impact too, or the speculative bound would slow it to end at
        # the slop (by up to slop/dt) and restitution would act on the reduced speed
        colliding = vn < -rest_threshold and gap[i] + vn * dt < slop
        vmin[i] = base
        tt1[i] = 0.0
        tt2[i] = 0.0
        if colliding:
            if e_n[i] > 0.0:
                vmin[i] = max(base, -e_n[i] * vn)
            tt1[i] = -beta[i] * (vr[0] * t1[i, 0] + vr[1] * t1[i, 1] + vr[2] * t1[i, 2])
            tt2[i] = -beta[i] * (vr[0] * t2[i, 0] + vr[1] * t2[i, 1] + vr[2] * t2[i, 2])
    # warm start
    for i in range(n):
        if lam[i, 0] != 0.0 or lam[i, 1] != 0.0 or lam[i, 2] != 0.0:
            for e in range(3):
                P[e] = lam[i, 0] * normal[i, e] + lam[i, 1] * t1[i, e] + lam[i, 2] * t2[i, e]
            _apply(ca[i], cb[i], ra[i], rb[i], P, v, w, inv_mass, invI)
    for it in range(iterations):
        for s in range(n):
            i = s if it % 2 == 0 else n - 1 - s
            a = ca[i]
            b = cb[i]
            if kn[i] <= 0.0:
                continue
            _rel_vel(a, b, ra[i], rb[i], v, w, vr)
            _minus_wall(vr, vw, i)
            vn = vr[0] * normal[i, 0] + vr[1] * normal[i, 1] + vr[2] * normal[i, 2]
            old = lam[i, 0]
            new = old + (vmin[i] - vn) / kn[i]
            if new < 0.0:
                new = 0.0
            dl = new - old
            lam[i, 0] = new
            if dl != 0.0:
                for e in range(3):
                    P[e] = dl * normal[i, e]
                _apply(a, b, ra[i], rb[i], P, v, w, inv_mass, invI)
            # friction: both tangents, then the cone
            _rel_vel(a, b, ra[i], rb[i], v, w, vr)
            _minus_wall(vr, vw, i)
            u1 = vr[0] * t1[i, 0] + vr[1] * t1[i, 1] + vr[2] * t1[i, 2]
            u2 = vr[0] * t2[i, 0] + vr[1] * t2[i, 1] + vr[2] * t2[i, 2]
            o1 = lam[i, 1]
            o2 = lam[i, 2]
            n1 = o1 + (tt1[i] - u1) / kt1[i]
            n2 = o2 + (tt2[i] - u2) / kt2[i]
            lim = mu[i] * lam[i, 0]
            m = math.sqrt(n1 * n1 + n2 * n2)
            if m > lim:
                if m > 0.0:
                    n1 *= lim / m
                    n2 *= lim / m
            lam[i, 1] = n1
            lam[i, 2] = n2
            d1 = n1 - o1
            d2 = n2 - o2
            if d1 != 0.0 or d2 != 0.0:
                for e in range(3):
                    P[e] = d1 * t1[i, e] + d2 * t2[i, e]
                _apply(a, b, ra[i], rb[i], P, v, w, inv_mass, invI)
    vn_out = np.empty(n)
    for i in range(n):
        _rel_vel(ca[i], cb[i], ra[i], rb[i], v, w, vr)
        _minus_wall(vr, vw, i)
        vn_out[i] = vr[0] * normal[i, 0] + vr[1] * normal[i, 1] + vr[2] * normal[i, 2]
    return vn_out


@njit(cache=True)
def project_positions(con, gap_end, inv_mass, invI, slop, iterations, pos, quats):
    """Remove the predicted end-of-step overlaps ``gap_end < 0`` of the :class:`Constraints`
    ``con`` by moving and rotating the bodies (in place on ``pos`` (N, 3) and ``quats``
    (N, 4)); velocities are not touched."""
    ca, cb, normal, ra, rb = con.a, con.b, con.normal, con.ra, con.rb
    n = ca.shape[0]
    nb = pos.shape[0]
    dx = np.zeros((nb, 3))
    dth = np.zeros((nb, 3))
    acc = np.zeros(n)
    kn = np.empty(n)
    P = np.empty(3)
    any_overlap = False
    for i in range(n):
        kn[i] = _eff_mass(ca[i], cb[i], ra[i], rb[i], normal[i], inv_mass, invI)
        if gap_end[i] < -slop:
            any_overlap = True
    if not any_overlap:
        return
    for it in range(iterations):
        for s in range(n):
            i = s if it % 2 == 0 else n - 1 - s
            if kn[i] <= 0.0:
                continue
            a = ca[i]
            b = cb[i]
            _rel_vel(a, b, ra[i], rb[i], dx, dth, P)
            cur = (gap_end[i] + slop
                   + P[0] * normal[i, 0] + P[1] * normal[i, 1] + P[2] * normal[i, 2])
            new = acc[i] - cur / kn[i]
            if new < 0.0:
                new = 0.0
            d = new - acc[i]
            acc[i] = new
            if d != 0.0:
                for e in range(3):
                    P[e] = d * normal[i, e]
                _apply(a, b, ra[i], rb[i], P, dx, dth, inv_mass, invI)
    dq = np.empty(4)
    for j in range(nb):
        for e in range(3):
            pos[j, e] += dx[j, e]
        ang = math.sqrt(dth[j, 0] ** 2 + dth[j, 1] ** 2 + dth[j, 2] ** 2)
        if ang > 0.0:
            s = math.sin(0.5 * ang) / ang
            dq[0] = dth[j, 0] * s
            dq[1] = dth[j, 1] * s
            dq[2] = dth[j, 2] * s
            dq[3] = math.cos(0.5 * ang)
            qn = quat_normalize(quat_multiply(dq, quats[j]))
            for k in range(4):      # element copies (see rigid._advance_serial)
                quats[j, k] = qn[k]


@njit(cache=True)
def world_inv_inertias(quats, inv_inertia):
    """R diag(inv_inertia) R^T for every body: (N, 3, 3)."""
    n = quats.shape[0]
    out = np.empty((n, 3, 3))
    for k in range(n):
        m = world_inv_inertia(quats[k], inv_inertia[k])
        for a in range(3):          # element copies (see rigid._advance_serial)
            for b in range(3):
                out[k, a, b] = m[a, b]
    return out
