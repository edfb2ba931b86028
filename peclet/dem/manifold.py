"""Manifold reduction of a task's hits: at most MAX_PER_TASK contacts per body pair.

A task's hits (rows of ``hits``: point (3), normal (3), gap, feature) are first put in probe
order (:func:`sort_hits`), whatever order the culling visited them in, so that the reduction
sees the same rows in the same order. :func:`reduce_hits` then groups them by normal direction
(at most ``MAX_CLUSTERS`` groups, each seeded by its deepest remaining hit) and keeps at most
four points per group: the deepest, the one farthest from it in the contact plane, and the two
extremes on either side of that line. A pair's impulse thus does not depend on how many probes
happen to be inside. Every choice breaks ties by the lowest index (determinism).
"""
from __future__ import annotations

import numpy as np
from numba import njit

MAX_CLUSTERS = 4
POINTS_PER_CLUSTER = 4
MAX_PER_TASK = MAX_CLUSTERS * POINTS_PER_CLUSTER
#: Two hits belong to the same normal group when their normals make an angle below ~37 deg.
CLUSTER_COS = 0.8

# hit row layout
HX, HN, HG, HF = 0, 3, 6, 7
HIT_COLS = 8


@njit(cache=True)
def sort_hits(hits, n0, n1):
    """Insertion sort of the rows [n0, n1) by feature id: the probe order, whatever order the
    culling visited them in (so the reduction sees the same rows in the same order)."""
    for i in range(n0 + 1, n1):
        j = i
        while j > n0 and hits[j - 1, HF] > hits[j, HF]:
            for e in range(HIT_COLS):
                v = hits[j, e]
                hits[j, e] = hits[j - 1, e]
                hits[j - 1, e] = v
            j -= 1


@njit(cache=True)
def reduce_hits(hits, nh, lab, reps, tol2, touch, base, out_point, out_normal, out_gap, out_feat):
    """Reduce a task's hits to at most MAX_PER_TASK contacts written from slot ``base``."""
    if nh <= 1:
        # no hit, or one (every task with a sphere in it): kept as it is, which is what the
        # reduction below makes of a single hit (its own group, no spread points)
        if nh == 1:
            for e in range(3):
                out_point[base, e] = hits[0, e]
                out_normal[base, e] = hits[0, 3 + e]
            out_gap[base] = hits[0, HG]
            out_feat[base] = np.int64(hits[0, HF])
        return nh
    for i in range(nh):
        lab[i] = -1
    ncl = 0
    while ncl < MAX_CLUSTERS:
        best = -1
        for i in range(nh):
            if lab[i] < 0 and (best < 0 or hits[i, HG] < hits[best, HG]):
                best = i
        if best < 0:
            break
        for i in range(nh):
            if lab[i] < 0:
                d = (hits[i, 3] * hits[best, 3] + hits[i, 4] * hits[best, 4]
                     + hits[i, 5] * hits[best, 5])
                if d >= CLUSTER_COS:
                    lab[i] = ncl
        lab[best] = ncl
        reps[ncl] = best
        ncl += 1
    for i in range(nh):
        if lab[i] < 0:
            bk = 0
            bd = -2.0
            for k in range(ncl):
                r = reps[k]
                d = hits[i, 3] * hits[r, 3] + hits[i, 4] * hits[r, 4] + hits[i, 5] * hits[r, 5]
                if d > bd:
                    bd = d
                    bk = k
            lab[i] = bk
    nout = 0
    for k in range(ncl):
        i0 = reps[k]
        nx = hits[i0, 3]
        ny = hits[i0, 4]
        nz = hits[i0, 5]
        # farthest from the deepest point, in the contact plane
        # the spread points are chosen among the hits within ``touch`` of the deepest: the
        # support polygon of what actually touches, not of far speculative probes
        lim = hits[i0, HG] + touch
        i1 = -1
        b1 = tol2
        for i in range(nh):
            if lab[i] == k and hits[i, HG] <= lim:
                ex = hits[i, 0] - hits[i0, 0]
                ey = hits[i, 1] - hits[i0, 1]
                ez = hits[i, 2] - hits[i0, 2]
                en = ex * nx + ey * ny + ez * nz
                d2 = ex * ex + ey * ey + ez * ez - en * en
                if d2 > b1:
                    b1 = d2
                    i1 = i
        i2 = -1
        i3 = -1
        if i1 >= 0:
            ux = hits[i1, 0] - hits[i0, 0]
            uy = hits[i1, 1] - hits[i0, 1]
            uz = hits[i1, 2] - hits[i0, 2]
            # signed (doubled) triangle area n . (u x e), largest either side of the line
            thr = tol2 ** 0.5 * b1 ** 0.5
            b2 = thr
            b3 = -thr
            for i in range(nh):
                if lab[i] == k and hits[i, HG] <= lim:
                    ex = hits[i, 0] - hits[i0, 0]
                    ey = hits[i, 1] - hits[i0, 1]
                    ez = hits[i, 2] - hits[i0, 2]
                    a = (nx * (uy * ez - uz * ey) + ny * (uz * ex - ux * ez)
                         + nz * (ux * ey - uy * ex))
                    if a > b2:
                        b2 = a
                        i2 = i
                    if a < b3:
                        b3 = a
                        i3 = i
        for i in (i0, i1, i2, i3):
            if i >= 0:
                o = base + nout
                for e in range(3):
                    out_point[o, e] = hits[i, e]
                    out_normal[o, e] = hits[i, 3 + e]
                out_gap[o] = hits[i, HG]
                out_feat[o] = np.int64(hits[i, HF])
                nout += 1
    return nout
