"""The seeds of a composed pair's patches at a rebuild of the candidate list: the detection's
points and every probe within the skin, deepest first (docstring of
:mod:`peclet.dem.hertz.patch`)."""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from .fields import field, pair_of
from .patch import MAX_PATCHES, PATCH_OK, SAME_PATCH, solve_patch


@njit(cache=True)
def _in_footprint(pt, px_, foot, npatch):
    """Whether the point ``pt`` lies in the footprint (centre ``px_[j]``, radius ``foot[j]``)
    of one of the first ``npatch`` patches."""
    for j in range(npatch):
        d2 = 0.0
        for e in range(3):
            d2 += (pt[e] - px_[j, e]) ** 2
        if d2 <= foot[j] * foot[j]:
            return True
    return False


@njit(cache=True)
def _seed_pair(ia, ib, shift, det_pt, det_gap, margin, sh, o_mode, o_u, o_probe):
    """The patches of one composed pair at a rebuild: seeds are the detection's points
    (``det_pt``, gaps ``det_gap``) and every probe of a (of b, when b is a composed body)
    within ``margin`` of the other side, taken deepest first; a seed outside the footprint
    of every patch found so far starts a patch solve, and a solve that ends on a known patch
    adds nothing. Writes per patch its mode (0 a patch, tracked in a's home frame; 1 / 2 the
    deepest seed whose solve failed, a probe of a / of b, tracked in that body's frame), ``o_u``
    and ``o_probe`` (the seed's probe index within its shape, -1 for a detection point).
    Returns the number of rows (MAX_PATCHES + 1: too many)."""
    Ha = np.empty((3, 3))
    Hb = np.empty((3, 3))
    out = np.empty(10)
    pair = pair_of(ia, ib, shift, sh)
    A, B, _, scale, st = pair
    ka, xa, Ra, kb, xb, Rb = A.kind, A.x, A.R, B.kind, B.x, B.R
    shape_of, shape_p0, shape_np, probes = sh.shape_of, sh.shape_p0, sh.shape_np, sh.probes
    na_p = shape_np[shape_of[ia]] if ka == 1 else 0
    nb_p = shape_np[shape_of[ib]] if (ib >= 0 and kb == 1) else 0
    nd = det_pt.shape[0]
    ns = nd + na_p + nb_p
    spt = np.empty((ns, 3))
    sdep = np.empty(ns)
    sside = np.empty(ns, np.int64)          # 0 detection point, 1 a's probe, 2 b's probe
    sprobe = np.empty(ns, np.int64)
    k = 0
    for j in range(nd):
        for e in range(3):
            spt[k, e] = det_pt[j, e]
        sdep[k] = det_gap[j]
        sside[k] = 0
        sprobe[k] = -1
        k += 1
    for side in range(1, 3):
        if side == 1:
            m, xo, Ro, p0 = na_p, xa, Ra, shape_p0[shape_of[ia]] if ka == 1 else 0
        else:
            m, xo, Ro, p0 = nb_p, xb, Rb, shape_p0[shape_of[ib]] if nb_p > 0 else 0
        for p in range(m):
            q = probes[p0 + p]
            px = xo[0] + Ro[0, 0] * q[0] + Ro[0, 1] * q[1] + Ro[0, 2] * q[2]
            py = xo[1] + Ro[1, 0] * q[0] + Ro[1, 1] * q[1] + Ro[1, 2] * q[2]
            pz = xo[2] + Ro[2, 0] * q[0] + Ro[2, 1] * q[1] + Ro[2, 2] * q[2]
            other = B if side == 1 else A
            rt, xt = other.rad, other.x
            if rt < np.inf:
                d2 = (px - xt[0]) ** 2 + (py - xt[1]) ** 2 + (pz - xt[2]) ** 2
                if d2 > (rt + margin) ** 2:
                    continue
            ph, gx, gy, gz = field(other, sh, px, py, pz, st)
            gn = math.sqrt(gx * gx + gy * gy + gz * gz)
            if not (gn > 0.0):
                continue
            d = ph / gn
            if not (d < margin):
                continue
            spt[k, 0] = px
            spt[k, 1] = py
            spt[k, 2] = pz
            sdep[k] = d
            sside[k] = side
            sprobe[k] = p
            k += 1
    order = np.argsort(sdep[:k], kind="mergesort")
    px_ = np.empty((MAX_PATCHES, 3))
    foot = np.empty(MAX_PATCHES)
    npatch = 0
    fail = -1
    tol2 = (SAME_PATCH * scale) ** 2
    for oi in range(k):
        s = order[oi]
        if _in_footprint(spt[s], px_, foot, npatch):
            continue
        res = solve_patch(pair, spt[s, 0], spt[s, 1], spt[s, 2], Ha, Hb, out)
        if res != PATCH_OK:
            if fail < 0 and sside[s] != 0:
                fail = s
            continue
        same = False
        for j in range(npatch):
            d2 = 0.0
            for e in range(3):
                d2 += (out[e] - px_[j, e]) ** 2
            if d2 <= tol2:
                same = True
                break
        if same:
            continue
        if npatch == MAX_PATCHES:
            return MAX_PATCHES + 1
        for e in range(3):
            px_[npatch, e] = out[e]
        # the seeds within margin of a paraboloid patch of smaller radius R'
        foot[npatch] = math.sqrt(2.0 * out[8] * max(margin - out[6], 0.0))
        dx = out[0] - xa[0]
        dy = out[1] - xa[1]
        dz = out[2] - xa[2]
        o_mode[npatch] = 0
        for e in range(3):
            o_u[npatch, e] = Ra[0, e] * dx + Ra[1, e] * dy + Ra[2, e] * dz
        o_probe[npatch] = sprobe[s]
        npatch += 1
    if fail >= 0:
        if not _in_footprint(spt[fail], px_, foot, npatch):
            if npatch == MAX_PATCHES:
                return MAX_PATCHES + 1
            side = sside[fail]
            o_mode[npatch] = side
            s0 = shape_of[ia] if side == 1 else shape_of[ib]
            for e in range(3):
                o_u[npatch, e] = probes[shape_p0[s0] + sprobe[fail], e]
            o_probe[npatch] = sprobe[fail]
            npatch += 1
    return npatch


@njit(cache=True)
def seed_patches(qa, qb, qshift, det_off, det_pt, det_gap, margin, sh):
    """:func:`_seed_pair` for each composed pair (a ``qa[k]``, b ``qb[k]``, image ``qshift``;
    its detection points ``det_pt[det_off[k]:det_off[k + 1]]``): (count (Q,), mode (Q, MP),
    u (Q, MP, 3), probe (Q, MP)) with MP = MAX_PATCHES; ``sh``: the
    :class:`~peclet.dem.hertz.fields.Shapes`. Serial, in pair order."""
    nq = qa.shape[0]
    cnt = np.empty(nq, np.int64)
    mode = np.zeros((nq, MAX_PATCHES), np.int64)
    u = np.zeros((nq, MAX_PATCHES, 3))
    probe = np.full((nq, MAX_PATCHES), -1, np.int64)
    for k in range(nq):
        cnt[k] = _seed_pair(qa[k], qb[k], qshift[k], det_pt[det_off[k]:det_off[k + 1]],
                            det_gap[det_off[k]:det_off[k + 1]], margin, sh, mode[k], u[k],
                            probe[k])
    return cnt, mode, u, probe
