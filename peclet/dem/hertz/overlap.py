"""The overlap region of a distributed contact along one normal: the sampling grid and its zooms,
the overlap's integral over the inside cells and the flat-punch law (docstring of
:mod:`peclet.dem.hertz.distributed`)."""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from .fields import field, tangents
from .patch import PATCH_OK, PATCH_REASONS, PATCH_TOL

#: Nodes per axis of a distributed contact's sampling grid (the grid is zoomed onto the
#: overlap region, so this is the resolution across the region in each direction).
DIST_GRID = np.int64(24)
#: At most this many zooms of the sampling grid onto the overlap region.
DIST_ZOOMS = np.int64(8)
#: Bisection steps that place the region's boundary between an inside and an outside node.
DIST_BISECT = np.int64(8)
#: A distributed contact is refused when its largest overlap exceeds this fraction of the
#: smaller bounding radius of its bodies (the law assumes a shallow overlap).
DIST_DEEP_LIMIT = 0.1
#: The feature id of a pair's distributed contact (one per pair; its history key).
DIST_FEATURE = (1 << 26) - 1
#: Status of a distributed contact whose overlap is too deep (refused).
PATCH_DIST_DEEP = 7
#: Candidate mode of a pair that had too many patches at its rebuild: always distributed.
MODE_DISTRIBUTED = 3
#: dist_region's status when its search ended without an overlap it could rule out.
DIST_UNRESOLVED = -1
#: _zoom's status when it placed its last grid (the region is integrated on it).
_ZOOMED = -2

PATCH_REASONS[PATCH_DIST_DEEP] = (
    f"the distributed contact's overlap exceeds {DIST_DEEP_LIMIT} x the smaller bounding "
    "radius (far too soft, or dt far too large)")


@njit(cache=True)
def midway(p, px, py, pz, nx, ny, nz, s0):
    """Along the line p + s n (n from b to a): (m, s) with m = max(phi_a, phi_b) at the s where
    the two are equal (Newton from s0): m < 0 means the line passes through both bodies, and
    m bounds the distance from p + s n to their intersection (1-Lipschitz fields)."""
    A, B, sh, scale, st = p
    s = s0
    tol = PATCH_TOL * scale
    cap = 0.25 * scale
    m = np.inf
    for _ in range(12):
        x = px + s * nx
        y = py + s * ny
        z = pz + s * nz
        pa, gax, gay, gaz = field(A, sh, x, y, z, st)
        pb, gbx, gby, gbz = field(B, sh, x, y, z, st)
        m = max(pa, pb)
        fp = (gax - gbx) * nx + (gay - gby) * ny + (gaz - gbz) * nz
        if not (fp < -0.25):
            fp = -1.0
        step = -(pa - pb) / fp
        if step > cap:
            step = cap
        elif step < -cap:
            step = -cap
        if abs(step) <= tol:
            break
        s += step
    return m, s


@njit(cache=True)
def exit_along(side, p, px, py, pz, nx, ny, nz, s0, direction):
    """From p + s0 n inside the :class:`~peclet.dem.hertz.fields.Side` ``side`` of the pair
    ``p``, the s where its surface is crossed moving along
    ``direction`` * n (Newton on phi along the line, steps at least the sphere-tracing bound)."""
    sh, scale, st = p.sh, p.scale, p.st
    s = s0
    tol = PATCH_TOL * scale
    for _ in range(30):
        ph, gx, gy, gz = field(side, sh, px + s * nx, py + s * ny, pz + s * nz, st)
        d = direction * (gx * nx + gy * ny + gz * nz)       # d phi / d(distance moved)
        step = -ph / d if d > 0.2 else -ph      # Newton; at grazing incidence a safe |phi|
        if abs(step) <= tol:
            break
        s += direction * step
    return s


@njit(cache=True)
def agm_ellipk(m):
    """Complete elliptic integral of the first kind K(m), m = e^2 in [0, 1)."""
    a = 1.0
    b = math.sqrt(1.0 - m)
    for _ in range(40):
        if abs(a - b) <= 1e-15 * a:
            break
        a, b = 0.5 * (a + b), math.sqrt(a * b)
    return 0.5 * math.pi / a


@njit(cache=True)
def grid_eval(p, c, u1, u2, w1, w2, n, N, grid):
    """m and s of :func:`midway` at the N x N cell centres of the box c +- w1 u1 +- w2 u2;
    node positions into gx (N, N, 3); ``grid`` = (gm, gs, gx)."""
    gm, gs, gx = grid
    for i in range(N):
        a1 = ((2.0 * i + 1.0) / N - 1.0) * w1
        for j in range(N):
            a2 = ((2.0 * j + 1.0) / N - 1.0) * w2
            for e in range(3):
                gx[i, j, e] = c[e] + a1 * u1[e] + a2 * u2[e]
            m, s = midway(p, gx[i, j, 0], gx[i, j, 1], gx[i, j, 2], n[0], n[1], n[2],
                          0.0)
            gm[i, j] = m
            gs[i, j] = s


@njit(cache=True)
def _zoom(p, NF, zooms, n, c, u1, u2, grid):
    """The zooms of the sampling grid (``grid`` = (gm, gs, gx), NF x NF at most) onto the
    overlap region along ``n``, from the box of centre ``c`` and axes ``u1``, ``u2`` (all
    three changed in place): (status, N, w1, w2), the last grid's size and half-widths;
    status PATCH_OK (nothing overlaps: a rigorous bound on the first, whole box),
    DIST_UNRESOLVED (nothing found after a zoom) or _ZOOMED (integrate on the last grid)."""
    gm = grid[0]
    w1 = p.scale
    w2 = p.scale
    N = NF
    for it in range(zooms):
        # a coarse first look (its rigorous bound settles most pairs that do not overlap)
        N = min(np.int64(8), NF) if it == 0 else NF
        grid_eval(p, c, u1, u2, w1, w2, n, N, grid)
        h1 = 2.0 * w1 / N
        h2 = 2.0 * w2 / N
        hd = 0.5 * math.sqrt(h1 * h1 + h2 * h2)
        # inside nodes: their in-plane coordinates, moments
        cnt = 0
        s1 = 0.0
        s2 = 0.0
        border = False
        border1 = False
        border2 = False
        imin = 0
        jmin = 0
        for i in range(N):
            for j in range(N):
                if gm[i, j] < gm[imin, jmin]:
                    imin, jmin = i, j
                if gm[i, j] < 0.0:
                    cnt += 1
                    s1 += ((2.0 * i + 1.0) / N - 1.0) * w1
                    s2 += ((2.0 * j + 1.0) / N - 1.0) * w2
                    if i == 0 or i == N - 1:
                        border1 = True
                    if j == 0 or j == N - 1:
                        border2 = True
                    border = border1 or border2
        if cnt == 0:
            if gm[imin, jmin] > hd:
                # nothing within reach: no overlap, a rigorous bound on the first (whole) box
                # only; after a zoom it is the zoomed box's
                return (PATCH_OK if it == 0 else DIST_UNRESOLVED), N, w1, w2
            w1, w2 = _toward_minimum(gm, N, NF, imin, jmin, w1, w2, h1, h2, c, u1, u2)
            continue
        # inside nodes exist: principal axes of their positions, the box around them
        e1x, e1y, e2x, e2y, lo1, hi1, lo2, hi2, nw1, nw2 = _inside_box(gm, N, w1, w2, h1, h2,
                                                                       cnt, s1, s2)
        same_axes = e1x == 1.0 and e1y == 0.0
        if same_axes:
            # the overlap reaches the grid's edge: widen that way
            if border1:
                nw1 = max(nw1, 1.5 * w1)
            if border2:
                nw2 = max(nw2, 1.5 * w2)
        if not border and same_axes and nw1 >= 0.7 * w1 and nw2 >= 0.7 * w2 and N == NF:
            break
        if it == zooms - 1:
            break
        if N != NF and not border and same_axes and nw1 >= 0.7 * w1 and nw2 >= 0.7 * w2:
            continue                               # the same box, now at full resolution
        cc1 = 0.5 * (lo1 + hi1)
        cc2 = 0.5 * (lo2 + hi2)
        v1 = np.empty(3)
        v2 = np.empty(3)
        for e in range(3):
            c[e] = c[e] + (cc1 * e1x + cc2 * e2x) * u1[e] + (cc1 * e1y + cc2 * e2y) * u2[e]
            v1[e] = e1x * u1[e] + e1y * u2[e]
            v2[e] = e2x * u1[e] + e2y * u2[e]
        for e in range(3):
            u1[e] = v1[e]
            u2[e] = v2[e]
        w1 = nw1
        w2 = nw2
    # the zooms may run out with the overlap on the grid's border or never resolved: the last
    # grid is sampled as it is (a coarse estimate, documented)
    return _ZOOMED, N, w1, w2


@njit(cache=True)
def _toward_minimum(gm, N, NF, imin, jmin, w1, w2, h1, h2, c, u1, u2):
    """No inside node: the next box (``c``, ``u1``, ``u2`` changed in place; its half-widths
    returned) from a quadratic model of m on the 3 x 3 nodes around the smallest."""
    # quadratic model of m on the 3 x 3 nodes around the smallest: jump to its minimum
    i0 = min(max(imin, 1), N - 2)
    j0 = min(max(jmin, 1), N - 2)
    f0 = gm[i0, j0]
    g1 = 0.5 * (gm[i0 + 1, j0] - gm[i0 - 1, j0])
    g2 = 0.5 * (gm[i0, j0 + 1] - gm[i0, j0 - 1])
    h11 = gm[i0 + 1, j0] - 2.0 * f0 + gm[i0 - 1, j0]
    h22 = gm[i0, j0 + 1] - 2.0 * f0 + gm[i0, j0 - 1]
    h12 = 0.25 * (gm[i0 + 1, j0 + 1] - gm[i0 + 1, j0 - 1] - gm[i0 - 1, j0 + 1]
                  + gm[i0 - 1, j0 - 1])
    # eigen-directions of the 2 x 2 model Hessian (in grid units)
    half = 0.5 * (h11 + h22)
    rad_ = math.sqrt(0.25 * (h11 - h22) ** 2 + h12 * h12)
    lam1 = half + rad_
    lam2 = half - rad_
    if abs(h12) > 1e-300:
        e1x, e1y = lam1 - h22, h12
    elif h11 >= h22:
        e1x, e1y = 1.0, 0.0
    else:
        e1x, e1y = 0.0, 1.0
    en = math.sqrt(e1x * e1x + e1y * e1y)
    e1x /= en
    e1y /= en
    e2x, e2y = -e1y, e1x
    d1 = 0.0
    d2 = 0.0
    ga = g1 * e1x + g2 * e1y
    gb = g1 * e2x + g2 * e2y
    if lam1 > 0.0:
        d1 = min(max(-ga / lam1, -1.5), 1.5)
    if lam2 > 0.0:
        d2 = min(max(-gb / lam2, -1.5), 1.5)
    di = d1 * e1x + d2 * e2x
    dj = d1 * e1y + d2 * e2y
    a1 = ((2.0 * i0 + 1.0) / N - 1.0) * w1 + di * h1
    a2 = ((2.0 * j0 + 1.0) / N - 1.0) * w2 + dj * h2
    if lam1 > 0.0 and lam2 <= 0.05 * lam1:
        # line-like (flat along e2): the next grid's axes along and across the line,
        # a row of nodes through the model's minimum, the extent along it kept
        v1 = np.empty(3)
        v2 = np.empty(3)
        for e in range(3):
            v1[e] = e2x * h1 * u1[e] + e2y * h2 * u2[e]     # along
            v2[e] = e1x * h1 * u1[e] + e1y * h2 * u2[e]     # across
        l1 = math.sqrt(v1[0] ** 2 + v1[1] ** 2 + v1[2] ** 2)
        for e in range(3):
            v1[e] /= l1
        dd = v1[0] * v2[0] + v1[1] * v2[1] + v1[2] * v2[2]
        for e in range(3):
            v2[e] -= dd * v1[e]
        l2 = math.sqrt(v2[0] ** 2 + v2[1] ** 2 + v2[2] ** 2)
        for e in range(3):
            v2[e] /= l2
        off = 0.0
        for e in range(3):
            off += (a1 * u1[e] + a2 * u2[e]) * v2[e]
        wmax = max(w1, w2)
        for e in range(3):
            c[e] += (off + wmax / NF) * v2[e]
            u1[e] = v1[e]
            u2[e] = v2[e]
        return wmax, wmax
    # shift the next (full) grid so that a node lies on the model's minimum: a small
    # region between the nodes is then seen
    k1 = min(max(int(round((a1 / w1 + 1.0) * 0.5 * NF - 0.5)), 0), NF - 1)
    k2 = min(max(int(round((a2 / w2 + 1.0) * 0.5 * NF - 0.5)), 0), NF - 1)
    b1 = a1 - ((2.0 * k1 + 1.0) / NF - 1.0) * w1
    b2 = a2 - ((2.0 * k2 + 1.0) / NF - 1.0) * w2
    for e in range(3):
        c[e] += b1 * u1[e] + b2 * u2[e]
    return w1, w2


@njit(cache=True)
def _inside_box(gm, N, w1, w2, h1, h2, cnt, s1, s2):
    """Inside nodes exist: the principal axes (e1, e2, in the grid's axes) of their positions,
    their extents along them (lo1, hi1, lo2, hi2) and the box's new half-widths."""
    m1 = s1 / cnt
    m2 = s2 / cnt
    j11 = 0.0
    j12 = 0.0
    j22 = 0.0
    for i in range(N):
        for j in range(N):
            if gm[i, j] < 0.0:
                q1 = ((2.0 * i + 1.0) / N - 1.0) * w1 - m1
                q2 = ((2.0 * j + 1.0) / N - 1.0) * w2 - m2
                j11 += q1 * q1
                j12 += q1 * q2
                j22 += q2 * q2
    j11 += cnt * h1 * h1 / 12.0
    j22 += cnt * h2 * h2 / 12.0
    half = 0.5 * (j11 + j22)
    rad_ = math.sqrt(0.25 * (j11 - j22) ** 2 + j12 * j12)
    lam1 = half + rad_
    lam2 = half - rad_
    if lam1 > 1.5 * lam2 and abs(j12) > 1e-12 * lam1:
        e1x, e1y = lam1 - j22, j12
        en = math.sqrt(e1x * e1x + e1y * e1y)
        e1x /= en
        e1y /= en
    else:
        e1x, e1y = 1.0, 0.0                    # keep the current axes
    e2x, e2y = -e1y, e1x
    lo1 = np.inf
    hi1 = -np.inf
    lo2 = np.inf
    hi2 = -np.inf
    for i in range(N):
        for j in range(N):
            if gm[i, j] < 0.0:
                q1 = ((2.0 * i + 1.0) / N - 1.0) * w1
                q2 = ((2.0 * j + 1.0) / N - 1.0) * w2
                r1 = q1 * e1x + q2 * e1y
                r2 = q1 * e2x + q2 * e2y
                lo1 = min(lo1, r1)
                hi1 = max(hi1, r1)
                lo2 = min(lo2, r2)
                hi2 = max(hi2, r2)
    mg1 = abs(e1x) * h1 + abs(e1y) * h2
    mg2 = abs(e2x) * h1 + abs(e2y) * h2
    nw1 = 0.5 * (hi1 - lo1) + mg1
    nw2 = 0.5 * (hi2 - lo2) + mg2
    return e1x, e1y, e2x, e2y, lo1, hi1, lo2, hi2, nw1, nw2


@njit(cache=True)
def _integrate(p, grid, N, w1, w2, nbis, n):
    """The overlap over the inside cells of the last grid (each cell cut at the region's
    boundary by ``nbis`` bisections): (A, V, the area's and the volume's first moments cA1,
    cA2, cV1, cV2, cVs, the second moments J11, J12, J22, the largest chord)."""
    A_, B_ = p.a, p.b
    gm, gs, gx_ = grid
    h1 = 2.0 * w1 / N
    h2 = 2.0 * w2 / N
    A = 0.0
    V = 0.0
    cA1 = 0.0
    cA2 = 0.0
    cV1 = 0.0
    cV2 = 0.0
    cVs = 0.0
    J11 = 0.0
    J12 = 0.0
    J22 = 0.0
    dmax = 0.0
    ext = np.empty(4)
    for i in range(N):
        for j in range(N):
            if not (gm[i, j] < 0.0):
                continue
            # the chord of the intersection along n through the node
            px, py, pz = gx_[i, j, 0], gx_[i, j, 1], gx_[i, j, 2]
            s_a = exit_along(A_, p, px, py, pz, n[0], n[1], n[2], gs[i, j], -1.0)
            s_b = exit_along(B_, p, px, py, pz, n[0], n[1], n[2], gs[i, j], 1.0)
            d = s_b - s_a
            if not (d > 0.0):
                continue
            for k in range(4):
                di = (1, -1, 0, 0)[k]
                dj = (0, 0, 1, -1)[k]
                hh = h1 if k < 2 else h2
                ii = i + di
                jj = j + dj
                if ii < 0 or jj < 0 or ii >= N or jj >= N:
                    ext[k] = 0.5 * hh
                    continue
                if gm[ii, jj] < 0.0:
                    ext[k] = 0.5 * hh
                    continue
                # bisect the boundary on the segment to the outside neighbour
                lo_ = 0.0
                hi_ = 1.0
                sg = gs[i, j]
                for _ in range(nbis):
                    t = 0.5 * (lo_ + hi_)
                    qx = px + t * (gx_[ii, jj, 0] - px)
                    qy = py + t * (gx_[ii, jj, 1] - py)
                    qz = pz + t * (gx_[ii, jj, 2] - pz)
                    mq, sq = midway(p, qx, qy, qz, n[0], n[1], n[2], sg)
                    if mq < 0.0:
                        lo_ = t
                        sg = sq
                    else:
                        hi_ = t
                ext[k] = 0.5 * (lo_ + hi_) * hh
            l1 = ext[0] + ext[1]
            l2 = ext[2] + ext[3]
            w = l1 * l2
            q1 = ((2.0 * i + 1.0) / N - 1.0) * w1 + 0.5 * (ext[0] - ext[1])
            q2 = ((2.0 * j + 1.0) / N - 1.0) * w2 + 0.5 * (ext[2] - ext[3])
            A += w
            V += w * d
            cA1 += w * q1
            cA2 += w * q2
            cV1 += w * d * q1
            cV2 += w * d * q2
            cVs += w * d * 0.5 * (s_a + s_b)
            J11 += w * (q1 * q1 + l1 * l1 / 12.0)
            J12 += w * q1 * q2
            J22 += w * (q2 * q2 + l2 * l2 / 12.0)
            dmax = max(dmax, d)
    return A, V, cA1, cA2, cV1, cV2, cVs, J11, J12, J22, dmax


@njit(cache=True)
def dist_region(p, N, zooms, nbis, estar, n, y0, out):
    """The region, overlap and law of a distributed contact of the pair ``p`` along the unit
    normal ``n`` (from b to a) through the probe ``y0``: writes ``out`` (see
    :func:`~peclet.dem.hertz.distributed.dist_pair`) and returns PATCH_OK (force 0: nothing
    overlaps anywhere, a rigorous bound on the first, whole box), DIST_UNRESOLVED (force 0: no
    overlap found, none ruled out) or PATCH_DIST_DEEP."""
    for e in range(out.shape[0]):
        out[e] = 0.0
    out[3], out[4], out[5] = n[0], n[1], n[2]
    scale = p.scale
    # ---- grid box: the smaller side's bounding disc, in the plane through y0
    xs = p.a.x if p.a.rad <= p.b.rad else p.b.x
    c = np.empty(3)
    dn = (xs[0] - y0[0]) * n[0] + (xs[1] - y0[1]) * n[1] + (xs[2] - y0[2]) * n[2]
    for e in range(3):
        c[e] = xs[e] - dn * n[e]
    t1x, t1y, t1z, t2x, t2y, t2z = tangents(n[0], n[1], n[2])
    u1 = np.array([t1x, t1y, t1z])
    u2 = np.array([t2x, t2y, t2z])
    grid = (np.empty((N, N)), np.empty((N, N)), np.empty((N, N, 3)))
    res, N, w1, w2 = _zoom(p, N, zooms, n, c, u1, u2, grid)
    if res != _ZOOMED:
        return res
    # ---- integrate over the last grid: inside cells, their extents to the boundary
    A, V, cA1, cA2, cV1, cV2, cVs, J11, J12, J22, dmax = _integrate(p, grid, N, w1, w2, nbis, n)
    if not (V > 0.0):
        return DIST_UNRESOLVED
    a1 = cA1 / A
    a2 = cA2 / A
    J11 -= A * a1 * a1
    J12 -= A * a1 * a2
    J22 -= A * a2 * a2
    half = 0.5 * (J11 + J22)
    rad_ = math.sqrt(0.25 * (J11 - J22) ** 2 + J12 * J12)
    lam1 = half + rad_
    lam2 = max(half - rad_, 1e-300)
    r = math.sqrt(lam1 / lam2)
    ea = math.sqrt(A * r / math.pi)            # the equal-area ellipse of the region's shape
    eb = A / (math.pi * ea)
    kk = agm_ellipk(1.0 - 1.0 / (r * r))
    k = math.pi * ea * estar / (kk * A)        # pressure per unit overlap
    q1 = cV1 / V
    q2 = cV2 / V
    qs = cVs / V
    for e in range(3):
        out[e] = c[e] + q1 * u1[e] + q2 * u2[e] + qs * n[e]
    out[6] = dmax
    out[7] = k * V
    out[8] = k * A
    out[9] = A
    out[10] = V
    out[11] = ea
    out[12] = eb
    if dmax > DIST_DEEP_LIMIT * scale:
        return PATCH_DIST_DEEP
    return PATCH_OK
