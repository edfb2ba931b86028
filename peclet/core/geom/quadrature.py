"""Mass properties of a CSG solid by implicit quadrature (sign of phi only).

Method: an adaptive octree of cells with a Saye-style height-function rule in each cut cell
(Saye, SIAM J. Sci. Comput. 37(2) A993, 2015), extended with exact breakpoints at CSG creases.

- **Cells.** The box is split into ``n`` cells per axis. For a 1-Lipschitz root (every leaf
  1-Lipschitz; the certificate's second half) one evaluation at the centre decides a cell whose
  half-diagonal is below ``|phi|``: wholly inside (its box moments are added exactly) or
  outside. Other cells are *cut*.
- **Height direction.** In a cut cell the height axis k is the largest component of grad phi
  at the centre; u and v are the other two axes.
- **Inner (k), exact.** Along a line (u, v, .) every root of phi in the cell is bracketed by
  sign (steps of ``max(|phi|, hmin)`` for a 1-Lipschitz tree: ``|phi|`` proves the skipped
  stretch has no root; a uniform ``hmin`` otherwise) and refined to round-off by the Illinois
  method. The inside runs give the moments of 1, k, k^2 in closed form.
- **Middle (v), breakpoints.** The line integrals are smooth in v except where the line's
  *signature* changes: its number of roots, or the leaf active at a root (a crease; the
  evaluator reports the active leaf). Signatures are sampled at 5 points across the cell and
  every change is located by bisection to ~1e-13 of the cell; each smooth piece gets its own
  Gauss-Legendre rule, so creases and the jumps of walls parallel to k cost no accuracy.
- **Outer (u)** Gauss-Legendre across the cell.
- **Error estimate and adaptivity.** Every cut cell is integrated with q = 5 and q = 7 points
  per transverse axis; the reported value is the q = 7 one and |I7 - I5| its error estimate,
  which over-estimates the q = 7 error wherever the rule converges. A cell whose estimate
  exceeds ``tol * V_box * (d_cell / d_box)^2`` (a tolerance per unit of surface, since cut
  cells tile a surface) is split into 8, down to ``MAX_DEPTH`` levels. The estimates of all
  accepted cells add up to the reported error.

The work is parallel over the top-level cells, each writing its own row, and the rows are
summed in a fixed order: results are bitwise identical at any thread count.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit, prange

from . import kernels as K
from .transforms import matrix_to_quat

#: Max roots along one line and breakpoints across one cell.
MAX_ROOTS = 64
MAX_BREAKS = 64
#: Levels of refinement below the top cells.
MAX_DEPTH = 8
#: Signature probes across a cell (intervals).
V_PROBES = 4
#: Bisection steps locating a breakpoint of the inner integrand (2^-44 of the cell): it may
#: jump there (a wall parallel to the height axis), so the location must be sharp.
BREAK_STEPS = 44
#: ... and of the outer integrand, which is continuous: an error quadratic in the location.
U_BREAK_STEPS = 30

# moment indices of the 10 raw moments (coordinates relative to the box centre)
# 0: 1, 1: x, 2: y, 3: z, 4: xx, 5: yy, 6: zz, 7: xy, 8: xz, 9: yz


@njit(cache=True)
def _phi(ops, lk, lr, ob, oe, ak, u, v, t, iu, iv, st):
    """phi at the point with coordinate t on axis ak and u, v on axes iu, iv."""
    p0 = 0.0
    p1 = 0.0
    p2 = 0.0
    if ak == 0:
        p0 = t
    elif ak == 1:
        p1 = t
    else:
        p2 = t
    if iu == 0:
        p0 = u
    elif iu == 1:
        p1 = u
    else:
        p2 = u
    if iv == 0:
        p0 = v
    elif iv == 1:
        p1 = v
    else:
        p2 = v
    return K.eval_point(ops, lk, lr, ob, oe, p0, p1, p2, st)[0]


@njit(cache=True)
def _refine(ops, lk, lr, ob, oe, ak, iu, iv, u, v, a, fa, b, fb, st):
    """A root of phi in [a, b] (fa, fb of opposite signs) by the Illinois method.

    Returns (root, active leaf at the root side nearest the root)."""
    side = 0
    leaf = -1.0
    for it in range(200):
        if b - a <= 4e-16 * (abs(a) + abs(b)) + 1e-300:
            break
        if it % 4 == 3:                      # a bisection now and then bounds the worst case
            m = 0.5 * (a + b)
        else:
            m = (a * fb - b * fa) / (fb - fa)
            if not (a < m < b):
                m = 0.5 * (a + b)
        fm = _phi(ops, lk, lr, ob, oe, ak, u, v, m, iu, iv, st)
        leaf = st[0, 4]
        if fm == 0.0:
            return m, leaf
        if (fm < 0.0) == (fa < 0.0):
            a = m
            fa = fm
            if side == -1:
                fb *= 0.5
            side = -1
        else:
            b = m
            fb = fm
            if side == 1:
                fa *= 0.5
            side = 1
    r = 0.5 * (a + b)
    _phi(ops, lk, lr, ob, oe, ak, u, v, r, iu, iv, st)
    return r, st[0, 4]


@njit(cache=True)
def _line(ops, lk, lr, ob, oe, ak, iu, iv, u, v, a, b, lip, hmin, st, roots, leaves):
    """Roots of phi along axis ak over [a, b] at (u, v). Returns (count, starts_inside);
    count = -1 if more than MAX_ROOTS."""
    t = a
    f = _phi(ops, lk, lr, ob, oe, ak, u, v, t, iu, iv, st)
    inside0 = f < 0.0
    nr = 0
    while t < b:
        step = hmin
        if lip and abs(f) > step:
            step = abs(f)
        t2 = t + step
        if t2 > b:
            t2 = b
        f2 = _phi(ops, lk, lr, ob, oe, ak, u, v, t2, iu, iv, st)
        if (f < 0.0) != (f2 < 0.0):
            if nr >= MAX_ROOTS:
                return -1, inside0
            r, lf = _refine(ops, lk, lr, ob, oe, ak, iu, iv, u, v, t, f, t2, f2, st)
            roots[nr] = r
            leaves[nr] = lf
            nr += 1
        t = t2
        f = f2
    return nr, inside0


@njit(cache=True)
def _signature(nr, inside0, leaves):
    h = np.int64(nr * 2 + (1 if inside0 else 0))
    for i in range(nr):
        h = (h * np.int64(1000003) + np.int64(leaves[i]) + 1) % np.int64(4611686018427387903)
    return h


@njit(cache=True)
def _accumulate(acc, w, iu, iv, ak, u, v, a, b, nr, inside0, roots, cen):
    """Add w * (moments of the inside runs of the line) to acc (10 raw moments)."""
    m0 = 0.0
    m1 = 0.0
    m2 = 0.0
    ins = inside0
    lo = a
    for i in range(nr + 1):
        hi = roots[i] if i < nr else b
        if ins:
            x0 = lo - cen[ak]
            x1 = hi - cen[ak]
            m0 += x1 - x0
            m1 += 0.5 * (x1 * x1 - x0 * x0)
            m2 += (x1 * x1 * x1 - x0 * x0 * x0) / 3.0
        ins = not ins
        lo = hi
    if m0 == 0.0:
        return
    uu = u - cen[iu]
    vv = v - cen[iv]
    acc[0] += w * m0
    acc[1 + iu] += w * uu * m0
    acc[1 + iv] += w * vv * m0
    acc[1 + ak] += w * m1
    acc[4 + iu] += w * uu * uu * m0
    acc[4 + iv] += w * vv * vv * m0
    acc[4 + ak] += w * m2
    # off-diagonal slots: 7 xy, 8 xz, 9 yz
    acc[_pair(iu, iv)] += w * uu * vv * m0
    acc[_pair(iu, ak)] += w * uu * m1
    acc[_pair(iv, ak)] += w * vv * m1


@njit(cache=True, inline="always")
def _pair(i, j):
    s = i + j
    if s == 1:
        return 7
    if s == 2:
        return 8
    return 9


@njit(cache=True)
def _breaks(ops, lk, lr, ob, oe, ak, iu, iv, u, v0, v1, a, b, lip, hmin, st, roots, leaves,
            brk):
    """Breakpoints of the v-integrand at outer coordinate u: fills brk[0..m-1] with v0, the
    located signature changes, v1. Returns (m, hash of the pieces' signature sequence);
    m = -1 on overflow. Changes are located to 2^-BREAK_STEPS of the probe interval."""
    m = 0
    brk[m] = v0
    m += 1
    nr, ins = _line(ops, lk, lr, ob, oe, ak, iu, iv, u, v0, a, b, lip, hmin, st, roots, leaves)
    if nr < 0:
        return -1, 0
    sl = _signature(nr, ins, leaves)
    seq = sl
    vl = v0
    for j in range(1, V_PROBES + 1):
        vr = v0 + (v1 - v0) * j / V_PROBES
        nr, ins = _line(ops, lk, lr, ob, oe, ak, iu, iv, u, vr, a, b, lip, hmin, st, roots,
                        leaves)
        if nr < 0:
            return -1, 0
        sr = _signature(nr, ins, leaves)
        x0 = vl
        s0 = sl
        while s0 != sr:               # every change in (vl, vr], left to right
            lo_ = x0
            hi_ = vr
            s_hi = sr                 # the signature at hi_, kept so it is never re-solved
            for _ in range(BREAK_STEPS):
                mid = 0.5 * (lo_ + hi_)
                nr, ins = _line(ops, lk, lr, ob, oe, ak, iu, iv, u, mid, a, b, lip, hmin, st,
                                roots, leaves)
                if nr < 0:
                    return -1, 0
                sm = _signature(nr, ins, leaves)
                if sm == s0:
                    lo_ = mid
                else:
                    hi_ = mid
                    s_hi = sm
            if m >= MAX_BREAKS - 1:
                return -1, 0
            brk[m] = hi_
            m += 1
            x0 = hi_
            s0 = s_hi
            seq = (seq * np.int64(1000033) + s0) % np.int64(4611686018427387903)
            if hi_ >= vr:
                break
        vl = vr
        sl = sr
    brk[m] = v1
    m += 1
    return m, seq


@njit(cache=True, inline="always")
def _piece_node(p0, p1, x, smooth):
    """(point, weight factor) of Gauss node x in [0, 1] on piece [p0, p1]. With ``smooth``,
    t = p0 + (p1 - p0)(3x^2 - 2x^3): square-root behaviour at a breakpoint becomes analytic."""
    if smooth:
        return p0 + (p1 - p0) * x * x * (3.0 - 2.0 * x), 6.0 * (p1 - p0) * x * (1.0 - x)
    return p0 + (p1 - p0) * x, p1 - p0


@njit(cache=True)
def _cell_rules(ops, lk, lr, ob, oe, clo, chi, ak, iu, iv, g5x, g5w, g7x, g7w, lip, cen, st,
                roots, leaves, brk, ubrk, a5, a7):
    """Integrate the cut cell [clo, chi] with 5- and 7-point Gauss-Legendre rules on every
    smooth piece in u and v (shared u-breakpoints). Returns False on an overflow."""
    a = clo[ak]
    b = chi[ak]
    u0 = clo[iu]
    u1 = chi[iu]
    v0 = clo[iv]
    v1 = chi[iv]
    hmin = (b - a) / 64.0
    # u-breakpoints: where the sequence of v-piece signatures changes
    mu = 0
    ubrk[mu] = u0
    mu += 1
    m, hl = _breaks(ops, lk, lr, ob, oe, ak, iu, iv, u0, v0, v1, a, b, lip, hmin, st, roots,
                    leaves, brk)
    if m < 0:
        return False
    ul = u0
    for j in range(1, V_PROBES + 1):
        ur = u0 + (u1 - u0) * j / V_PROBES
        m, hr = _breaks(ops, lk, lr, ob, oe, ak, iu, iv, ur, v0, v1, a, b, lip, hmin, st,
                        roots, leaves, brk)
        if m < 0:
            return False
        x0 = ul
        h0 = hl
        while h0 != hr:
            lo_ = x0
            hi_ = ur
            h_hi = hr                 # the structure hash at hi_, kept so it is never redone
            for _ in range(U_BREAK_STEPS):
                mid = 0.5 * (lo_ + hi_)
                m, hm = _breaks(ops, lk, lr, ob, oe, ak, iu, iv, mid, v0, v1, a, b, lip, hmin,
                                st, roots, leaves, brk)
                if m < 0:
                    return False
                if hm == h0:
                    lo_ = mid
                else:
                    hi_ = mid
                    h_hi = hm
            if mu >= MAX_BREAKS - 1:
                return False
            ubrk[mu] = hi_
            mu += 1
            x0 = hi_
            h0 = h_hi
            if hi_ >= ur:
                break
        ul = ur
        hl = hr
    ubrk[mu] = u1
    mu += 1
    for rule in range(2):
        gx = g5x if rule == 0 else g7x
        gw = g5w if rule == 0 else g7w
        acc = a5 if rule == 0 else a7
        q = gx.shape[0]
        for pu in range(mu - 1):
            pu0 = ubrk[pu]
            pu1 = ubrk[pu + 1]
            if pu1 <= pu0:
                continue
            smooth_u = pu > 0 or pu < mu - 2
            for i in range(q):
                u, wu = _piece_node(pu0, pu1, gx[i], smooth_u)
                wu *= gw[i]
                m, hv = _breaks(ops, lk, lr, ob, oe, ak, iu, iv, u, v0, v1, a, b, lip, hmin,
                                st, roots, leaves, brk)
                if m < 0:
                    return False
                for pc in range(m - 1):
                    p0 = brk[pc]
                    p1 = brk[pc + 1]
                    if p1 <= p0:
                        continue
                    smooth_v = pc > 0 or pc < m - 2
                    for jv in range(q):
                        v, wv = _piece_node(p0, p1, gx[jv], smooth_v)
                        nr, ins = _line(ops, lk, lr, ob, oe, ak, iu, iv, u, v, a, b, lip,
                                        hmin, st, roots, leaves)
                        if nr < 0:
                            return False
                        _accumulate(acc, wu * wv * gw[jv], iu, iv, ak, u, v, a, b, nr, ins,
                                    roots, cen)
    return True


@njit(cache=True)
def _axis_order(gx, gy, gz):
    """Axes by decreasing |grad phi|: (height k, inner v, outer u).

    The height axis makes the surface a graph over the transverse face. Where the surface
    meets the cell's k-faces it traces curves whose normal is roughly the transverse part of
    grad phi; making the larger transverse component the inner axis keeps those curves graphs
    over the outer axis, so the outer integrand stays smooth (Saye's choice, one level down).
    """
    a0 = abs(gx)
    a1 = abs(gy)
    a2 = abs(gz)
    k = 0
    if a1 > a0:
        k = 1
    if a2 > max(a0, a1):
        k = 2
    if k == 0:
        return (0, 1, 2) if a1 >= a2 else (0, 2, 1)
    if k == 1:
        return (1, 0, 2) if a0 >= a2 else (1, 2, 0)
    return (2, 0, 1) if a0 >= a1 else (2, 1, 0)


@njit(cache=True)
def _box_moments(acc, clo, chi, cen):
    """Add the exact raw moments of the full box [clo, chi] (relative to cen)."""
    h0 = chi[0] - clo[0]
    h1 = chi[1] - clo[1]
    h2 = chi[2] - clo[2]
    vol = h0 * h1 * h2
    c0 = 0.5 * (clo[0] + chi[0]) - cen[0]
    c1 = 0.5 * (clo[1] + chi[1]) - cen[1]
    c2 = 0.5 * (clo[2] + chi[2]) - cen[2]
    acc[0] += vol
    acc[1] += vol * c0
    acc[2] += vol * c1
    acc[3] += vol * c2
    acc[4] += vol * (c0 * c0 + h0 * h0 / 12.0)
    acc[5] += vol * (c1 * c1 + h1 * h1 / 12.0)
    acc[6] += vol * (c2 * c2 + h2 * h2 / 12.0)
    acc[7] += vol * c0 * c1
    acc[8] += vol * c0 * c2
    acc[9] += vol * c1 * c2


@njit(cache=True)
def _top_cell(ops, lk, lr, ob, oe, clo0, chi0, lip, tol_area, g5x, g5w, g7x, g7w, cen, mom,
              err, stats):
    """Integrate one top-level cell adaptively; adds into mom/err (10,), stats (4,)."""
    st = np.empty((K.MAX_STACK, K.STACK_COLS))
    roots = np.empty(MAX_ROOTS)
    leaves = np.empty(MAX_ROOTS)
    brk = np.empty(MAX_BREAKS)
    ubrk = np.empty(MAX_BREAKS)
    a5 = np.zeros(10)
    a7 = np.zeros(10)
    # explicit stack of cells: lo (3), hi (3), depth
    cells = np.empty((8 * MAX_DEPTH + 8, 7))
    cells[0, 0:3] = clo0
    cells[0, 3:6] = chi0
    cells[0, 6] = 0.0
    top = 1
    clo = np.empty(3)
    chi = np.empty(3)
    while top > 0:
        top -= 1
        for d in range(3):
            clo[d] = cells[top, d]
            chi[d] = cells[top, 3 + d]
        depth = int(cells[top, 6])
        stats[0] += 1.0
        cx = 0.5 * (clo[0] + chi[0])
        cy = 0.5 * (clo[1] + chi[1])
        cz = 0.5 * (clo[2] + chi[2])
        f, gx_, gy_, gz_ = K.eval_point(ops, lk, lr, ob, oe, cx, cy, cz, st)
        hd = 0.5 * math.sqrt((chi[0] - clo[0]) ** 2 + (chi[1] - clo[1]) ** 2
                             + (chi[2] - clo[2]) ** 2)
        if lip and f >= hd:
            continue
        if lip and f <= -hd:
            _box_moments(mom, clo, chi, cen)
            continue
        ak, iv, iu = _axis_order(gx_, gy_, gz_)
        a5[:] = 0.0
        a7[:] = 0.0
        ok = _cell_rules(ops, lk, lr, ob, oe, clo, chi, ak, iu, iv, g5x, g5w, g7x, g7w, lip,
                         cen, st, roots, leaves, brk, ubrk, a5, a7)
        if not ok:
            stats[3] = 1.0
            return
        est = 0.0
        for m in range(10):
            e = abs(a7[m] - a5[m])
            if e > est:
                est = e
        # tolerance per unit of surface: (cell half-diagonal)^2 scaled
        if est <= tol_area * hd * hd or depth >= MAX_DEPTH:
            if depth >= MAX_DEPTH and est > tol_area * hd * hd:
                stats[2] += 1.0
            for m in range(10):
                mom[m] += a7[m]
                err[m] += abs(a7[m] - a5[m])
            if depth > stats[1]:
                stats[1] = depth
            continue
        # split into 8 children, pushed in a fixed order
        for c in range(8):
            for d in range(3):
                mid = 0.5 * (clo[d] + chi[d])
                if (c >> d) & 1:
                    cells[top, d] = mid
                    cells[top, 3 + d] = chi[d]
                else:
                    cells[top, d] = clo[d]
                    cells[top, 3 + d] = mid
            cells[top, 6] = depth + 1
            top += 1
    return


@njit(cache=True, parallel=True)
def integrate_body(ops, lk, lr, ob, oe, lo, hi, n, lip, tol, g5x, g5w, g7x, g7w):
    """Raw moments (10,) relative to the box centre, their error estimates (10,), and
    diagnostics (cells visited, deepest level, cells stopped at MAX_DEPTH, overflow flag)."""
    cen = 0.5 * (lo + hi)
    ncell = n * n * n
    rows = np.zeros((ncell, 10))
    erows = np.zeros((ncell, 10))
    srows = np.zeros((ncell, 4))
    h = (hi - lo) / n
    box_vol = (hi[0] - lo[0]) * (hi[1] - lo[1]) * (hi[2] - lo[2])
    box_hd2 = 0.25 * ((hi[0] - lo[0]) ** 2 + (hi[1] - lo[1]) ** 2 + (hi[2] - lo[2]) ** 2)
    tol_area = tol * box_vol / box_hd2
    for c in prange(ncell):
        i = c % n
        j = (c // n) % n
        k = c // (n * n)
        clo = np.empty(3)
        chi = np.empty(3)
        clo[0] = lo[0] + i * h[0]
        clo[1] = lo[1] + j * h[1]
        clo[2] = lo[2] + k * h[2]
        chi[0] = hi[0] if i == n - 1 else lo[0] + (i + 1) * h[0]
        chi[1] = hi[1] if j == n - 1 else lo[1] + (j + 1) * h[1]
        chi[2] = hi[2] if k == n - 1 else lo[2] + (k + 1) * h[2]
        _top_cell(ops, lk, lr, ob, oe, clo, chi, lip, tol_area, g5x, g5w, g7x, g7w, cen,
                  rows[c], erows[c], srows[c])
    mom = np.zeros(10)
    err = np.zeros(10)
    diag = np.zeros(4)
    for c in range(ncell):
        for m in range(10):
            mom[m] += rows[c, m]
            err[m] += erows[c, m]
        diag[0] += srows[c, 0]
        diag[1] = max(diag[1], srows[c, 1])
        diag[2] += srows[c, 2]
        diag[3] = max(diag[3], srows[c, 3])
    return mom, err, diag


def _gauss01(q):
    x, w = np.polynomial.legendre.leggauss(q)
    return np.ascontiguousarray(0.5 * (x + 1.0)), np.ascontiguousarray(0.5 * w)


_G5 = _gauss01(5)
_G7 = _gauss01(7)


# ---------------------------------------------------------------------- Python API
@dataclass(frozen=True)
class BodyProperties:
    """Mass properties of a solid (all in the root's parent frame, user units).

    volume, mass (= density * volume), com (3,), inertia (3, 3) about the com (mass-weighted,
    density x volume integrals of (r^2 I - r r^T)), principal (3,) ascending moments, axes
    (3, 3) whose COLUMNS are the principal axes (a proper rotation, det +1), quat (x, y, z, w)
    of ``axes`` (the rotation taking principal-frame coordinates to the root's frame),
    volume_error and moment_error (absolute error estimates of volume and of any inertia
    entry/principal moment), diagnostics (dict).
    """

    volume: float
    mass: float
    density: float
    com: np.ndarray
    inertia: np.ndarray
    principal: np.ndarray
    axes: np.ndarray
    quat: np.ndarray
    volume_error: float
    moment_error: float
    diagnostics: dict = field(default_factory=dict)


def _check_box(lo, hi):
    lo_a = np.asarray(lo, dtype=np.float64).reshape(-1)
    hi_a = np.asarray(hi, dtype=np.float64).reshape(-1)
    if lo_a.size != 3 or not np.all(np.isfinite(lo_a)):
        raise ValueError(f"lo must be 3 finite numbers, got {lo!r}")
    if hi_a.size != 3 or not np.all(np.isfinite(hi_a)):
        raise ValueError(f"hi must be 3 finite numbers, got {hi!r}")
    if not np.all(hi_a > lo_a):
        raise ValueError(f"hi must exceed lo on every axis, got lo={lo_a.tolist()}, "
                         f"hi={hi_a.tolist()}")
    return lo_a, hi_a


def _check_faces(builder, root, lo, hi, m):
    """Raise unless phi >= 0 on an (m+1)^2 sample of every face of the box."""
    u = np.linspace(0.0, 1.0, m + 1)
    a, b = np.meshgrid(u, u, indexing="ij")
    a = a.ravel()
    b = b.ravel()
    pts = []
    for ax in range(3):
        o1, o2 = [k for k in range(3) if k != ax]
        for side in (lo[ax], hi[ax]):
            p = np.empty((a.size, 3))
            p[:, ax] = side
            p[:, o1] = lo[o1] + a * (hi[o1] - lo[o1])
            p[:, o2] = lo[o2] + b * (hi[o2] - lo[o2])
            pts.append(p)
    phi = builder.eval_root(root, np.concatenate(pts))
    if np.any(phi < 0.0):
        raise ValueError("box does not contain the solid: phi < 0 on its boundary "
                         f"(min phi {phi.min():.3g}); enlarge lo/hi")


def principal_axes(inertia, tol):
    """Ascending principal moments and a proper rotation whose columns are the axes.

    Deterministic axis choice: eigenvalues closer than ``tol`` form a cluster; within a
    cluster the basis is rotated onto the input axes (orthogonal Procrustes onto the
    coordinate axes that the cluster's subspace captures best), so a sphere or a cube gives
    the identity and a ring about y keeps x and z. A non-degenerate axis is signed so that its
    largest component is positive; the last non-degenerate axis then absorbs det = +1.
    """
    w, V = np.linalg.eigh(inertia)
    order = np.argsort(w, kind="stable")
    w = w[order]
    V = V[:, order]
    clusters = [[0]]
    for i in range(1, 3):
        if w[i] - w[clusters[-1][-1]] <= tol:
            clusters[-1].append(i)
        else:
            clusters.append([i])
    A = V.copy()
    free = []
    for cl in clusters:
        if len(cl) == 1:
            i = cl[0]
            col = A[:, i]
            if col[np.argmax(np.abs(col))] < 0.0:
                A[:, i] = -col
            free.append(i)
            continue
        Vc = V[:, cl]
        # coordinate axes best captured by the cluster's subspace, in index order
        capture = np.sum(Vc * Vc, axis=1)
        tgt = np.sort(np.argsort(-capture, kind="stable")[:len(cl)])
        T = np.eye(3)[:, tgt]
        U, _, Wt = np.linalg.svd(Vc.T @ T)
        A[:, cl] = Vc @ (U @ Wt)
    if np.linalg.det(A) < 0.0:
        i = free[-1] if free else 2
        A[:, i] = -A[:, i]
    return w, A


def body_properties(builder, root, lo, hi, density=1.0, n=16, tol=1e-7):
    """Mass properties of the solid ``phi < 0`` of ``root`` inside the box [lo, hi].

    Parameters
    ----------
    lo, hi : 3 finite numbers each, hi > lo; the box must contain the solid (phi >= 0 on its
        boundary, checked on a sample of the faces).
    density : > 0, mass per unit volume.
    n : int in [2, 4096], top-level cells per axis. Cut cells refine adaptively below it;
        a line is stepped at no more than 1/64 of its cell, so a feature thinner than that
        along the line could be missed (for 1-Lipschitz trees the step is ``max(|phi|,
        floor)``, and ``|phi|`` proves the skipped stretch empty).
    tol : in (0, 1e-3], the relative accuracy asked of the volume; cells refine until their
        error estimate is below ``tol * V_box * (d_cell / d_box)^2``.

    Only the SIGN of phi enters the integrand (gradients choose the height direction), so
    bound-only leaves (ellipsoid, superquadric, hollow_cylinder_shell) carry no bias; for them
    no cell can be skipped, so they cost more.
    """
    lo_a, hi_a = _check_box(lo, hi)
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 2 <= n <= 4096:
        raise ValueError(f"n (resolution) must be an integer in [2, 4096], got {n!r}")
    density = float(density)
    if not (math.isfinite(density) and density > 0.0):
        raise ValueError(f"density must be a finite number > 0, got {density!r}")
    tol = float(tol)
    if not (0.0 < tol <= 1e-3):
        raise ValueError(f"tol must be in (0, 1e-3], got {tol!r}")
    _check_faces(builder, root, lo_a, hi_a, max(2 * int(n), 16))
    prog = builder.program(root)
    lip = bool(builder.is_lipschitz(root))
    mom, err, diag = integrate_body(prog.ops, prog.leaf_kind, prog.leaf_reals, prog.op_begin,
                                    prog.op_end, lo_a, hi_a, int(n), lip, tol, *_G5, *_G7)
    if diag[3] != 0.0:
        raise ValueError(f"a line crossed the surface more than {MAX_ROOTS} times, or a cell "
                         f"had more than {MAX_BREAKS} breakpoints: the tree is pathological "
                         "for this box (or n is far too small)")
    vol = float(mom[0])
    if not vol > 0.0:
        raise ValueError("empty solid: no point of the box has phi < 0")
    cen = 0.5 * (lo_a + hi_a)
    d = mom[1:4] / vol                       # com relative to the box centre
    com = cen + d
    S = np.array([[mom[4], mom[7], mom[8]],
                  [mom[7], mom[5], mom[9]],
                  [mom[8], mom[9], mom[6]]])
    S_com = S - vol * np.outer(d, d)         # second moments about the com
    inertia = density * (np.trace(S_com) * np.eye(3) - S_com)
    # error propagation (first order, absolute)
    e_v = float(err[0])
    e_d = (np.abs(err[1:4]) + np.abs(d) * e_v) / vol
    e_S = max(err[4:10].max(), 0.0) + 2.0 * vol * np.max(np.abs(d)) * e_d.max() \
        + float(np.max(d * d)) * e_v
    e_I = density * 3.0 * e_S
    principal, axes = principal_axes(inertia, tol=max(1e-9 * abs(np.trace(inertia)), 10 * e_I))
    quat = matrix_to_quat(axes)
    return BodyProperties(volume=vol, mass=density * vol, density=density, com=com,
                          inertia=inertia, principal=principal, axes=axes, quat=quat,
                          volume_error=e_v, moment_error=float(e_I),
                          diagnostics={"cells": int(diag[0]), "max_depth": int(diag[1]),
                                       "unconverged_cells": int(diag[2]), "n": int(n),
                                       "tol": tol, "lipschitz": lip})


def principal_frame(builder, root, lo, hi, **kw):
    """(new_root, props): an exact copy of ``root`` whose frame is the principal frame.

    ``new_root = builder.add_reframed(root, translation=-A^T com, rotation=quat(A^T))`` with A
    = props.axes, so in the new root's parent frame the com is at the origin and the principal
    axes lie on x, y, z (ascending moments). A transform on a copied root, never a resample.
    ``kw`` goes to :func:`body_properties`.
    """
    props = body_properties(builder, root, lo, hi, **kw)
    At = props.axes.T
    new_root = builder.add_reframed(root, translation=-(At @ props.com),
                                    rotation=matrix_to_quat(At))
    return new_root, props
