"""Mass properties of a CSG solid by implicit quadrature (sign of phi only).

Method: nested 1-D integration, x outer, y middle, z inner (a Saye-style height-function
reduction taken one axis at a time; Saye, SIAM J. Sci. Comput. 37(2) A993, 2015).

- **Inner (z), exact.** Along a line (x, y, .) every root of phi in [zlo, zhi] is bracketed
  by sign and refined to ~1e-15 by safeguarded Newton (the analytic gradient) with bisection
  fallback. The inside runs between roots give the polynomial moments of 1, z, z^2 in closed
  form. Root isolation: for a 1-Lipschitz tree the step is ``max(|phi|, hmin)`` (``|phi|``
  proves the skipped stretch is free of roots: the certificate, one evaluation per empty
  stretch); otherwise a uniform ``hmin``. Between two same-sign samples whose directional
  derivative shows an extremum, the extremum is located (bisection on the derivative sign) so
  that a grazing line that clips the solid is not missed.
- **Middle (y) and outer (x), breakpoints + adaptive Gauss-Legendre.** The transverse
  integrands G(x, y) and F(x) are smooth except where the line's root structure changes
  (root count: tangencies, edges; or a crease is crossed: the root's normal jumps). Those
  points are found by sampling a uniform grid of ``n`` + 1 points and bisecting every interval
  whose end signatures differ (count change -> located to 1e-14 of the box; a normal jump that
  survives halving -> a crease, located to 1e-10). Each smooth piece [a, b] is mapped by
  ``t = a + (b - a)(3u^2 - 2u^3)``, which turns square-root endpoint behaviour (tangency) into
  an analytic integrand, and integrated by q-point Gauss-Legendre panels in u, each compared
  with its two halves; a panel whose difference exceeds the tolerance is split. For x, the
  signature is the number of y-breakpoints of the slice.
- **Error estimate.** Sum over accepted panels of |coarse - fine| (the reported value is the
  fine one), the inner levels' estimates integrated through, plus (jump bound) x (location
  tolerance) for every located breakpoint. It is an estimate, not a proof.

All hot loops are ``@njit(cache=True)`` kernels over the flat program arrays; the work order is
fixed, so results are bitwise reproducible.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from . import kernels as K
from .transforms import matrix_to_quat

#: Max roots along one line; more raises (a pathological tree or a far too coarse box).
MAX_ROOTS = 64
#: Gauss-Legendre points per panel (the panel is checked against its two halves).
GL_POINTS = 8

# moment indices of the 10 raw moments (coordinates relative to the box centre)
# 0: 1, 1: x, 2: y, 3: z, 4: xx, 5: yy, 6: zz, 7: xy, 8: xz, 9: yz


# ---------------------------------------------------------------------- inner: a line in z
@njit(cache=True)
def _ev(ops, lk, lr, ob, oe, x, y, z, st):
    return K.eval_point(ops, lk, lr, ob, oe, x, y, z, st)


@njit(cache=True)
def _refine_root(ops, lk, lr, ob, oe, x, y, a, fa, b, fb, tolz, st, out, k):
    """Root of phi(x, y, .) in [a, b] (fa, fb of opposite inside-sign). Writes z and the
    unit normal into out[k, 0:4]. Safeguarded Newton with bisection fallback."""
    # secant start: for a distance field it is already close to the root
    z = a - fa * (b - a) / (fb - fa)
    if not (a < z < b):
        z = 0.5 * (a + b)
    g = 0.0
    gx = 0.0
    gy = 0.0
    for _ in range(200):
        f, gx, gy, g = _ev(ops, lk, lr, ob, oe, x, y, z, st)
        if (f < 0.0) == (fa < 0.0):
            a = z
            fa = f
        else:
            b = z
            fb = f
        if b - a <= tolz:
            break
        zn = z - f / g if g != 0.0 else 0.5 * (a + b)
        # Newton only while it stays well inside the bracket; else bisect
        if not (a < zn < b) or not (zn == zn):
            zn = 0.5 * (a + b)
        if abs(zn - z) <= 0.5 * tolz:
            z = zn
            break
        z = zn
    zr = 0.5 * (a + b) if b - a <= tolz else z
    nn = math.sqrt(gx * gx + gy * gy + g * g)
    if nn == 0.0:
        nn = 1.0
    out[k, 0] = zr
    out[k, 1] = gx / nn
    out[k, 2] = gy / nn
    out[k, 3] = g / nn


@njit(cache=True)
def _extremum(ops, lk, lr, ob, oe, x, y, a, b, s, tolx, lip, st):
    """Locate the extremum of phi(x, y, .) in [a, b] where s*dphi/dz goes - -> +; returns
    (z, phi)."""
    fa = abs(_ev(ops, lk, lr, ob, oe, x, y, a, st)[0])
    fb = abs(_ev(ops, lk, lr, ob, oe, x, y, b, st)[0])
    for _ in range(80):
        # 1-Lipschitz: no zero in [a, b] once |fa| + |fb| > b - a
        if lip and fa + fb > b - a:
            break
        m = 0.5 * (a + b)
        f, gx, gy, gz = _ev(ops, lk, lr, ob, oe, x, y, m, st)
        if (f < 0.0) != (s < 0.0):
            return m, f
        if s * gz < 0.0:
            a = m
            fa = abs(f)
        else:
            b = m
            fb = abs(f)
        if b - a <= tolx:
            break
    m = 0.5 * (a + b)
    f, gx, gy, gz = _ev(ops, lk, lr, ob, oe, x, y, m, st)
    return m, f


@njit(cache=True)
def _line(ops, lk, lr, ob, oe, x, y, zlo, zhi, hmin, lip, tolz, st, roots):
    """All sign changes of phi along (x, y, zlo..zhi); roots[k] = (z, nx, ny, nz).

    Returns the number of roots (a leading negative sample counts as a root at zlo)."""
    nr = 0
    z0 = zlo
    f0, gx, gy, g0 = _ev(ops, lk, lr, ob, oe, x, y, z0, st)
    if f0 < 0.0:
        roots[0, 0] = zlo
        roots[0, 1] = 0.0
        roots[0, 2] = 0.0
        roots[0, 3] = -1.0
        nr = 1
    while z0 < zhi:
        step = hmin
        if lip and abs(f0) > step:
            step = abs(f0)
        z1 = z0 + step
        if z1 > zhi:
            z1 = zhi
        f1, gx, gy, g1 = _ev(ops, lk, lr, ob, oe, x, y, z1, st)
        if (f0 < 0.0) != (f1 < 0.0):
            if nr >= MAX_ROOTS:
                return -1
            _refine_root(ops, lk, lr, ob, oe, x, y, z0, f0, z1, f1, tolz, st, roots, nr)
            nr += 1
        else:
            s = 1.0 if f0 >= 0.0 else -1.0
            # |phi| falls then rises inside the step and could reach zero: look at the extremum
            reach = (abs(f0) + abs(f1) if lip else min(abs(f0), abs(f1))) < (z1 - z0)
            if s * g0 < 0.0 and s * g1 > 0.0 and reach:
                # a sliver thinner than ~1e6 tolz is below any moment we report
                zm, fm = _extremum(ops, lk, lr, ob, oe, x, y, z0, z1, s, 1e6 * tolz, lip, st)
                if (fm < 0.0) != (f0 < 0.0):
                    if nr + 2 > MAX_ROOTS:
                        return -1
                    _refine_root(ops, lk, lr, ob, oe, x, y, z0, f0, zm, fm, tolz, st, roots, nr)
                    _refine_root(ops, lk, lr, ob, oe, x, y, zm, fm, z1, f1, tolz, st, roots,
                                 nr + 1)
                    nr += 2
        z0 = z1
        f0 = f1
        g0 = g1
    if f0 < 0.0:
        if nr >= MAX_ROOTS:
            return -1
        roots[nr, 0] = zhi
        roots[nr, 1] = 0.0
        roots[nr, 2] = 0.0
        roots[nr, 3] = 1.0
        nr += 1
    return nr


@njit(cache=True)
def _z_moments(roots, nr, out):
    """Closed-form moments of 1, z, z^2 over the inside runs [roots[0], roots[1]], ..."""
    out[0] = 0.0
    out[1] = 0.0
    out[2] = 0.0
    for k in range(0, nr - 1, 2):
        a = roots[k, 0]
        b = roots[k + 1, 0]
        out[0] += b - a
        out[1] += 0.5 * (b - a) * (b + a)
        out[2] += (b - a) * (b * b + a * b + a * a) / 3.0


# ---------------------------------------------------------------------- breakpoint search
@njit(cache=True)
def _normal_jump(nrm, i, j, nr):
    """max over roots of |n_i - n_j| (roots matched in order)."""
    jm = 0.0
    for r in range(nr):
        dx = nrm[i, 4 * r + 1] - nrm[j, 4 * r + 1]
        dy = nrm[i, 4 * r + 2] - nrm[j, 4 * r + 2]
        dz = nrm[i, 4 * r + 3] - nrm[j, 4 * r + 3]
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        if d > jm:
            jm = d
    return jm


#: a normal jump above this between neighbouring samples is examined as a possible crease
KINK_TAU = 0.05
#: a crease keeps >= this fraction of its parent's jump in one half; smooth bending halves it
KINK_KEEP = 0.8


@njit(cache=True)
def _store_line(ops, lk, lr, ob, oe, x, y, zlo, zhi, hmin, lip, tolz, st, roots, ys, cnt, nrm,
                ns):
    """Solve the line at (x, y), append its signature as sample ``ns``; return new arrays."""
    if ns >= ys.shape[0]:
        cap = 2 * ys.shape[0]
        ys2 = np.empty(cap)
        ys2[:ns] = ys[:ns]
        cnt2 = np.empty(cap, np.int64)
        cnt2[:ns] = cnt[:ns]
        nrm2 = np.empty((cap, nrm.shape[1]))
        nrm2[:ns] = nrm[:ns]
        ys, cnt, nrm = ys2, cnt2, nrm2
    nr = _line(ops, lk, lr, ob, oe, x, y, zlo, zhi, hmin, lip, tolz, st, roots)
    ys[ns] = y
    cnt[ns] = nr
    for r in range(max(nr, 0)):
        for c in range(4):
            nrm[ns, 4 * r + c] = roots[r, c]
    return ys, cnt, nrm


@njit(cache=True)
def _slice_breaks(ops, lk, lr, ob, oe, x, lo, hi, n, hmin, lip, tolz, dcount, dkink, st,
                  roots):
    """Breakpoints in y of the slice at x: sorted array including lo[1] and hi[1].

    Returns (breaks, ok) with ok False if a line had more than MAX_ROOTS roots."""
    cap = 4 * (n + 1) + 64
    ys = np.empty(cap)
    cnt = np.empty(cap, np.int64)
    nrm = np.empty((cap, 4 * MAX_ROOTS))
    ns = 0
    ylo = lo[1]
    yhi = hi[1]
    for i in range(n + 1):
        y = ylo + (yhi - ylo) * i / n
        ys, cnt, nrm = _store_line(ops, lk, lr, ob, oe, x, y, lo[2], hi[2], hmin, lip, tolz,
                                   st, roots, ys, cnt, nrm, ns)
        ns += 1
    ok = True
    for i in range(n + 1):
        if cnt[i] < 0:
            ok = False
    brk = [ylo]
    # stack of (ia, ib, parent jump)
    sa = [0]
    sb = [0]
    sj = [0.0]
    sa.pop()
    sb.pop()
    sj.pop()
    for i in range(n, 0, -1):
        sa.append(i - 1)
        sb.append(i)
        sj.append(np.inf)
    while len(sa) > 0:
        ia = sa.pop()
        ib = sb.pop()
        pj = sj.pop()
        a = ys[ia]
        b = ys[ib]
        count_ev = cnt[ia] != cnt[ib]
        jump = 0.0
        kink_ev = False
        if not count_ev and cnt[ia] > 0:
            jump = _normal_jump(nrm, ia, ib, cnt[ia])
            kink_ev = jump > KINK_TAU and (pj == np.inf or jump > KINK_KEEP * pj)
        if not count_ev and not kink_ev:
            continue
        if (count_ev and b - a <= dcount) or (not count_ev and b - a <= dkink):
            brk.append(0.5 * (a + b))
            continue
        m = 0.5 * (a + b)
        ys, cnt, nrm = _store_line(ops, lk, lr, ob, oe, x, m, lo[2], hi[2], hmin, lip, tolz,
                                   st, roots, ys, cnt, nrm, ns)
        if cnt[ns] < 0:
            ok = False
        im = ns
        ns += 1
        nj = jump if kink_ev else np.inf
        sa.append(im)
        sb.append(ib)
        sj.append(nj)
        sa.append(ia)
        sb.append(im)
        sj.append(nj)
    brk.append(yhi)
    out = np.sort(np.array(brk))
    # merge coincident breakpoints
    keep = [out[0]]
    for i in range(1, len(out)):
        if out[i] - keep[-1] > dcount:
            keep.append(out[i])
        elif i == len(out) - 1:
            keep[-1] = out[i]
    return np.array(keep), ok, ns


# ---------------------------------------------------------------------- adaptive pieces
@njit(cache=True)
def _smooth_map(a, b, u):
    """t(u) = a + (b - a)(3u^2 - 2u^3) and dt/du: square-root ends become analytic."""
    return a + (b - a) * u * u * (3.0 - 2.0 * u), (b - a) * 6.0 * u * (1.0 - u)


@njit(cache=True)
def _y_integrand(ops, lk, lr, ob, oe, x, y, cy, zlo, zhi, hmin, lip, tolz, st, roots, zm, out):
    """The 6 slice moments' integrand at (x, y): m0, y m0, y^2 m0, m1, y m1, m2 (centred)."""
    nr = _line(ops, lk, lr, ob, oe, x, y, zlo, zhi, hmin, lip, tolz, st, roots)
    if nr < 0:
        return False
    _z_moments(roots, nr, zm)
    yc = y - cy
    out[0] = zm[0]
    out[1] = yc * zm[0]
    out[2] = yc * yc * zm[0]
    out[3] = zm[1]
    out[4] = yc * zm[1]
    out[5] = zm[2]
    return True


@njit(cache=True)
def _slice(ops, lk, lr, ob, oe, x, lo, hi, cen, n, hmin, lip, tolz, dcount, dkink, tol, gx,
           gw, st, roots, res):
    """Integrate the slice at x over (y, z); res[0:6] moments (z relative to cen[2] handled by
    the caller through shifted z limits), res[6] error estimate, res[7] breakpoint count.
    Returns False on failure (too many roots)."""
    brk, ok, _ = _slice_breaks(ops, lk, lr, ob, oe, x, lo, hi, n, hmin, lip, tolz, dcount,
                               dkink, st, roots)
    q = gx.shape[0]
    for c in range(8):
        res[c] = 0.0
    zm = np.empty(3)
    val = np.empty(6)
    coarse = np.empty(6)
    fine = np.empty(6)
    half = np.empty(6)
    scale = np.empty(6)
    ey = 0.5 * (hi[1] - lo[1])
    ez = 0.5 * (hi[2] - lo[2])
    scale[0] = ez
    scale[1] = ez * ey
    scale[2] = ez * ey * ey
    scale[3] = ez * ez
    scale[4] = ez * ez * ey
    scale[5] = ez * ez * ez
    # a located count breakpoint may hide a jump of at most 2*ez in m0, over dcount
    res[6] += (len(brk) - 2) * dcount * 2.0 * ez * 4.0
    for p in range(len(brk) - 1):
        a = brk[p]
        b = brk[p + 1]
        # explicit stack of u-panels; each carries its coarse value
        pu0 = [0.0]
        pu1 = [1.0]
        pco = [np.zeros(6)]
        pfl = [False]
        while len(pu0) > 0:
            u0 = pu0.pop()
            u1 = pu1.pop()
            cv = pco.pop()
            have = pfl.pop()
            if have:
                for c in range(6):
                    coarse[c] = cv[c]
            else:
                for c in range(6):
                    coarse[c] = 0.0
                for k in range(q):
                    u = u0 + (u1 - u0) * gx[k]
                    t, dt = _smooth_map(a, b, u)
                    if not _y_integrand(ops, lk, lr, ob, oe, x, t, cen[1], lo[2], hi[2], hmin,
                                        lip, tolz, st, roots, zm, val):
                        ok = False
                    w = gw[k] * (u1 - u0) * dt
                    for c in range(6):
                        coarse[c] += w * val[c]
            hl = np.zeros(6)
            hr = np.zeros(6)
            um = 0.5 * (u0 + u1)
            for side in range(2):
                v0 = u0 if side == 0 else um
                v1 = um if side == 0 else u1
                for c in range(6):
                    half[c] = 0.0
                for k in range(q):
                    u = v0 + (v1 - v0) * gx[k]
                    t, dt = _smooth_map(a, b, u)
                    if not _y_integrand(ops, lk, lr, ob, oe, x, t, cen[1], lo[2], hi[2], hmin,
                                        lip, tolz, st, roots, zm, val):
                        ok = False
                    w = gw[k] * (v1 - v0) * dt
                    for c in range(6):
                        half[c] += w * val[c]
                for c in range(6):
                    if side == 0:
                        hl[c] = half[c]
                    else:
                        hr[c] = half[c]
            err = 0.0
            for c in range(6):
                fine[c] = hl[c] + hr[c]
                e = abs(fine[c] - coarse[c]) / scale[c]
                if e > err:
                    err = e
            width = (b - a) * (u1 - u0)
            if err <= tol * width / (hi[1] - lo[1]) or u1 - u0 < 1e-12:
                for c in range(6):
                    res[c] += fine[c]
                res[6] += err * scale[0]
            else:
                pu0.append(um)
                pu1.append(u1)
                pco.append(hr)
                pfl.append(True)
                pu0.append(u0)
                pu1.append(um)
                pco.append(hl)
                pfl.append(True)
    res[7] = len(brk)
    return ok


@njit(cache=True)
def _slice_sig(ops, lk, lr, ob, oe, x, lo, hi, n, hmin, lip, tolz, dcount, dkink, st, roots):
    brk, ok, _ = _slice_breaks(ops, lk, lr, ob, oe, x, lo, hi, n, hmin, lip, tolz, dcount,
                               dkink, st, roots)
    return len(brk) if ok else -1


@njit(cache=True)
def _x_integrand(ops, lk, lr, ob, oe, x, lo, hi, cen, n, hmin, lip, tolz, dcount, dkink, tol,
                 gx, gw, st, roots, sres, out):
    """10 raw moments' integrand at x (centred) and the slice's error estimate in out[10]."""
    ok = _slice(ops, lk, lr, ob, oe, x, lo, hi, cen, n, hmin, lip, tolz, dcount, dkink, tol, gx,
                gw, st, roots, sres)
    xc = x - cen[0]
    # sres (y centred, z raw): m0, y m0, y2 m0, z1, y z1, z2 ; shift z to centred
    cz = cen[2]
    m0 = sres[0]
    ym0 = sres[1]
    yym0 = sres[2]
    z1 = sres[3] - cz * m0
    yz1 = sres[4] - cz * ym0
    z2 = sres[5] - 2.0 * cz * sres[3] + cz * cz * m0
    out[0] = m0
    out[1] = xc * m0
    out[2] = ym0
    out[3] = z1
    out[4] = xc * xc * m0
    out[5] = yym0
    out[6] = z2
    out[7] = xc * ym0
    out[8] = xc * z1
    out[9] = yz1
    out[10] = sres[6]
    return ok


@njit(cache=True)
def integrate_body(ops, lk, lr, ob, oe, lo, hi, n, lip, tol):
    """Raw moments (10,) about the box centre, their error estimates (10,), and diagnostics
    (evaluations are not counted; (pieces, panels, x-breakpoints, ok))."""
    st = np.empty((K.MAX_STACK, 4))
    roots = np.empty((MAX_ROOTS + 2, 4))
    cen = 0.5 * (lo + hi)
    ext = np.max(hi - lo)
    hmin = np.min(hi - lo) / (2.0 * n)
    tolz = 1e-15 * ext
    dcount = 1e-14 * ext
    dkink = 1e-10 * ext
    q = GL_POINTS
    gx, gw = _gauss(q)
    sres = np.empty(8)
    # x signatures on the coarse grid, then bisection to breakpoints
    xs = [lo[0] + (hi[0] - lo[0]) * i / n for i in range(n + 1)]
    sg = [_slice_sig(ops, lk, lr, ob, oe, xs[i], lo, hi, n, hmin, lip, tolz, dcount, dkink, st,
                     roots) for i in range(n + 1)]
    ok = True
    for v in sg:
        if v < 0:
            ok = False
    brk = [lo[0]]
    sa = [0.0]
    sb = [0.0]
    fa = [0]
    fb = [0]
    sa.pop()
    sb.pop()
    fa.pop()
    fb.pop()
    for i in range(n, 0, -1):
        if sg[i - 1] != sg[i]:
            sa.append(xs[i - 1])
            sb.append(xs[i])
            fa.append(sg[i - 1])
            fb.append(sg[i])
    while len(sa) > 0:
        a = sa.pop()
        b = sb.pop()
        ga = fa.pop()
        gb = fb.pop()
        if b - a <= dcount:
            brk.append(0.5 * (a + b))
            continue
        m = 0.5 * (a + b)
        gm = _slice_sig(ops, lk, lr, ob, oe, m, lo, hi, n, hmin, lip, tolz, dcount, dkink, st,
                        roots)
        if gm < 0:
            ok = False
        if gm != gb:
            sa.append(m)
            sb.append(b)
            fa.append(gm)
            fb.append(gb)
        if gm != ga:
            sa.append(a)
            sb.append(m)
            fa.append(ga)
            fb.append(gm)
    brk.append(hi[0])
    xb = np.sort(np.array(brk))
    keep = [xb[0]]
    for i in range(1, len(xb)):
        if xb[i] - keep[-1] > dcount:
            keep.append(xb[i])
        elif i == len(xb) - 1:
            keep[-1] = xb[i]
    mom = np.zeros(10)
    err = np.zeros(10)
    val = np.empty(11)
    coarse = np.empty(11)
    half = np.empty(11)
    ex = 0.5 * (hi[0] - lo[0])
    ey = 0.5 * (hi[1] - lo[1])
    ez = 0.5 * (hi[2] - lo[2])
    vol_box = 8.0 * ex * ey * ez
    scale = np.empty(10)
    scale[0] = vol_box
    scale[1] = vol_box * ex
    scale[2] = vol_box * ey
    scale[3] = vol_box * ez
    scale[4] = vol_box * ex * ex
    scale[5] = vol_box * ey * ey
    scale[6] = vol_box * ez * ez
    scale[7] = vol_box * ex * ey
    scale[8] = vol_box * ex * ez
    scale[9] = vol_box * ey * ez
    # a located x breakpoint may hide a jump of F of at most the box's cross-section
    loc = (len(keep) - 2) * dcount * 8.0 * ey * ez
    panels = 0
    for p in range(len(keep) - 1):
        a = keep[p]
        b = keep[p + 1]
        pu0 = [0.0]
        pu1 = [1.0]
        pco = [np.zeros(11)]
        pfl = [False]
        while len(pu0) > 0:
            u0 = pu0.pop()
            u1 = pu1.pop()
            cv = pco.pop()
            have = pfl.pop()
            if have:
                for c in range(11):
                    coarse[c] = cv[c]
            else:
                for c in range(11):
                    coarse[c] = 0.0
                for k in range(q):
                    u = u0 + (u1 - u0) * gx[k]
                    t, dt = _smooth_map(a, b, u)
                    if not _x_integrand(ops, lk, lr, ob, oe, t, lo, hi, cen, n, hmin, lip, tolz,
                                        dcount, dkink, tol, gx, gw, st, roots, sres, val):
                        ok = False
                    w = gw[k] * (u1 - u0) * dt
                    for c in range(11):
                        coarse[c] += w * val[c]
            hl = np.zeros(11)
            hr = np.zeros(11)
            um = 0.5 * (u0 + u1)
            for side in range(2):
                v0 = u0 if side == 0 else um
                v1 = um if side == 0 else u1
                for c in range(11):
                    half[c] = 0.0
                for k in range(q):
                    u = v0 + (v1 - v0) * gx[k]
                    t, dt = _smooth_map(a, b, u)
                    if not _x_integrand(ops, lk, lr, ob, oe, t, lo, hi, cen, n, hmin, lip, tolz,
                                        dcount, dkink, tol, gx, gw, st, roots, sres, val):
                        ok = False
                    w = gw[k] * (v1 - v0) * dt
                    for c in range(11):
                        half[c] += w * val[c]
                if side == 0:
                    hl[:] = half
                else:
                    hr[:] = half
            e_rel = 0.0
            for c in range(10):
                e = abs(hl[c] + hr[c] - coarse[c]) / scale[c]
                if e > e_rel:
                    e_rel = e
            width = (b - a) * (u1 - u0)
            if e_rel <= tol * width / (hi[0] - lo[0]) or u1 - u0 < 1e-12:
                panels += 1
                for c in range(10):
                    mom[c] += hl[c] + hr[c]
                    # panel difference + inner estimates (integrated, in m0 units)
                    err[c] += (abs(hl[c] + hr[c] - coarse[c])
                               + (hl[10] + hr[10]) * scale[c] / scale[0])
            else:
                pu0.append(um)
                pu1.append(u1)
                pco.append(hr)
                pfl.append(True)
                pu0.append(u0)
                pu1.append(um)
                pco.append(hl)
                pfl.append(True)
    for c in range(10):
        err[c] += loc * scale[c] / scale[0]
    diag = np.array([len(keep) - 1.0, float(panels), len(keep) - 2.0, 1.0 if ok else 0.0])
    return mom, err, diag


@njit(cache=True)
def _gauss(q):
    """Gauss-Legendre nodes on [0, 1] and weights (Newton on the Legendre recurrence)."""
    x = np.empty(q)
    w = np.empty(q)
    for i in range(q):
        t = math.cos(math.pi * (i + 0.75) / (q + 0.5))
        for _ in range(100):
            p0 = 1.0
            p1 = t
            for k in range(2, q + 1):
                p0, p1 = p1, ((2 * k - 1) * t * p1 - (k - 1) * p0) / k
            dp = q * (t * p1 - p0) / (t * t - 1.0)
            dt = p1 / dp
            t -= dt
            if abs(dt) < 1e-16:
                break
        p0 = 1.0
        p1 = t
        for k in range(2, q + 1):
            p0, p1 = p1, ((2 * k - 1) * t * p1 - (k - 1) * p0) / k
        dp = q * (t * p1 - p0) / (t * t - 1.0)
        x[i] = 0.5 * (1.0 - t)
        w[i] = 1.0 / ((1.0 - t * t) * dp * dp)
    return x, w


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


def body_properties(builder, root, lo, hi, density=1.0, n=16, tol=1e-13):
    """Mass properties of the solid ``phi < 0`` of ``root`` inside the box [lo, hi].

    Parameters
    ----------
    lo, hi : 3 finite numbers each, hi > lo; the box must contain the solid (phi >= 0 on its
        boundary, checked on a sample of the faces).
    density : > 0, mass per unit volume.
    n : int >= 2, the resolution knob: initial samples per axis for locating breakpoints, and
        the line step floor ``min(hi - lo) / (2n)``. Features thinner than that floor may be
        missed by a line (for 1-Lipschitz trees the step is ``max(|phi|, floor)``).
    tol : in (0, 1e-3], the panel acceptance tolerance relative to the box scale.

    Only the SIGN of phi enters the integrand (gradients steer Newton and detect creases), so
    bound-only leaves (ellipsoid, superquadric, hollow_cylinder_shell) carry no bias.
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
                                    prog.op_end, lo_a, hi_a, int(n), lip, tol)
    if diag[3] == 0.0:
        raise ValueError(f"a line crossed the surface more than {MAX_ROOTS} times: the tree "
                         "is pathological for this box")
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
                          diagnostics={"x_pieces": int(diag[0]), "x_panels": int(diag[1]),
                                       "x_breakpoints": int(diag[2]), "n": int(n),
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
