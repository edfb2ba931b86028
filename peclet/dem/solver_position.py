"""The position projection of :mod:`peclet.dem.solver`: non-linear Gauss-Seidel on the predicted
end-of-step gaps with accumulated, non-negative corrections that move and rotate both bodies
(never their velocities), and the range kernels the coloured projection
(:mod:`peclet.dem.solver_colored`) runs in parallel.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from peclet.core.geom.transforms import (multiply_xyzw, normalize_xyzw, quat_multiply,
                                         quat_normalize)
from peclet.dem.solver_rows import FIRST, Rows, apply_impulse, eff_mass, rel_vel


class PosState(NamedTuple):
    """Per contact, what the projection sweeps read and write beside the
    :class:`~peclet.dem.solver.Constraints`: the predicted end-of-step gaps ``gap_end`` (n,)
    (< 0: an overlap), the inverse effective masses ``kn`` (n,) along the normal (``kn <= 0``:
    skipped), the accumulated corrections ``acc`` (n,) (>= 0, in and out), and the ``slop``
    (a length) the corrections leave in each overlap."""
    gap_end: np.ndarray
    kn: np.ndarray
    acc: np.ndarray
    slop: float


@njit(cache=True)
def pos_sweep(c0, c1, backward, con, st, body):
    """One non-linear Gauss-Seidel pass of the position corrections over contacts c0..c1-1 of
    ``con`` (from the last when ``backward``), on the :class:`PosState` ``st`` and the
    accumulated displacements and rotation vectors of the :class:`Rows` ``body``."""
    gap_end, kn, acc, slop = st
    ca, cb, nrm, ra, rb = con.a, con.b, con.normal, con.ra, con.rb
    dx, dth, inv_mass, invI = body
    P = np.empty(3)
    for s in range(c1 - c0):
        i = c1 - 1 - s if backward else c0 + s
        if kn[i] <= 0.0:
            continue
        a = ca[i]
        b = cb[i]
        rel_vel(a, b, ra[i], rb[i], dx, dth, P)
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
            apply_impulse(a, b, ra[i], rb[i], P, dx, dth, inv_mass, invI)


@njit(cache=True)
def move_bodies(j0, j1, dx, dth, pos, quats):
    """Bodies j0..j1-1 moved by their accumulated corrections: ``pos += dx``, ``quats`` turned
    by the rotation vector ``dth`` and normalised (quat_normalize(quat_multiply(dq, q)) on
    scalars, the same bits). Returns the first body whose turned quaternion cannot be
    normalised (its quaternion left as it was; the caller raises as quat_normalize does, with
    :func:`raise_bad_turn`), else -1."""
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
def raise_bad_turn(j, dth, quats):
    """quat_normalize's own error for body ``j``, whose turned quaternion is not finite."""
    ang = math.sqrt(dth[j, 0] ** 2 + dth[j, 1] ** 2 + dth[j, 2] ** 2)
    s = math.sin(0.5 * ang) / ang
    dq = np.empty(4)
    dq[0] = dth[j, 0] * s
    dq[1] = dth[j, 1] * s
    dq[2] = dth[j, 2] * s
    dq[3] = math.cos(0.5 * ang)
    quat_normalize(quat_multiply(dq, quats[j]))


@njit(cache=True)
def _pos_setup(con, gap_end, inv_mass, invI, slop, kn):
    # kn for every contact; whether any predicted gap is below -slop
    return pos_setup_range(FIRST, con.a.shape[0], con, gap_end, inv_mass, invI, slop, kn)


@njit(cache=True)
def pos_setup_range(c0, c1, con, gap_end, inv_mass, invI, slop, kn):
    """Contacts c0..c1-1: ``kn`` along the normal; returns whether any predicted gap
    ``gap_end`` is below ``-slop``."""
    ca, cb, nrm, ra, rb = con.a, con.b, con.normal, con.ra, con.rb
    any_overlap = False
    for i in range(c0, c1):
        kn[i] = eff_mass(ca[i], cb[i], ra[i], rb[i], nrm[i], inv_mass, invI)
        if gap_end[i] < -slop:
            any_overlap = True
    return any_overlap


@njit(cache=True)
def corrections(n, nb):
    """Zero accumulated corrections for ``n`` contacts and ``nb`` bodies: (dx, dth) (nb, 3),
    acc (n,)."""
    return np.zeros((nb, 3)), np.zeros((nb, 3)), np.zeros(n)


@njit(cache=True)
def project_positions(con, gap_end, inv_mass, invI, slop, iterations, pos, quats):
    """Remove the predicted end-of-step overlaps ``gap_end < 0`` of the
    :class:`~peclet.dem.solver.Constraints` ``con`` by moving and rotating the bodies (in
    place on ``pos`` (N, 3) and ``quats`` (N, 4)); velocities are not touched. Serial, in
    contact order (alternating)."""
    n = con.a.shape[0]
    nb = pos.shape[0]
    kn = np.empty(n)
    if not _pos_setup(con, gap_end, inv_mass, invI, slop, kn):
        return
    dx, dth, acc = corrections(n, nb)
    st = PosState(gap_end, kn, acc, slop)
    body = Rows(dx, dth, inv_mass, invI)
    for it in range(iterations):
        pos_sweep(FIRST, n, it % 2 == 1, con, st, body)
    bad = move_bodies(FIRST, nb, dx, dth, pos, quats)
    if bad >= 0:
        raise_bad_turn(bad, dth, quats)
