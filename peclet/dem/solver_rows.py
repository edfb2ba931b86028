"""The pieces every contact sweep of :mod:`peclet.dem.solver` is made of: the bundles
:class:`Constraints` (the contacts, as every solver takes them) and :class:`Rows` (what an
impulse moves), the per-contact terms (effective mass, relative velocity, an impulse applied to
both bodies), the tangent basis, the bodies' world inverse inertias, and the chunking of the
coloured path's parallel loops.

Conventions (module docstring of :mod:`peclet.dem.solver`): a contact joins body ``a`` and body
``b`` (``b < 0`` a wall, which is no body and is not moved), its normal points from b to a,
``ra``/``rb`` are the contact point relative to each body's centre of mass; an impulse ``P``
acts on a along +P, on b along -P.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from peclet.dem.rigid import world_inv_inertia

#: A colour with fewer contacts than this is swept in the calling thread (a parallel launch
#: costs more than it saves); the contacts of a colour share no body, so either way gives the
#: same bits.
PARALLEL_COLOR_MIN = 512
#: Contacts (or bodies) per task of a parallel loop in the coloured path.
COLOR_CHUNK = 256

#: The first contact (or body) of a serial sweep's range as an int64, not a literal 0: the
#: coloured sweeps call the same range kernels with int64 starts, and a literal would compile
#: each of them a second time (about 10 s of a cold test run's compilation,
#: docs/architecture.md §7).
FIRST = np.int64(0)


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


class Rows(NamedTuple):
    """What a contact impulse moves, per body: ``lin`` and ``ang`` (N, 3) (in and out: the
    velocities v and omega, world frame, in the velocity solve; the accumulated displacement
    and rotation vector in the position projection), ``inv_mass`` (N,) and ``invI`` (N, 3, 3)
    the world-frame inverse inertia (0 for a fixed body)."""
    lin: np.ndarray
    ang: np.ndarray
    inv_mass: np.ndarray
    invI: np.ndarray


@njit(cache=True, inline="always")
def cross(a0, a1, a2, b0, b1, b2):
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True, inline="always")
def ang_term(I, r, d):
    """(r x d) . I (r x d)."""
    c0, c1, c2 = cross(r[0], r[1], r[2], d[0], d[1], d[2])
    u0 = I[0, 0] * c0 + I[0, 1] * c1 + I[0, 2] * c2
    u1 = I[1, 0] * c0 + I[1, 1] * c1 + I[1, 2] * c2
    u2 = I[2, 0] * c0 + I[2, 1] * c1 + I[2, 2] * c2
    return c0 * u0 + c1 * u1 + c2 * u2


@njit(cache=True, inline="always")
def eff_mass(a, b, ra, rb, d, inv_mass, invI):
    """d . M^-1 d of the contact along the unit direction ``d``: the inverse effective mass
    (b's share only when b is a body)."""
    k = inv_mass[a] + ang_term(invI[a], ra, d)
    if b >= 0:
        k += inv_mass[b] + ang_term(invI[b], rb, d)
    return k


@njit(cache=True, inline="always")
def rel_vel(a, b, ra, rb, v, w, out):
    """out = (v_a + w_a x ra) - (v_b + w_b x rb), the second term only when b is a body."""
    c0, c1, c2 = cross(w[a, 0], w[a, 1], w[a, 2], ra[0], ra[1], ra[2])
    out[0] = v[a, 0] + c0
    out[1] = v[a, 1] + c1
    out[2] = v[a, 2] + c2
    if b >= 0:
        c0, c1, c2 = cross(w[b, 0], w[b, 1], w[b, 2], rb[0], rb[1], rb[2])
        out[0] -= v[b, 0] + c0
        out[1] -= v[b, 1] + c1
        out[2] -= v[b, 2] + c2


@njit(cache=True, inline="always")
def minus_wall(vr, vw, i):
    """The relative velocity against a moving wall's surface: vr -= vw[i] (exactly vr for a
    static wall, vw = 0)."""
    vr[0] -= vw[i, 0]
    vr[1] -= vw[i, 1]
    vr[2] -= vw[i, 2]


@njit(cache=True, inline="always")
def apply_impulse(a, b, ra, rb, P, lin, ang, inv_mass, invI):
    """lin[a] += m_a^-1 P, ang[a] += I_a^-1 (ra x P); the opposite on b."""
    c0, c1, c2 = cross(ra[0], ra[1], ra[2], P[0], P[1], P[2])
    for e in range(3):
        lin[a, e] += inv_mass[a] * P[e]
        ang[a, e] += invI[a, e, 0] * c0 + invI[a, e, 1] * c1 + invI[a, e, 2] * c2
    if b >= 0:
        c0, c1, c2 = cross(rb[0], rb[1], rb[2], P[0], P[1], P[2])
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
        b0, b1, b2 = cross(nx, ny, nz, t1[i, 0], t1[i, 1], t1[i, 2])
        t2[i, 0] = b0
        t2[i, 1] = b1
        t2[i, 2] = b2
    return t1, t2


@njit(cache=True)
def world_inv_inertias(quats, inv_inertia):
    """R diag(inv_inertia) R^T for every body: (N, 3, 3)."""
    n = quats.shape[0]
    out = np.empty((n, 3, 3))
    _world_inv_range(FIRST, n, quats, inv_inertia, out)
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
