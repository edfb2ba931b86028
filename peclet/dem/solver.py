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

Large contact sets (at least :data:`COLORED_MIN_CONTACTS`, a fixed count) are swept colour by
colour instead (:func:`color_contacts`: greedy in contact order, no two contacts of a colour
share a body; walls are no bodies), the contacts of one colour in parallel, the colours in
alternating order: each update then touches rows no other update of its colour touches, so the
result is that of a serial sweep in colour order, bit for bit at any thread count
(docs/architecture.md §7). Below the threshold the serial sweep in contact order is unchanged.
The colour order converges more slowly along a stack than the contact order does (contacts
sorted by body, bodies numbered up a stack, carry a correction through the whole stack in one
sweep; alternate colours carry it a contact or two per sweep): on the stirred column the
largest grain-grain overlap over 400 steps was 0.0030 against 0.0021 serially (radius 0.4),
the mean overlap and the kinetic energy the same to a few percent. The position projection of
:meth:`Simulation.relax`, which works on one state and has no later step to catch up, stays
serial at any size.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from peclet.core.geom.transforms import (multiply_xyzw, normalize_xyzw, quat_multiply,
                                         quat_normalize)
from peclet.dem.rigid import world_inv_inertia
from peclet.dem.sorting import counting_sort

#: From this many contacts a step's velocity solve and position projection sweep the contacts
#: colour by colour, each colour in parallel (:func:`solve_velocities_colored`); below it they
#: sweep serially in contact order. A count of contacts, never of threads: which path runs, and
#: so the bits, never depends on the thread count. On the stirred column (58,000 contacts, 11
#: colours) the coloured sweeps cost 1.15x the serial ones' CPU time at one thread, plus 2.6 ms
#: to colour and reorder, and run about 150 parallel regions a step: worth it where each colour
#: holds thousands of contacts per thread. The page's pour (a few thousand contacts) and the
#: 1000-ring column (at most 12,870) stay below it, with their bits.
COLORED_MIN_CONTACTS = 20000

#: A colour with fewer contacts than this is swept in the calling thread (a parallel launch
#: costs more than it saves); the contacts of a colour share no body, so either way gives the
#: same bits.
PARALLEL_COLOR_MIN = 512
#: Contacts (or bodies) per task of a parallel loop in the coloured path.
COLOR_CHUNK = 256

# bits of colour set per int64 word in color_contacts (the sign bit left alone)
_COLOR_BITS = 62
# the first contact (or body) of a serial sweep's range as an int64, not a literal 0: the
# coloured sweeps call the same range kernels with int64 starts, and a literal would compile
# each of them a second time (about 10 s of a cold test run's compilation, docs/architecture.md
# §7)
_FIRST = np.int64(0)


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


# The sweeps below run over a range of contacts with the update written in the loop itself
# (a helper function per contact, inlined or not, made the whole solve 2-3 times slower), and
# with the scratch vectors of the original serial code (tuples of scalars instead cost 30 %).

@njit(cache=True)
def _vel_setup(c0, c1, ca, cb, nrm, t1, t2, ra, rb, gap, e_n, beta, vw, v, w, inv_mass, invI,
               dt, rest_threshold, slop, kn, kt1, kt2, vmin, tt1, tt2):
    """Contacts c0..c1-1: effective masses, target normal velocity and Walton targets, from
    the velocities before the warm start."""
    vr = np.empty(3)
    for i in range(c0, c1):
        a = ca[i]
        b = cb[i]
        kn[i] = _eff_mass(a, b, ra[i], rb[i], nrm[i], inv_mass, invI)
        kt1[i] = _eff_mass(a, b, ra[i], rb[i], t1[i], inv_mass, invI)
        kt2[i] = _eff_mass(a, b, ra[i], rb[i], t2[i], inv_mass, invI)
        _rel_vel(a, b, ra[i], rb[i], v, w, vr)
        _minus_wall(vr, vw, i)
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
def _vel_sweep(c0, c1, backward, ca, cb, nrm, t1, t2, ra, rb, mu, vw, kn, kt1, kt2, vmin, tt1,
               tt2, lam, v, w, inv_mass, invI):
    """One Gauss-Seidel pass over contacts c0..c1-1 (from the last when ``backward``): each
    contact's normal impulse, then its friction inside the Coulomb cone."""
    vr = np.empty(3)
    P = np.empty(3)
    for s in range(c1 - c0):
        i = c1 - 1 - s if backward else c0 + s
        a = ca[i]
        b = cb[i]
        if kn[i] <= 0.0:
            continue
        _rel_vel(a, b, ra[i], rb[i], v, w, vr)
        _minus_wall(vr, vw, i)
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


@njit(cache=True)
def _vn_after(c0, c1, ca, cb, nrm, ra, rb, vw, v, w, out):
    """Contacts c0..c1-1: the normal relative velocity (against a moving wall's surface)."""
    vr = np.empty(3)
    for i in range(c0, c1):
        _rel_vel(ca[i], cb[i], ra[i], rb[i], v, w, vr)
        _minus_wall(vr, vw, i)
        out[i] = vr[0] * nrm[i, 0] + vr[1] * nrm[i, 1] + vr[2] * nrm[i, 2]


@njit(cache=True)
def solve_velocities(con, lam, v, w, inv_mass, invI, dt, rest_threshold, slop, iterations):
    """Projected Gauss-Seidel over the :class:`Constraints` ``con``, in place on ``v``, ``w``
    (N, 3) and the accumulated impulses ``lam`` (n, 3) = (lambda_n, lambda_t1, lambda_t2),
    which enter as the warm start. ``inv_mass`` (N,), ``invI`` (N, 3, 3) world inverse inertia.
    Returns the normal relative velocity of every contact after the solve (n,). Serial, in
    contact order (forward, then backward, alternately)."""
    ca, cb, nrm, t1, t2, ra, rb = con.a, con.b, con.normal, con.t1, con.t2, con.ra, con.rb
    gap, e_n, beta, mu, vw = con.gap, con.e, con.beta, con.mu, con.vw
    n = ca.shape[0]
    kn = np.empty(n)
    kt1 = np.empty(n)
    kt2 = np.empty(n)
    vmin = np.empty(n)
    tt1 = np.empty(n)
    tt2 = np.empty(n)
    _vel_setup(_FIRST, n, ca, cb, nrm, t1, t2, ra, rb, gap, e_n, beta, vw, v, w, inv_mass,
               invI, dt, rest_threshold, slop, kn, kt1, kt2, vmin, tt1, tt2)
    # warm start
    P = np.empty(3)
    for i in range(n):
        if lam[i, 0] != 0.0 or lam[i, 1] != 0.0 or lam[i, 2] != 0.0:
            for e in range(3):
                P[e] = lam[i, 0] * nrm[i, e] + lam[i, 1] * t1[i, e] + lam[i, 2] * t2[i, e]
            _apply(ca[i], cb[i], ra[i], rb[i], P, v, w, inv_mass, invI)
    for it in range(iterations):
        _vel_sweep(_FIRST, n, it % 2 == 1, ca, cb, nrm, t1, t2, ra, rb, mu, vw, kn, kt1, kt2,
                   vmin, tt1, tt2, lam, v, w, inv_mass, invI)
    vn_out = np.empty(n)
    _vn_after(_FIRST, n, ca, cb, nrm, ra, rb, vw, v, w, vn_out)
    return vn_out


@njit(cache=True)
def _warm_bodies(j0, j1, body_start, body_items, ca, nrm, t1, t2, ra, rb, lam, v, w, inv_mass,
                 invI):
    """The warm start of bodies j0..j1-1, body by body: each body's share of its contacts'
    impulses (``body_items[body_start[j]:body_start[j + 1]]``, ascending), added in that
    order with the arithmetic of the serial warm start on that body's rows."""
    for j in range(j0, j1):
        for k in range(body_start[j], body_start[j + 1]):
            u = body_items[k]
            if lam[u, 0] != 0.0 or lam[u, 1] != 0.0 or lam[u, 2] != 0.0:
                P0 = lam[u, 0] * nrm[u, 0] + lam[u, 1] * t1[u, 0] + lam[u, 2] * t2[u, 0]
                P1 = lam[u, 0] * nrm[u, 1] + lam[u, 1] * t1[u, 1] + lam[u, 2] * t2[u, 1]
                P2 = lam[u, 0] * nrm[u, 2] + lam[u, 1] * t1[u, 2] + lam[u, 2] * t2[u, 2]
                if ca[u] == j:
                    c0, c1, c2 = _cross(ra[u, 0], ra[u, 1], ra[u, 2], P0, P1, P2)
                    v[j, 0] += inv_mass[j] * P0
                    v[j, 1] += inv_mass[j] * P1
                    v[j, 2] += inv_mass[j] * P2
                    for e in range(3):
                        w[j, e] += invI[j, e, 0] * c0 + invI[j, e, 1] * c1 + invI[j, e, 2] * c2
                else:
                    c0, c1, c2 = _cross(rb[u, 0], rb[u, 1], rb[u, 2], P0, P1, P2)
                    v[j, 0] -= inv_mass[j] * P0
                    v[j, 1] -= inv_mass[j] * P1
                    v[j, 2] -= inv_mass[j] * P2
                    for e in range(3):
                        w[j, e] -= invI[j, e, 0] * c0 + invI[j, e, 1] * c1 + invI[j, e, 2] * c2


@njit(cache=True, parallel=True)
def solve_velocities_colored(con, lam, v, w, inv_mass, invI, dt, rest_threshold, slop,
                             iterations, start, body_start, body_items):
    """:func:`solve_velocities` on contacts given colour by colour (:func:`color_contacts`,
    :class:`Colored`: colour k is the contacts ``start[k]`` to ``start[k + 1]``), sweeping
    the colours 0, 1, ... on even iterations and in reverse on odd ones, the contacts of one
    colour in parallel (chunks of ``COLOR_CHUNK``). No two contacts of a colour share a body,
    so each update reads and writes rows no other update of its colour touches; the warm
    start is applied body by body (``body_items[body_start[j]:body_start[j + 1]]``: body j's
    contacts in ascending order), each body's impulses added in contact order. The result is
    that of :func:`solve_velocities` on the same contact list, bit for bit, at any thread
    count."""
    ca, cb, nrm, t1, t2, ra, rb = con.a, con.b, con.normal, con.t1, con.t2, con.ra, con.rb
    gap, e_n, beta, mu, vw = con.gap, con.e, con.beta, con.mu, con.vw
    n = ca.shape[0]
    nb = v.shape[0]
    ncol = start.shape[0] - 1
    kn = np.empty(n)
    kt1 = np.empty(n)
    kt2 = np.empty(n)
    vmin = np.empty(n)
    tt1 = np.empty(n)
    tt2 = np.empty(n)
    for ch in prange((n + COLOR_CHUNK - 1) // COLOR_CHUNK):
        _vel_setup(ch * COLOR_CHUNK, min(n, (ch + 1) * COLOR_CHUNK), ca, cb, nrm, t1, t2, ra,
                   rb, gap, e_n, beta, vw, v, w, inv_mass, invI, dt, rest_threshold, slop, kn,
                   kt1, kt2, vmin, tt1, tt2)
    for ch in prange((nb + COLOR_CHUNK - 1) // COLOR_CHUNK):
        _warm_bodies(ch * COLOR_CHUNK, min(nb, (ch + 1) * COLOR_CHUNK), body_start, body_items,
                     ca, nrm, t1, t2, ra, rb, lam, v, w, inv_mass, invI)
    for it in range(iterations):
        back = it % 2 == 1
        for kk in range(ncol):
            k = ncol - 1 - kk if back else kk
            c0 = start[k]
            c1 = start[k + 1]
            if c1 - c0 < PARALLEL_COLOR_MIN:
                _vel_sweep(c0, c1, back, ca, cb, nrm, t1, t2, ra, rb, mu, vw, kn, kt1, kt2,
                           vmin, tt1, tt2, lam, v, w, inv_mass, invI)
            else:
                for ch in prange((c1 - c0 + COLOR_CHUNK - 1) // COLOR_CHUNK):
                    _vel_sweep(c0 + ch * COLOR_CHUNK, min(c1, c0 + (ch + 1) * COLOR_CHUNK),
                               back, ca, cb, nrm, t1, t2, ra, rb, mu, vw, kn, kt1, kt2, vmin,
                               tt1, tt2, lam, v, w, inv_mass, invI)
    vn_out = np.empty(n)
    for ch in prange((n + COLOR_CHUNK - 1) // COLOR_CHUNK):
        _vn_after(ch * COLOR_CHUNK, min(n, (ch + 1) * COLOR_CHUNK), ca, cb, nrm, ra, rb, vw, v,
                  w, vn_out)
    return vn_out


@njit(cache=True)
def _pos_sweep(c0, c1, backward, ca, cb, nrm, ra, rb, gap_end, slop, kn, acc, dx, dth,
               inv_mass, invI):
    """One non-linear Gauss-Seidel pass of the position corrections over contacts c0..c1-1
    (from the last when ``backward``)."""
    P = np.empty(3)
    for s in range(c1 - c0):
        i = c1 - 1 - s if backward else c0 + s
        if kn[i] <= 0.0:
            continue
        a = ca[i]
        b = cb[i]
        _rel_vel(a, b, ra[i], rb[i], dx, dth, P)
        cur = (gap_end[i] + slop
               + P[0] * nrm[i, 0] + P[1] * nrm[i, 1] + P[2] * nrm[i, 2])
        new = acc[i] - cur / kn[i]
        if new < 0.0:
            new = 0.0
        d = new - acc[i]
        acc[i] = new
        if d != 0.0:
            for e in range(3):
                P[e] = d * nrm[i, e]
            _apply(a, b, ra[i], rb[i], P, dx, dth, inv_mass, invI)


@njit(cache=True)
def _move_bodies(j0, j1, dx, dth, pos, quats):
    """Bodies j0..j1-1 moved by their accumulated corrections: ``pos += dx``, ``quats`` turned
    by the rotation vector ``dth`` and normalised (quat_normalize(quat_multiply(dq, q)) on
    scalars, the same bits). Returns the first body whose turned quaternion cannot be
    normalised (its quaternion left as it was; the caller raises as quat_normalize does),
    else -1."""
    for j in range(j0, j1):
        for e in range(3):
            pos[j, e] += dx[j, e]
        ang = math.sqrt(dth[j, 0] ** 2 + dth[j, 1] ** 2 + dth[j, 2] ** 2)
        if ang > 0.0:
            s = math.sin(0.5 * ang) / ang
            x, y, z, ww = multiply_xyzw(dth[j, 0] * s, dth[j, 1] * s, dth[j, 2] * s,
                                        math.cos(0.5 * ang), quats[j, 0], quats[j, 1],
                                        quats[j, 2], quats[j, 3])
            x, y, z, ww, ok = normalize_xyzw(x, y, z, ww)
            if not ok:
                return j
            quats[j, 0] = x
            quats[j, 1] = y
            quats[j, 2] = z
            quats[j, 3] = ww
    return -1


@njit(cache=True)
def _raise_bad_turn(j, dth, quats):
    # quat_normalize's own error for the body whose turned quaternion is not finite
    ang = math.sqrt(dth[j, 0] ** 2 + dth[j, 1] ** 2 + dth[j, 2] ** 2)
    s = math.sin(0.5 * ang) / ang
    dq = np.empty(4)
    dq[0] = dth[j, 0] * s
    dq[1] = dth[j, 1] * s
    dq[2] = dth[j, 2] * s
    dq[3] = math.cos(0.5 * ang)
    quat_normalize(quat_multiply(dq, quats[j]))


@njit(cache=True)
def _pos_setup(ca, cb, nrm, ra, rb, gap_end, inv_mass, invI, slop, kn):
    # kn for every contact; whether any predicted gap is below -slop
    return _pos_setup_range(_FIRST, ca.shape[0], ca, cb, nrm, ra, rb, gap_end, inv_mass, invI,
                            slop, kn)


@njit(cache=True)
def _pos_setup_range(c0, c1, ca, cb, nrm, ra, rb, gap_end, inv_mass, invI, slop, kn):
    # _pos_setup for contacts c0..c1-1
    any_overlap = False
    for i in range(c0, c1):
        kn[i] = _eff_mass(ca[i], cb[i], ra[i], rb[i], nrm[i], inv_mass, invI)
        if gap_end[i] < -slop:
            any_overlap = True
    return any_overlap


@njit(cache=True)
def project_positions(con, gap_end, inv_mass, invI, slop, iterations, pos, quats):
    """Remove the predicted end-of-step overlaps ``gap_end < 0`` of the :class:`Constraints`
    ``con`` by moving and rotating the bodies (in place on ``pos`` (N, 3) and ``quats``
    (N, 4)); velocities are not touched. Serial, in contact order (alternating)."""
    ca, cb, nrm, ra, rb = con.a, con.b, con.normal, con.ra, con.rb
    n = ca.shape[0]
    nb = pos.shape[0]
    kn = np.empty(n)
    if not _pos_setup(ca, cb, nrm, ra, rb, gap_end, inv_mass, invI, slop, kn):
        return
    dx = np.zeros((nb, 3))
    dth = np.zeros((nb, 3))
    acc = np.zeros(n)
    for it in range(iterations):
        _pos_sweep(_FIRST, n, it % 2 == 1, ca, cb, nrm, ra, rb, gap_end, slop, kn, acc, dx,
                   dth, inv_mass, invI)
    bad = _move_bodies(_FIRST, nb, dx, dth, pos, quats)
    if bad >= 0:
        _raise_bad_turn(bad, dth, quats)


@njit(cache=True, parallel=True)
def project_positions_colored(con, gap_end, inv_mass, invI, slop, iterations, pos, quats,
                              start):
    """:func:`project_positions` on contacts given colour by colour, swept as
    :func:`solve_velocities_colored` sweeps them (each colour in parallel, the colours in
    alternating order): the bits of the serial projection of that contact list, at any
    thread count."""
    ca, cb, nrm, ra, rb = con.a, con.b, con.normal, con.ra, con.rb
    n = ca.shape[0]
    nb = pos.shape[0]
    ncol = start.shape[0] - 1
    kn = np.empty(n)
    nch = (n + COLOR_CHUNK - 1) // COLOR_CHUNK
    over = np.empty(nch, np.bool_)
    for ch in prange(nch):
        over[ch] = _pos_setup_range(ch * COLOR_CHUNK, min(n, (ch + 1) * COLOR_CHUNK), ca, cb,
                                    nrm, ra, rb, gap_end, inv_mass, invI, slop, kn)
    if not over.any():
        return
    dx = np.zeros((nb, 3))
    dth = np.zeros((nb, 3))
    acc = np.zeros(n)
    for it in range(iterations):
        back = it % 2 == 1
        for kk in range(ncol):
            k = ncol - 1 - kk if back else kk
            c0 = start[k]
            c1 = start[k + 1]
            if c1 - c0 < PARALLEL_COLOR_MIN:
                _pos_sweep(c0, c1, back, ca, cb, nrm, ra, rb, gap_end, slop, kn, acc, dx, dth,
                           inv_mass, invI)
            else:
                for ch in prange((c1 - c0 + COLOR_CHUNK - 1) // COLOR_CHUNK):
                    _pos_sweep(c0 + ch * COLOR_CHUNK, min(c1, c0 + (ch + 1) * COLOR_CHUNK),
                               back, ca, cb, nrm, ra, rb, gap_end, slop, kn, acc, dx, dth,
                               inv_mass, invI)
    nch = (nb + COLOR_CHUNK - 1) // COLOR_CHUNK
    bad = np.empty(nch, np.int64)
    for ch in prange(nch):
        bad[ch] = _move_bodies(ch * COLOR_CHUNK, min(nb, (ch + 1) * COLOR_CHUNK), dx, dth, pos,
                               quats)
    for ch in range(nch):
        if bad[ch] >= 0:
            _raise_bad_turn(bad[ch], dth, quats)


@njit(cache=True)
def color_contacts(ca, cb, n_bodies):
    """A colouring of the contacts (a[i], b[i]) (b < 0: a wall, which is no body) such that no
    two contacts of one colour share a body: greedy in contact order, each contact taking the
    lowest colour free at both its bodies (deterministic: a function of the contact list
    alone). Returns (order (n,), start (K + 1,), body_start (N + 1,), body_items): the
    contacts colour by colour, in contact order within a colour (colour k at
    ``order[start[k]:start[k + 1]]``), and for each body j the positions u in ``order`` of
    its contacts, ascending, at ``body_items[body_start[j]:body_start[j + 1]]``."""
    n = ca.shape[0]
    body_start = np.zeros(n_bodies + 1, np.int64)
    for i in range(n):
        body_start[ca[i] + 1] += 1
        if cb[i] >= 0:
            body_start[cb[i] + 1] += 1
    maxdeg = 0
    for j in range(n_bodies):
        maxdeg = max(maxdeg, body_start[j + 1])
        body_start[j + 1] += body_start[j]
    # a contact meets at most deg(a) - 1 + deg(b) - 1 coloured neighbours: 2 maxdeg colours
    # always suffice. Colour sets as bit words of _COLOR_BITS bits (int64, sign bit unused).
    words = (2 * maxdeg) // _COLOR_BITS + 1
    full = (np.int64(1) << _COLOR_BITS) - 1
    used = np.zeros((n_bodies, words), np.int64)
    color = np.empty(n, np.int64)
    ncol = np.int64(0)
    for i in range(n):
        a = ca[i]
        b = cb[i]
        c = -1
        for k in range(words):
            m = used[a, k]
            if b >= 0:
                m |= used[b, k]
            free = ~m & full
            if free != 0:
                bit = 0
                while (free >> bit) & 1 == 0:
                    bit += 1
                c = k * _COLOR_BITS + bit
                break
        color[i] = c
        k = c // _COLOR_BITS
        f = np.int64(1) << (c % _COLOR_BITS)
        used[a, k] |= f
        if b >= 0:
            used[b, k] |= f
        ncol = max(ncol, c + 1)
    start, order = counting_sort(color, ncol)
    body_fill = body_start[:-1].copy()
    body_items = np.empty(body_start[n_bodies], np.int64)
    for u in range(n):
        i = order[u]
        body_items[body_fill[ca[i]]] = u
        body_fill[ca[i]] += 1
        if cb[i] >= 0:
            body_items[body_fill[cb[i]]] = u
            body_fill[cb[i]] += 1
    return order, start, body_start, body_items


class Colored(NamedTuple):
    """A colouring of a contact list (:func:`color_contacts`): ``order`` (n,) the contacts
    colour by colour, ``start`` (K + 1,) each colour's first position in it, and for each body
    j its positions in ``order``, ascending, at ``body_items[body_start[j]:body_start[j +
    1]]``. The coloured solvers take the contacts rearranged into ``order``
    (:func:`peclet.dem.contacts.reorder`), so that a colour's contacts are contiguous."""
    order: np.ndarray
    start: np.ndarray
    body_start: np.ndarray
    body_items: np.ndarray


def colors_for(a, b, n_bodies, threshold=None):
    """The :class:`Colored` colouring of the contacts (``a``, ``b``) (b < 0: a wall) when
    there are at least ``threshold`` (default :data:`COLORED_MIN_CONTACTS`) of them, else None
    (the serial path). The choice depends on the contact count alone, never on the thread
    count."""
    lim = COLORED_MIN_CONTACTS if threshold is None else threshold
    if len(a) < lim:
        return None
    return Colored(*color_contacts(a, b, np.int64(n_bodies)))


def solve(con, lam, v, w, inv_mass, invI, dt, rest_threshold, slop, iterations, colors=None):
    """The velocity solve: :func:`solve_velocities` (serial, in contact order) when
    ``colors`` is None, else :func:`solve_velocities_colored`, ``con`` and ``lam`` then in
    the colour order of ``colors`` (:func:`colors_for`)."""
    if colors is None:
        return solve_velocities(con, lam, v, w, inv_mass, invI, dt, rest_threshold, slop,
                                iterations)
    return solve_velocities_colored(con, lam, v, w, inv_mass, invI, dt, rest_threshold, slop,
                                    iterations, colors.start, colors.body_start,
                                    colors.body_items)


def project(con, gap_end, inv_mass, invI, slop, iterations, pos, quats, colors=None):
    """The position projection: :func:`project_positions` when ``colors`` is None, else
    :func:`project_positions_colored` (``con`` and ``gap_end`` in colour order, see
    :func:`solve`)."""
    if colors is None:
        project_positions(con, gap_end, inv_mass, invI, slop, iterations, pos, quats)
    else:
        project_positions_colored(con, gap_end, inv_mass, invI, slop, iterations, pos, quats,
                                  colors.start)


@njit(cache=True)
def world_inv_inertias(quats, inv_inertia):
    """R diag(inv_inertia) R^T for every body: (N, 3, 3)."""
    n = quats.shape[0]
    out = np.empty((n, 3, 3))
    _world_inv_range(_FIRST, n, quats, inv_inertia, out)
    return out


@njit(cache=True, parallel=True)
def world_inv_inertias_parallel(quats, inv_inertia):
    """:func:`world_inv_inertias` over chunks of bodies in parallel (each body's rows written
    by itself: the same bits)."""
    n = quats.shape[0]
    out = np.empty((n, 3, 3))
    for ch in prange((n + COLOR_CHUNK - 1) // COLOR_CHUNK):
        _world_inv_range(ch * COLOR_CHUNK, min(n, (ch + 1) * COLOR_CHUNK), quats, inv_inertia,
                         out)
    return out


@njit(cache=True)
def _world_inv_range(k0, k1, quats, inv_inertia, out):
    for k in range(k0, k1):
        m = world_inv_inertia(quats[k], inv_inertia[k])
        for a in range(3):          # element copies (see rigid._advance_serial)
            for b in range(3):
                out[k, a, b] = m[a, b]
