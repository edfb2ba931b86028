"""The velocity solve of :mod:`peclet.dem.solver`: projected Gauss-Seidel on the contacts'
accumulated impulses (the conditions, restitution and friction are in that module's docstring),
and the range kernels the coloured solve (:mod:`peclet.dem.solver_colored`) runs in parallel.

The sweeps run over a range of contacts with the update written in the loop itself (a helper
function per contact, inlined or not, made the whole solve 2-3 times slower), and with the
scratch vectors of the original serial code (tuples of scalars instead cost 30 %).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from peclet.dem.solver_rows import FIRST, Rows, apply_impulse, cross, eff_mass, minus_wall, rel_vel


class VelState(NamedTuple):
    """Per contact, what the velocity sweeps read and write beside the
    :class:`~peclet.dem.solver.Constraints`: set once a solve from the velocities before the
    warm start, the inverse effective masses ``kn``, ``kt1``, ``kt2`` (n,) along the normal
    and the two tangents (a contact with ``kn <= 0`` joins nothing that moves and is
    skipped), ``vmin`` (n,) the least normal relative velocity allowed (speculative, resting
    or restitution bound), ``tt1``, ``tt2`` (n,) the tangential relative velocities friction
    drives toward (Walton's ``-beta v_t^-`` for a colliding contact, else 0); and the
    accumulated impulses ``lam`` (n, 3) = (lambda_n, lambda_t1, lambda_t2) along (normal, t1,
    t2), in and out.

    Built in the kernel with its class (not by a helper): a parallel loop that reads a named
    tuple rebuilds it from the class of its definition."""
    kn: np.ndarray
    kt1: np.ndarray
    kt2: np.ndarray
    vmin: np.ndarray
    tt1: np.ndarray
    tt2: np.ndarray
    lam: np.ndarray


@njit(cache=True)
def vel_setup(c0, c1, con, body, dt, rest_threshold, slop, st):
    """Contacts c0..c1-1: the targets of the :class:`VelState` ``st`` (effective masses,
    target normal velocity and Walton targets), from the velocities of the :class:`Rows`
    ``body`` before the warm start."""
    ca, cb, nrm, t1, t2, ra, rb = con.a, con.b, con.normal, con.t1, con.t2, con.ra, con.rb
    gap, e_n, beta, vw = con.gap, con.e, con.beta, con.vw
    v, w, inv_mass, invI = body
    kn, kt1, kt2, vmin, tt1, tt2 = st.kn, st.kt1, st.kt2, st.vmin, st.tt1, st.tt2
    vr = np.empty(3)
    for i in range(c0, c1):
        a = ca[i]
        b = cb[i]
        kn[i] = eff_mass(a, b, ra[i], rb[i], nrm[i], inv_mass, invI)
        kt1[i] = eff_mass(a, b, ra[i], rb[i], t1[i], inv_mass, invI)
        kt2[i] = eff_mass(a, b, ra[i], rb[i], t2[i], inv_mass, invI)
        rel_vel(a, b, ra[i], rb[i], v, w, vr)
        minus_wall(vr, vw, i)
        vn = vr[0] * nrm[i, 0] + vr[1] * nrm[i, 1] + vr[2] * nrm[i, 2]
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


@njit(cache=True)
def vel_sweep(c0, c1, backward, con, st, body):
    """One Gauss-Seidel pass over contacts c0..c1-1 of ``con`` (from the last when
    ``backward``), on the :class:`VelState` ``st`` and the velocities of the :class:`Rows`
    ``body``: each contact's normal impulse, then its friction inside the Coulomb cone."""
    ca, cb, nrm, t1, t2, ra, rb = con.a, con.b, con.normal, con.t1, con.t2, con.ra, con.rb
    mu, vw = con.mu, con.vw
    kn, kt1, kt2, vmin, tt1, tt2, lam = st
    v, w, inv_mass, invI = body
    vr = np.empty(3)
    P = np.empty(3)
    for s in range(c1 - c0):
        i = c1 - 1 - s if backward else c0 + s
        a = ca[i]
        b = cb[i]
        if kn[i] <= 0.0:
            continue
        rel_vel(a, b, ra[i], rb[i], v, w, vr)
        minus_wall(vr, vw, i)
        vn = vr[0] * nrm[i, 0] + vr[1] * nrm[i, 1] + vr[2] * nrm[i, 2]
        old = lam[i, 0]
        new = old + (vmin[i] - vn) / kn[i]
        if new < 0.0:
            new = 0.0
        dl = new - old
        lam[i, 0] = new
        if dl != 0.0:
            for e in range(3):
                P[e] = dl * nrm[i, e]
            apply_impulse(a, b, ra[i], rb[i], P, v, w, inv_mass, invI)
        # friction: both tangents, then the cone
        rel_vel(a, b, ra[i], rb[i], v, w, vr)
        minus_wall(vr, vw, i)
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
            apply_impulse(a, b, ra[i], rb[i], P, v, w, inv_mass, invI)


@njit(cache=True)
def vn_after(c0, c1, con, v, w, out):
    """Contacts c0..c1-1: the normal relative velocity (against a moving wall's surface)."""
    ca, cb, nrm, ra, rb, vw = con.a, con.b, con.normal, con.ra, con.rb, con.vw
    vr = np.empty(3)
    for i in range(c0, c1):
        rel_vel(ca[i], cb[i], ra[i], rb[i], v, w, vr)
        minus_wall(vr, vw, i)
        out[i] = vr[0] * nrm[i, 0] + vr[1] * nrm[i, 1] + vr[2] * nrm[i, 2]


@njit(cache=True)
def solve_velocities(con, lam, v, w, inv_mass, invI, dt, rest_threshold, slop, iterations):
    """Projected Gauss-Seidel over the :class:`~peclet.dem.solver.Constraints` ``con``, in
    place on ``v``, ``w`` (N, 3) and the accumulated impulses ``lam`` (n, 3) = (lambda_n,
    lambda_t1, lambda_t2), which enter as the warm start. ``inv_mass`` (N,), ``invI``
    (N, 3, 3) world inverse inertia. Returns the normal relative velocity of every contact
    after the solve (n,). Serial, in contact order (forward, then backward, alternately)."""
    ca, cb, nrm, t1, t2, ra, rb = con.a, con.b, con.normal, con.t1, con.t2, con.ra, con.rb
    n = ca.shape[0]
    body = Rows(v, w, inv_mass, invI)
    st = VelState(np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n),
                  lam)
    vel_setup(FIRST, n, con, body, dt, rest_threshold, slop, st)
    # warm start
    P = np.empty(3)
    for i in range(n):
        if lam[i, 0] != 0.0 or lam[i, 1] != 0.0 or lam[i, 2] != 0.0:
            for e in range(3):
                P[e] = lam[i, 0] * nrm[i, e] + lam[i, 1] * t1[i, e] + lam[i, 2] * t2[i, e]
            apply_impulse(ca[i], cb[i], ra[i], rb[i], P, v, w, inv_mass, invI)
    for it in range(iterations):
        vel_sweep(FIRST, n, it % 2 == 1, con, st, body)
    vn_out = np.empty(n)
    vn_after(FIRST, n, con, v, w, vn_out)
    return vn_out


@njit(cache=True)
def warm_bodies(j0, j1, body_start, body_items, con, lam, body):
    """The warm start of bodies j0..j1-1, body by body: each body's share of its contacts'
    impulses (``body_items[body_start[j]:body_start[j + 1]]``, ascending), added in that
    order with the arithmetic of the serial warm start on that body's rows of ``body``."""
    ca, nrm, t1, t2, ra, rb = con.a, con.normal, con.t1, con.t2, con.ra, con.rb
    v, w, inv_mass, invI = body
    for j in range(j0, j1):
        for k in range(body_start[j], body_start[j + 1]):
            u = body_items[k]
            if lam[u, 0] != 0.0 or lam[u, 1] != 0.0 or lam[u, 2] != 0.0:
                P0 = lam[u, 0] * nrm[u, 0] + lam[u, 1] * t1[u, 0] + lam[u, 2] * t2[u, 0]
                P1 = lam[u, 0] * nrm[u, 1] + lam[u, 1] * t1[u, 1] + lam[u, 2] * t2[u, 1]
                P2 = lam[u, 0] * nrm[u, 2] + lam[u, 1] * t1[u, 2] + lam[u, 2] * t2[u, 2]
                if ca[u] == j:
                    c0, c1, c2 = cross(ra[u, 0], ra[u, 1], ra[u, 2], P0, P1, P2)
                    v[j, 0] += inv_mass[j] * P0
                    v[j, 1] += inv_mass[j] * P1
                    v[j, 2] += inv_mass[j] * P2
                    for e in range(3):
                        w[j, e] += invI[j, e, 0] * c0 + invI[j, e, 1] * c1 + invI[j, e, 2] * c2
                else:
                    c0, c1, c2 = cross(rb[u, 0], rb[u, 1], rb[u, 2], P0, P1, P2)
                    v[j, 0] -= inv_mass[j] * P0
                    v[j, 1] -= inv_mass[j] * P1
                    v[j, 2] -= inv_mass[j] * P2
                    for e in range(3):
                        w[j, e] -= invI[j, e, 0] * c0 + invI[j, e, 1] * c1 + invI[j, e, 2] * c2
