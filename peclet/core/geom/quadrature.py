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
  which over-estimates the q = 7 error wherever the rule converges (plus a few ulps of the
  cell for the round-off of its roots). Refinement is global: while the estimates, measured
  against the solid's own volume and second moments, add up to more than ``tol``, the cells
  with the largest are split into 8 (down to ``MAX_DEPTH`` levels). The estimates of all
  accepted cells add up to the reported error.
- **Missed structure.** A vertex of the solid poking into a cell between the probe lines
  leaves no trace in the rule; in a cell the certificate cannot decide whose rule found no
  surface, Newton projections from the centre and the octant centres look for it, and a
  cell found to hold surface that way is split. A wedge thinning towards a vertex is
  followed by its extrapolated midpoints while a u-breakpoint is bisected, and the bracket's
  lower end is probed again with the upper end's pieces.

The work is parallel over the cells of each refinement pass, each writing its own row, and
the rows are summed in a fixed order: results are bitwise identical at any thread count.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit, prange

from . import kernels as K
from .transforms import matrix_to_quat

#: Max roots along one line, knots and breakpoints across one cell (a scratch row each).
MAX_BREAKS = 128
#: Rows of the per-thread scratch S: line roots and their features, knot search roots and
#: features, v-knots, v-breaks and their tangency flags, u-knots, u-breaks and flags, extra
#: v-probes, piece midpoints carried from neighbouring u (two ends, the next probe and the
#: u-piece's centre), the ends' previous midpoints, two rows for extrapolated midpoints, and
#: the midpoints at a bracket's start.
(R_ROOT, R_LEAF, R_KROOT, R_KLEAF, R_VKNOT, R_VBRK, R_VFLAG, R_UKNOT, R_UBRK, R_UFLAG, R_EXTRA,
 R_MLO, R_MHI, R_MY, R_MC, R_MLP, R_MHP, R_XP, R_XT, R_MX) = range(20)
SCRATCH_ROWS = 20
#: A line search resolves pairs of roots down to LINE_EPS of the line (stack of halvings).
LINE_EPS = 1e-10
LINE_STACK = 64
#: ``lip`` (passed down every kernel) is 0 for a tree that is not 1-Lipschitz, else the cap on
#: certifying halvings per line (see _line): LINE_EXTRA when tol < CERTIFY_TOL, else
#: LINE_EXTRA_LOOSE. A capped line may miss a pair of roots narrower than a step; measured on
#: the Pall ring (against its exact volume) that costs 3e-10 relative at the loose cap, and
#: the full cap costs 4x the time.
LINE_EXTRA = 1024
LINE_EXTRA_LOOSE = 64
CERTIFY_TOL = 1e-8
#: A step left unproved is searched for an extremum of the other sign (see _dip): at most
#: DIP_STEPS evaluations each, DIP_BUDGET per line.
DIP_STEPS = 30
DIP_BUDGET = 256
#: Breaks closer than FLICKER (of the cell) to the previous one are a signature flickering at a
#: tangency, not structure: they are stepped over.
FLICKER = 1e-10
#: Structure is probed this far (of the cell) inside each knot segment: right at a knot a new
#: piece is thinner than the level below resolves, and probing there would only find it again
#: by bisection. Only where to look moves; pieces still start at the exact knots.
V_NUDGE = 1e-11
U_NUDGE = 1e-9
#: v-probes remembered per u-piece from the scan (see _cell_rules).
SEEDS = 32
#: Levels of refinement below the top cells.
MAX_DEPTH = 8
#: Signature probes across a cell (intervals).
V_PROBES = 4
#: Bisection steps locating a breakpoint of the inner integrand (2^-44 of the cell): it may
#: jump there (a wall parallel to the height axis), so the location must be sharp.
BREAK_STEPS = 44
#: ... but past KINK_STEPS a bracket across which the line's inside length changes by less than
#: KINK_SLOPE x its width holds a kink (or a jump of that size), whose misplacement costs only
#: O(width^2): the bisection stops there.
KINK_STEPS = 20
KINK_SLOPE = 1e3
#: ... and of the outer integrand (2^-30 of the probe interval): it jumps only at a wall normal to
#: u, whose trace on the cell's edges is a u-knot, found exactly, unless the wall ends inside.
U_BREAK_STEPS = 30
#: While locating a u-breakpoint only the v-structure (the sequence of piece signatures)
#: matters, not where its breaks sit: its v-bisections stop at 2^-HASH_STEPS.
HASH_STEPS = 12
#: ... but inside a u-bisection the v-pieces seen are the probes of the next step, and a
#: piece thinning to a vertex is followed only while its midpoint is sharper than its width.
TRACK_STEPS = 24
#: Re-probes of a bisected u-break's upper end per probe interval (see _cell_rules); a cell
#: that overflows with them is integrated again without.
U_REPROBES = 4
#: u-breaks closer than this to the previous one are flicker (4 u-bisection resolutions).
U_FLICKER = 4.0 / (V_PROBES * 2.0 ** U_BREAK_STEPS)
#: More than U_ZONE_BREAKS breaks in a row each closer than U_ZONE (of the cell) to the one
#: before are a flicker zone, not structure (see _cell_rules). A thin torus gave a steady run
#: of breaks 2^-20 of the cell apart, just over the first threshold tried; a real break the
#: zone steps over leaves a kink inside a u-piece, which its rules' estimate then reports.
U_ZONE = 2.0 ** -16
U_ZONE_BREAKS = 2
#: ... and a zone's step-over doubles up to U_ZONE_MAX (of the cell). Where two break curves
#: of the v-structure touch (the outline of a rim tangent to the outline of its wall), the
#: piece between them is thinner than any resolution over a stretch of u: its flicker zone can
#: be far wider than U_ZONE.
U_ZONE_MAX = 2.0 ** -12
#: Newton projection onto the surface (see _surface_in_cell): steps, and |phi| (of the cell)
#: at which it has arrived.
PROJECT_STEPS = 12
PROJECT_EPS = 1e-12
#: A cell's rule "saw surface" when its volume is this far (relative) from empty and full.
SURFACE_FRAC = 1e-12
#: Round-off carried by a cut cell's moments, in ulps of its moment bound (see
#: integrate_cells).
ROUND_ULPS = 16.0
EPS = 2.220446049250313e-16

# moment indices of the 10 raw moments (coordinates relative to the box centre)
# 0: 1, 1: x, 2: y, 3: z, 4: xx, 5: yy, 6: zz, 7: xy, 8: xz, 9: yz


@njit(cache=True)
def _phi_d(P, ak, u, v, t, iu, iv, st):
    """(phi, d phi / d t) at the point with coordinate t on axis ak, u on axis iu and v on
    axis iv. ``P`` is the program tuple (ops, leaf_kind, leaf_reals, op_begin, op_end)."""
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
    f, g0, g1, g2 = K.eval_point(P[0], P[1], P[2], P[3], P[4], p0, p1, p2, st)
    if ak == 0:
        return f, g0
    if ak == 1:
        return f, g1
    return f, g2


@njit(cache=True, inline="always")
def _phi(P, ak, u, v, t, iu, iv, st):
    """phi at the point with coordinate t on axis ak (see :func:`_phi_d`)."""
    return _phi_d(P, ak, u, v, t, iu, iv, st)[0]


@njit(cache=True)
def _refine(P, ak, iu, iv, u, v, a, fa, b, fb, st):
    """A root of phi in [a, b] (fa, fb of opposite signs) to round-off.

    Safeguarded Newton along the line (the evaluator returns the gradient with phi): a Newton
    step is taken when it stays inside the bracket and the previous one at least halved |phi|,
    a bisection otherwise, so the bracket always shrinks and a crease inside it (where the
    derivative jumps) costs at most a bisection's worth of steps. Starts at the secant point.
    Returns (root, active leaf feature at the root)."""
    x = (a * fb - b * fa) / (fb - fa)
    if not (a < x < b):
        x = 0.5 * (a + b)
    fprev = math.inf
    for _ in range(200):
        f, d = _phi_d(P, ak, u, v, x, iu, iv, st)
        if f == 0.0:
            return x, st[0, 4]
        if (f < 0.0) == (fa < 0.0):
            a = x
            fa = f
        else:
            b = x
            fb = f
        eps = 4e-16 * (abs(a) + abs(b)) + 1e-300
        if b - a <= eps:
            break
        step = -f / d if d != 0.0 else math.inf
        xn = x + step
        if a < xn < b and abs(step) <= eps:
            return x, st[0, 4]              # converged: the next step is round-off
        if a < xn < b and abs(f) <= 0.5 * fprev:
            x = xn
        else:
            x = 0.5 * (a + b)
        fprev = abs(f)
    r = 0.5 * (a + b)
    _phi(P, ak, u, v, r, iu, iv, st)
    return r, st[0, 4]


@njit(cache=True)
def _add_root(P, ak, iu, iv, u, v, x, fx, y, fy, st, roots, leaves, r0, nr, eps):
    """Refine the root in [x, y] (fx, fy of opposite signs) and append it to roots/leaves
    after slot r0 + nr; a root within ``eps`` of the previous one annihilates with it (a
    grazing pair, or round-off noise at a tangency: the run between them carries no
    measurable length). Returns the new count, -1 on overflow."""
    if r0 + nr >= roots.shape[0]:
        return -1
    r, lf = _refine(P, ak, iu, iv, u, v, x, fx, y, fy, st)
    if nr > 0 and r - roots[r0 + nr - 1] <= eps:
        return nr - 1
    roots[r0 + nr] = r
    leaves[r0 + nr] = lf
    return nr + 1


@njit(cache=True)
def _dip(P, ak, iu, iv, u, v, x, fx, dx, y, fy, dy, st, eps):
    """Search [x, y], whose ends have the same sign and slopes pointing at an extremum
    inside (phi falling then rising outside the solid, the reverse inside), for a point of
    the other sign: regula falsi on d phi / dt (a tangency's phi is locally a parabola, so
    one or two steps land on its extremum). Returns (t, phi(t), evaluations); phi(t) has
    fx's sign when none was found within DIP_STEPS evaluations."""
    sgn = 1.0 if fx >= 0.0 else -1.0
    p = x
    dp = sgn * dx
    q = y
    dq = sgn * dy
    t = x
    f = fx
    tprev = math.inf
    n = 0
    while n < DIP_STEPS:
        t = p - dp * (q - p) / (dq - dp)
        if not (p < t < q) or n % 4 == 3:
            t = 0.5 * (p + q)       # a bisection every fourth step: the bracket shrinks
        if abs(t - tprev) <= eps:
            break                   # converged on the extremum
        f, d = _phi_d(P, ak, u, v, t, iu, iv, st)
        n += 1
        if (f < 0.0) != (fx < 0.0):
            break
        if sgn * d < 0.0:
            p = t
            dp = sgn * d
        else:
            q = t
            dq = sgn * d
        if q - p <= eps:
            break
        tprev = t
    return t, f, n


@njit(cache=True)
def _line(P, ak, iu, iv, u, v, a, b, lip, st, roots, leaves, r0):
    """Roots of phi along axis ak over [a, b] at (u, v), written to roots/leaves from slot r0.

    Returns (count, starts_inside); count = -1 on overflow. Steps are ``max(|phi|, (b-a)/64)``.
    On a 1-Lipschitz tree a step [x, y] with no sign change is *proved* root-free when
    ``|phi(x)| + |phi(y)| > y - x`` (a root s would need |phi(x)| <= s - x and |phi(y)| <= y - s);
    otherwise a run of the other sign hidden in it is at most ``(y - x) - |phi(x)| - |phi(y)|``
    long, and the step is bisected until that bound is below ``LINE_EPS (b - a)``. Two roots
    closer than that annihilate (see _add_root). The halvings are capped at ``lip``
    evaluations per line: a line running at depth d past a tangency with a surface of radius
    R would need ~sqrt(R / d) of them. A step left unproved (past the cap; every step of a
    tree that is not 1-Lipschitz) whose end slopes point at an extremum inside is searched
    for it (:func:`_dip`, at most DIP_BUDGET evaluations per line), so the short run of a
    near-tangent line is still found: without that, whether it is seen would depend on where
    the cap falls, and the line structure would flicker across a whole band of lines."""
    hmin = (b - a) / 64.0
    eps = LINE_EPS * (b - a)
    t = a
    f, df = _phi_d(P, ak, u, v, t, iu, iv, st)
    inside0 = f < 0.0
    nr = 0
    extra = 0
    dips = 0
    stk = np.empty((LINE_STACK, 6))
    while t < b:
        step = hmin
        if lip > 0 and abs(f) > step:
            step = abs(f)
        t2 = t + step
        if t2 > b:
            t2 = b
        f2, d2 = _phi_d(P, ak, u, v, t2, iu, iv, st)
        # sub-intervals of [t, t2] still to examine, processed left to right:
        # (x, phi(x), y, phi(y), phi'(x), phi'(y))
        ns = 1
        stk[0, 0] = t
        stk[0, 1] = f
        stk[0, 2] = t2
        stk[0, 3] = f2
        stk[0, 4] = df
        stk[0, 5] = d2
        while ns > 0:
            ns -= 1
            x = stk[ns, 0]
            fx = stk[ns, 1]
            y = stk[ns, 2]
            fy = stk[ns, 3]
            dx = stk[ns, 4]
            dy = stk[ns, 5]
            if (fx < 0.0) != (fy < 0.0):
                nr = _add_root(P, ak, iu, iv, u, v, x, fx, y, fy, st, roots, leaves, r0, nr,
                               eps)
                if nr < 0:
                    return -1, inside0
                continue
            unproved = lip == 0 or (y - x) - (abs(fx) + abs(fy)) > eps
            if not unproved:
                continue
            if lip > 0 and ns + 2 <= LINE_STACK and extra < lip:
                extra += 1
                m = 0.5 * (x + y)
                fm, dm = _phi_d(P, ak, u, v, m, iu, iv, st)
                stk[ns, 0] = m                 # right half first: the left is popped next
                stk[ns, 1] = fm
                stk[ns, 2] = y
                stk[ns, 3] = fy
                stk[ns, 4] = dm
                stk[ns, 5] = dy
                stk[ns + 1, 0] = x
                stk[ns + 1, 1] = fx
                stk[ns + 1, 2] = m
                stk[ns + 1, 3] = fm
                stk[ns + 1, 4] = dx
                stk[ns + 1, 5] = dm
                ns += 2
                continue
            sgn = 1.0 if fx >= 0.0 else -1.0
            if dips < DIP_BUDGET and sgn * dx < 0.0 and sgn * dy > 0.0:
                tm, fm, used = _dip(P, ak, iu, iv, u, v, x, fx, dx, y, fy, dy, st, eps)
                dips += used
                if (fm < 0.0) != (fx < 0.0):
                    nr = _add_root(P, ak, iu, iv, u, v, x, fx, tm, fm, st, roots, leaves, r0,
                                   nr, eps)
                    if nr >= 0:
                        nr = _add_root(P, ak, iu, iv, u, v, tm, fm, y, fy, st, roots, leaves,
                                       r0, nr, eps)
                    if nr < 0:
                        return -1, inside0
        t = t2
        f = f2
        df = d2
    return nr, inside0


@njit(cache=True, inline="always")
def _mix(h, x):
    """One FNV-1a style step on uint64 (wrapping): order-sensitive, and no value maps to the
    identity, so an empty line and a missing piece cannot cancel out."""
    return (h ^ np.uint64(x)) * np.uint64(1099511628211)


@njit(cache=True)
def _signature(nr, inside0, leaves):
    """Hash of a line's root structure: root count, starting side, active feature per root."""
    h = _mix(np.uint64(14695981039346656037), nr * 2 + (1 if inside0 else 0))
    for i in range(nr):
        h = _mix(h, np.int64(leaves[i]) + 1)
    return h


@njit(cache=True)
def _run_moments(nr, inside0, roots, a, b, c):
    """Moments of 1, t, t^2 (t measured from c) over the inside runs of a line on [a, b]
    that starts inside iff inside0 and changes side at roots[0:nr]."""
    m0 = 0.0
    m1 = 0.0
    m2 = 0.0
    ins = inside0
    lo = a
    for i in range(nr + 1):
        hi = roots[i] if i < nr else b
        if ins:
            x0 = lo - c
            x1 = hi - c
            m0 += x1 - x0
            m1 += 0.5 * (x1 * x1 - x0 * x0)
            m2 += (x1 * x1 * x1 - x0 * x0 * x0) / 3.0
        ins = not ins
        lo = hi
    return m0, m1, m2


@njit(cache=True)
def _accumulate(acc, w, iu, iv, ak, u, v, a, b, nr, inside0, roots, cen):
    """Add w * (moments of the inside runs of the line) to acc (10 raw moments)."""
    m0, m1, m2 = _run_moments(nr, inside0, roots, a, b, cen[ak])
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
def _sort_prefix(x, n):
    """Sort x[:n] in place (insertion sort: a handful of roots or probes)."""
    for i in range(1, n):
        y = x[i]
        j = i - 1
        while j >= 0 and x[j] > y:
            x[j + 1] = x[j]
            j -= 1
        x[j + 1] = y


@njit(cache=True)
def _knots(P, ax, f1, f2, lo, hi, c1lo, c1hi, n1, c2lo, c2hi, lip, st, S, row):
    """Sorted roots in (lo, hi) of phi along axis ``ax`` on the lines whose other two
    coordinates (on axes f1, f2) are (c1, c2) for c1 in (c1lo, c1hi)[:n1] and c2 in (c2lo,
    c2hi) -- two lines on a cell face (n1 = 1) or a cell's four edges (n1 = 2): where the
    solid's trace on a cell face or edge changes sign. Written to S[row, 1:m+1] between
    S[row, 0] = lo and S[row, m+1] = hi; returns m + 2, or -1 on overflow. Found by the
    certified line search, so none is missed on a 1-Lipschitz tree."""
    n = 0
    for i in range(2 * n1):
        c1 = c1lo if i < 2 else c1hi
        c2 = c2lo if i % 2 == 0 else c2hi
        nr, _ = _line(P, ax, f1, f2, c1, c2, lo, hi, lip, st, S[R_KROOT], S[R_KLEAF], n)
        if nr < 0:
            return -1
        n += nr
    if n + 2 > S.shape[1]:
        return -1
    kr = S[R_KROOT]
    _sort_prefix(kr, n)
    out = S[row]
    out[0] = lo
    m = 1
    for i in range(n):
        if lo < kr[i] < hi:
            out[m] = kr[i]
            m += 1
    out[m] = hi
    return m + 1


@njit(cache=True)
def _vsig(P, ak, iu, iv, u, v, a, b, lip, st, S):
    """(signature, ok, root count, inside length) of the height line at (u, v); the roots
    are left in S[R_ROOT], S[R_LEAF]."""
    roots = S[R_ROOT]
    nr, ins = _line(P, ak, iu, iv, u, v, a, b, lip, st, roots, S[R_LEAF], 0)
    if nr < 0:
        return np.uint64(0), False, -1, 0.0
    length, _, _ = _run_moments(nr, ins, roots, a, b, 0.0)
    return _signature(nr, ins, S[R_LEAF]), True, nr, length


@njit(cache=True)
def _vbreaks(P, ak, iu, iv, u, v0, v1, a, b, lip, st, S, steps, nex):
    """Pieces of the v-integrand at outer coordinate u, where it is smooth.

    Breakpoints: the knots (roots of phi on the cell's k-faces along v, exact: there a root
    leaves the cell) and every other change of the line signature (a crease: the active
    feature at a root changes; a tangency: two roots merge), found between probes and located
    by bisection to 2^-steps of the probe interval. S[R_VBRK, 0:m] gets the breaks,
    S[R_VFLAG, 0:m] 1.0 where a break is a tangency (square-root behaviour: the piece is
    smoothed there). Returns (m, hash of the sequence of piece signatures); m = -1 on overflow.

    Probes: the regular grid, and S[R_EXTRA, 0:nex] (sorted), where the caller has seen pieces
    at a nearby u: a piece narrower than the grid spacing (one vanishing at a vertex inside the
    cell) is followed there instead of being lost between grid points.
    """
    nk = _knots(P, iv, iu, ak, v0, v1, u, u, 1, a, b, lip, st, S, R_VKNOT)
    if nk < 0:
        return -1, np.uint64(0)
    knot = S[R_VKNOT]
    brk = S[R_VBRK]
    flag = S[R_VFLAG]
    ex = S[R_EXTRA]
    seq = np.uint64(1469598103934665603)
    brk[0] = v0
    flag[0] = 0.0
    m = 1
    nudge = V_NUDGE * (v1 - v0)
    for s in range(nk - 1):
        s0 = knot[s]
        s1 = knot[s + 1]
        if s1 - s0 > 2.0 * nudge:
            # probes: the segment's ends (nudged inside) and the regular grid points in it
            x = s0 + nudge
            sx, ok, nx, lx = _vsig(P, ak, iu, iv, u, x, a, b, lip, st, S)
            if not ok:
                return -1, np.uint64(0)
            seq = _mix(seq, sx)
            j = int((x - v0) / (v1 - v0) * V_PROBES) + 1
            e = 0
            while e < nex and ex[e] <= x:
                e += 1
            while True:
                y = v0 + (v1 - v0) * j / V_PROBES
                use_extra = e < nex and ex[e] < y
                if use_extra:
                    y = ex[e]
                last = y >= s1 - nudge
                if last:
                    y = s1 - nudge
                sy, ok, ny, ly = _vsig(P, ak, iu, iv, u, y, a, b, lip, st, S)
                if not ok:
                    return -1, np.uint64(0)
                while sx != sy:               # every change in (x, y], left to right
                    lo_ = x
                    hi_ = y
                    s_hi = sy
                    n_hi = ny
                    l_lo = lx
                    l_hi = ly
                    for it in range(steps):
                        if it >= KINK_STEPS and abs(l_hi - l_lo) <= KINK_SLOPE * (hi_ - lo_):
                            break             # the integrand is continuous here: a kink
                        mid = 0.5 * (lo_ + hi_)
                        sm, ok, nm, lm = _vsig(P, ak, iu, iv, u, mid, a, b, lip, st, S)
                        if not ok:
                            return -1, np.uint64(0)
                        if sm == sx:
                            lo_ = mid
                            l_lo = lm
                        else:
                            hi_ = mid
                            s_hi = sm
                            n_hi = nm
                            l_hi = lm
                    if hi_ - brk[m - 1] <= FLICKER * (v1 - v0):
                        # the signature flickers at a tangency (round-off decides whether
                        # a grazing pair of roots is seen): step over the flicker
                        x = hi_ + FLICKER * (v1 - v0)
                        if x >= y:
                            break
                        sx, ok, nx, lx = _vsig(P, ak, iu, iv, u, x, a, b, lip, st, S)
                        if not ok:
                            return -1, np.uint64(0)
                        continue
                    if m >= S.shape[1] - 2:
                        return -1, np.uint64(0)
                    brk[m] = hi_
                    flag[m] = 1.0 if n_hi != nx else 0.0
                    m += 1
                    x = hi_
                    sx = s_hi
                    nx = n_hi
                    lx = l_hi
                    seq = _mix(seq, sx)
                    if hi_ >= y:
                        break
                x = y
                sx = sy
                nx = ny
                lx = ly
                if last:
                    break
                if use_extra:
                    e += 1
                else:
                    j += 1
        if s < nk - 2:                        # the knot itself closes this segment
            if m >= S.shape[1] - 2:
                return -1, np.uint64(0)
            brk[m] = s1
            flag[m] = 0.0
            m += 1
            seq = _mix(seq, 7)
    brk[m] = v1
    flag[m] = 0.0
    return m + 1, seq


@njit(cache=True)
def _probe(P, ak, iu, iv, u, v0, v1, a, b, lip, st, S, steps, ra, na, rb, nb):
    """The v-structure at u (:func:`_vbreaks`), probed also at S[ra, :na] and S[rb, :nb]
    (each sorted): (break count, hash); count -1 on overflow."""
    nex = _merge(S, ra, na, rb, nb, R_EXTRA)
    return _vbreaks(P, ak, iu, iv, u, v0, v1, a, b, lip, st, S, steps, nex)


@njit(cache=True)
def _probe_mids(P, ak, iu, iv, u, v0, v1, a, b, lip, st, S, steps, ra, na, rb, nb, dst):
    """:func:`_probe`, keeping the piece midpoints (either source row may be dst): (count of
    the midpoints, now in S[dst], hash); count -1 on overflow."""
    m, h = _probe(P, ak, iu, iv, u, v0, v1, a, b, lip, st, S, steps, ra, na, rb, nb)
    if m < 0:
        return -1, h
    return _piece_mids(S, m, dst), h


@njit(cache=True, inline="always")
def _piece_node(p0, p1, x, s0, s1):
    """(point, weight factor) of Gauss node x in [0, 1] on the piece [p0, p1].

    An end flagged s0 / s1 has square-root behaviour (a tangency); the map's derivative
    vanishes there (t - p0 ~ x^2), which makes the integrand analytic again."""
    L = p1 - p0
    if s0 and s1:
        return p0 + L * x * x * (3.0 - 2.0 * x), 6.0 * L * x * (1.0 - x)
    if s0:
        return p0 + L * x * x, 2.0 * L * x
    if s1:
        y = 1.0 - x
        return p1 - L * y * y, 2.0 * L * y
    return p0 + L * x, L


@njit(cache=True)
def _piece_mids(S, m, row):
    """Midpoints of the m - 1 v-pieces in S[R_VBRK] into S[row]; returns their count."""
    brk = S[R_VBRK]
    out = S[row]
    k = 0
    for i in range(m - 1):
        if brk[i + 1] > brk[i]:
            out[k] = 0.5 * (brk[i] + brk[i + 1])
            k += 1
    return k


@njit(cache=True)
def _merge(S, ra, na, rb, nb, dst):
    """Sorted merge of S[ra, 0:na] and S[rb, 0:nb] into S[dst] (dst may alias neither)."""
    A = S[ra]
    B = S[rb]
    D = S[dst]
    i = 0
    j = 0
    k = 0
    cap = D.shape[0]
    while (i < na or j < nb) and k < cap:
        if j >= nb or (i < na and A[i] <= B[j]):
            D[k] = A[i]
            i += 1
        else:
            D[k] = B[j]
            j += 1
        k += 1
    return k


@njit(cache=True)
def _extrapolate(S, rnow, nnow, unow, rprev, nprev, uprev, u, v0, v1, k):
    """Midpoints predicted at u by the straight line through each piece's midpoint at uprev
    and at unow (pieces paired in order; nothing when the counts differ), appended to
    S[R_XP] from index k (unsorted); returns the new count.

    A piece that vanishes at a vertex inside the cell is a wedge in (u, v): its midpoint
    moves along a line through the vertex, possibly faster than the wedge opens, so a probe
    at the old midpoint misses it while the extrapolated one stays inside it."""
    if nprev != nnow or nnow <= 0 or unow == uprev:
        return k
    out = S[R_XP]
    r = (u - unow) / (unow - uprev)
    for i in range(nnow):
        if k >= out.shape[0]:
            break
        x = S[rnow, i] + (S[rnow, i] - S[rprev, i]) * r
        if v0 < x < v1 and x != S[rnow, i]:
            out[k] = x
            k += 1
    return k


@njit(cache=True)
def _keep_seeds(seeds, nseed, piece, S, row, n):
    """Append S[row, :n] to the seeds of u-piece ``piece`` (values already there, or beyond
    the row's capacity, are dropped)."""
    if piece >= seeds.shape[0]:
        return
    k = nseed[piece]
    for i in range(n):
        x = S[row, i]
        dup = False
        for j in range(k):
            if seeds[piece, j] == x:
                dup = True
                break
        if not dup and k < seeds.shape[1]:
            seeds[piece, k] = x
            k += 1
    nseed[piece] = k


@njit(cache=True)
def _sorted_seeds(seeds, nseed, piece, S, row):
    """The seeds of u-piece ``piece``, sorted, into S[row]; returns their count."""
    n = nseed[piece]
    S[row, :n] = seeds[piece, :n]
    _sort_prefix(S[row], n)
    return n


@njit(cache=True)
def _cell_rules(P, clo, chi, ak, iu, iv, g5x, g5w, g7x, g7w, lip, cen, st, S, seeds, nseed,
                reprobes, a5, a7):
    """Integrate the cut cell [clo, chi] with 5- and 7-point Gauss-Legendre rules on every
    smooth piece in u and in v. Returns False on an overflow.

    u-breakpoints: the knots (roots of phi along u on the four cell edges (v0|v1, a|b): a
    face trace leaves the cell there) and every other change of the v-structure hash between
    probes, located by bisection (smoothed: a piece appearing or vanishing behaves like a
    power 3/2).

    Seeds: the v-piece midpoints that the scan saw inside each u-piece (at its probes and on
    either side of its bisected ends) are kept in ``seeds[piece, :nseed[piece]]`` and probed
    again at the piece's centre: a v-piece narrower than the probe grid (a wedge at a vertex
    inside the cell), which the scan found by its hash, is then not lost by the rule."""
    a = clo[ak]
    b = chi[ak]
    u0 = clo[iu]
    u1 = chi[iu]
    v0 = clo[iv]
    v1 = chi[iv]
    nk = _knots(P, iu, iv, ak, u0, u1, v0, v1, 2, a, b, lip, st, S, R_UKNOT)
    if nk < 0:
        return False
    knot = S[R_UKNOT]
    ubrk = S[R_UBRK]
    uflag = S[R_UFLAG]
    ubrk[0] = u0
    uflag[0] = 0.0
    mu = 1
    nseed[:] = 0
    nlo = 0
    nudge = U_NUDGE * (u1 - u0)
    # without re-probes (the fallback after an overflow) the scan is the plain one: hash-level
    # breaks while bisecting, and no probe just past a located break
    track = TRACK_STEPS if reprobes > 0 else HASH_STEPS
    flicker = (2.0 if reprobes > 0 else 1.0) * U_FLICKER * (u1 - u0)
    zone = U_ZONE * (u1 - u0)
    nshort = 0
    jump = U_FLICKER * (u1 - u0)
    zone_max = U_ZONE_MAX * (u1 - u0)
    for s in range(nk - 1):
        s0 = knot[s]
        s1 = knot[s + 1]
        if s1 - s0 > 2.0 * nudge:
            # the v-structure is probed with extra v-probes at the piece midpoints seen at the
            # neighbouring u (rows R_MLO / R_MHI / R_MY: bracket ends and the next probe)
            # ... and at the segment's start, with the pieces seen at the end of the previous
            # segment (a knot ends a face trace, not the narrow pieces that cross it)
            x = s0 + nudge
            nlo, hx = _probe_mids(P, ak, iu, iv, x, v0, v1, a, b, lip, st, S, HASH_STEPS,
                                  R_MLO, nlo, R_MLO, 0, R_MLO)
            if nlo < 0:
                return False
            _keep_seeds(seeds, nseed, mu - 1, S, R_MLO, nlo)
            j = int((x - u0) / (u1 - u0) * V_PROBES) + 1
            while True:
                y = u0 + (u1 - u0) * j / V_PROBES
                last = y >= s1 - nudge
                if last:
                    y = s1 - nudge
                ny, hy = _probe_mids(P, ak, iu, iv, y, v0, v1, a, b, lip, st, S, HASH_STEPS,
                                     R_MLO, nlo, R_MLO, 0, R_MY)
                if ny < 0:
                    return False
                nre = 0
                while hx != hy:
                    lo_ = x
                    hi_ = y
                    h_hi = hy
                    nhi = _merge(S, R_MY, ny, R_MY, 0, R_MHI)
                    nx0 = _merge(S, R_MLO, nlo, R_MLO, 0, R_MX)
                    for attempt in range(reprobes + 1):
                        # each end's previous midpoints (count -1: none yet) to extrapolate
                        nlp = -1
                        nhp = -1
                        ulp = lo_
                        uhp = hi_
                        for _ in range(U_BREAK_STEPS):
                            mid = 0.5 * (lo_ + hi_)
                            nxp = 0
                            if reprobes > 0:
                                nxp = _extrapolate(S, R_MLO, nlo, lo_, R_MLP, nlp, ulp, mid,
                                                   v0, v1, 0)
                                nxp = _extrapolate(S, R_MHI, nhi, hi_, R_MHP, nhp, uhp, mid,
                                                   v0, v1, nxp)
                            _sort_prefix(S[R_XP], nxp)
                            nt = _merge(S, R_MLO, nlo, R_MHI, nhi, R_XT)
                            mm, hm = _probe(P, ak, iu, iv, mid, v0, v1, a, b, lip, st, S,
                                            track, R_XT, nt, R_XP, nxp)
                            if mm < 0:
                                return False
                            if hm == hx:
                                nlp = _merge(S, R_MLO, nlo, R_MLO, 0, R_MLP)
                                ulp = lo_
                                lo_ = mid
                                nlo = _piece_mids(S, mm, R_MLO)
                            else:
                                nhp = _merge(S, R_MHI, nhi, R_MHI, 0, R_MHP)
                                uhp = hi_
                                hi_ = mid
                                h_hi = hm
                                nhi = _piece_mids(S, mm, R_MHI)
                        if attempt == reprobes or lo_ <= x:
                            break
                        # lo_ was probed with the pieces tracked from its own side, so a piece
                        # thinning towards lo_ (a wedge closing at a vertex further down, whose
                        # midpoint moves faster than it opens) may have been missed there: probe
                        # lo_ with hi_'s pieces, and if the change lies below, search again
                        mr, hr = _probe(P, ak, iu, iv, lo_, v0, v1, a, b, lip, st, S, track,
                                        R_MLO, nlo, R_MHI, nhi)
                        if mr < 0:
                            return False
                        if hr == hx:
                            break
                        hi_ = lo_
                        h_hi = hr
                        nhi = _piece_mids(S, mr, R_MHI)
                        lo_ = x
                        nlo = _merge(S, R_MX, nx0, R_MX, 0, R_MLO)
                    if nre < reprobes and hi_ - x > 4.0 * U_FLICKER * (u1 - u0):
                        # hi_ was probed with the pieces tracked from a bracket end far away, so
                        # a narrow piece followed up to it may have been missed there: probe it
                        # again with the pieces seen just below it (2^-U_BREAK_STEPS away)
                        nre += 1
                        mr, hr = _probe(P, ak, iu, iv, hi_, v0, v1, a, b, lip, st, S, track,
                                        R_MLO, nlo, R_MLO, 0)
                        if mr < 0:
                            return False
                        if hi_ == y:
                            hy = hr
                            ny = _piece_mids(S, mr, R_MY)
                        if hr == hx:          # no change at hi_ after all: go on from there
                            x = hi_
                            nlo = _piece_mids(S, mr, R_MLO)
                            continue
                        if hr != h_hi:
                            h_hi = hr
                            nhi = _piece_mids(S, mr, R_MHI)
                    gap = hi_ - ubrk[mu - 1]
                    # a zone lasts while its breaks keep following the step-over (they are
                    # its flicker, as far apart as the step), however wide it grows
                    zoned = nshort >= U_ZONE_BREAKS and (gap <= zone or gap <= 4.0 * jump)
                    if gap <= flicker or zoned:
                        # step over a flicker (see _vbreaks); inside a zone where breaks keep
                        # coming closer than U_ZONE apart (a line family grazing the surface
                        # along u, whose hash round-off decides), in doubling steps
                        x = hi_ + (jump if zoned else U_FLICKER * (u1 - u0))
                        if zoned:
                            jump = min(2.0 * jump, zone_max)
                        if x >= y:
                            break
                        nlo, hx = _probe_mids(P, ak, iu, iv, x, v0, v1, a, b, lip, st, S,
                                              HASH_STEPS, R_MLO, nlo, R_MHI, nhi, R_MLO)
                        if nlo < 0:
                            return False
                        continue
                    if mu >= S.shape[1] - 2:
                        return False
                    nshort = nshort + 1 if gap <= zone else 0
                    jump = U_FLICKER * (u1 - u0)
                    _keep_seeds(seeds, nseed, mu - 1, S, R_MLO, nlo)
                    _keep_seeds(seeds, nseed, mu, S, R_MHI, nhi)
                    ubrk[mu] = hi_
                    uflag[mu] = 1.0
                    mu += 1
                    x = hi_
                    hx = h_hi
                    nlo = _merge(S, R_MHI, nhi, R_MHI, 0, R_MLO)
                    if hi_ >= y:
                        break
                    xs = hi_ + U_FLICKER * (u1 - u0)
                    if reprobes > 0 and xs < y:
                        # right at the break the structure is degenerate (two creases
                        # crossing leave a piece of zero width), and it may hash like the
                        # structure at y by chance: the next bracket starts just past it
                        x = xs
                        nlo, hx = _probe_mids(P, ak, iu, iv, x, v0, v1, a, b, lip, st, S,
                                              track, R_MLO, nlo, R_MLO, 0, R_MLO)
                        if nlo < 0:
                            return False
                x = y
                hx = hy
                nlo = _merge(S, R_MY, ny, R_MY, 0, R_MLO)
                _keep_seeds(seeds, nseed, mu - 1, S, R_MLO, nlo)
                if last:
                    break
                j += 1
        if s < nk - 2:
            if mu >= S.shape[1] - 2:
                return False
            ubrk[mu] = s1
            uflag[mu] = 0.0
            mu += 1
    ubrk[mu] = u1
    uflag[mu] = 0.0
    mu += 1
    for pu in range(mu - 1):
        pu0 = ubrk[pu]
        pu1 = ubrk[pu + 1]
        if pu1 <= pu0:
            continue
        # the piece's centre first, then outwards both ways, each node probing where the
        # previous one saw pieces (a narrow piece is followed towards the end it thins at)
        um, _ = _piece_node(pu0, pu1, 0.5, False, False)
        ns = _sorted_seeds(seeds, nseed, pu, S, R_EXTRA)
        mc, _ = _vbreaks(P, ak, iu, iv, um, v0, v1, a, b, lip, st, S, HASH_STEPS, ns)
        if mc < 0:
            return False
        nc = _piece_mids(S, mc, R_MC)
        for rule in range(2):
            gx = g5x if rule == 0 else g7x
            gw = g5w if rule == 0 else g7w
            acc = a5 if rule == 0 else a7
            q = gx.shape[0]
            c = q // 2
            for k in range(q):
                i = c + k if c + k < q else q - 1 - k
                if k == 0 or i == c - 1:
                    nprev = _merge(S, R_MC, nc, R_MC, 0, R_MLO)
                u, wu = _piece_node(pu0, pu1, gx[i], uflag[pu] != 0.0, uflag[pu + 1] != 0.0)
                wu *= gw[i]
                m, hv = _probe(P, ak, iu, iv, u, v0, v1, a, b, lip, st, S, BREAK_STEPS,
                               R_MLO, nprev, R_MC, nc)
                if m < 0:
                    return False
                nprev = _piece_mids(S, m, R_MLO)
                brk = S[R_VBRK]
                flag = S[R_VFLAG]
                for pc in range(m - 1):
                    p0 = brk[pc]
                    p1 = brk[pc + 1]
                    if p1 <= p0:
                        continue
                    for jv in range(q):
                        v, wv = _piece_node(p0, p1, gx[jv], flag[pc] != 0.0,
                                            flag[pc + 1] != 0.0)
                        nr, ins = _line(P, ak, iu, iv, u, v, a, b, lip, st, S[R_ROOT],
                                        S[R_LEAF], 0)
                        if nr < 0:
                            return False
                        _accumulate(acc, wu * wv * gw[jv], iu, iv, ak, u, v, a, b, nr, ins,
                                    S[R_ROOT], cen)
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
def _cell_bound(acc, clo, chi, cen, scale):
    """Add ``scale`` times bounds on the magnitudes of the raw moments (relative to cen) of
    ANY part of the box [clo, chi]: vol, vol * max |x|, vol * max x^2, vol * max |x y|."""
    vol = scale * (chi[0] - clo[0]) * (chi[1] - clo[1]) * (chi[2] - clo[2])
    m0 = max(abs(clo[0] - cen[0]), abs(chi[0] - cen[0]))
    m1 = max(abs(clo[1] - cen[1]), abs(chi[1] - cen[1]))
    m2 = max(abs(clo[2] - cen[2]), abs(chi[2] - cen[2]))
    acc[0] += vol
    acc[1] += vol * m0
    acc[2] += vol * m1
    acc[3] += vol * m2
    acc[4] += vol * m0 * m0
    acc[5] += vol * m1 * m1
    acc[6] += vol * m2 * m2
    acc[7] += vol * m0 * m1
    acc[8] += vol * m0 * m2
    acc[9] += vol * m1 * m2


@njit(cache=True)
def _surface_in_cell(ops, lk, lr, ob, oe, clo, chi, st):
    """True when a Newton projection onto phi = 0, started from the cell's centre or from one
    of its 8 octant centres, converges to a point inside the closed cell.

    Used on cells of a 1-Lipschitz tree that the certificate cannot decide but whose rule
    found no surface: a convex vertex or edge of the solid that pokes into the cell between
    the probe lines is then seen (its nearest point to a nearby start is usually the tip
    itself), and the cell is split until the probes resolve it. A heuristic, not a proof: a
    start whose nearest surface point lies outside the cell proves nothing."""
    size = max(chi[0] - clo[0], max(chi[1] - clo[1], chi[2] - clo[2]))
    p = np.empty(3)
    for s in range(9):
        for d in range(3):
            if s == 0:
                p[d] = 0.5 * (clo[d] + chi[d])
            else:
                f = 0.25 if ((s - 1) >> d) & 1 == 0 else 0.75
                p[d] = clo[d] + f * (chi[d] - clo[d])
        for _ in range(PROJECT_STEPS):
            f, gx, gy, gz = K.eval_point(ops, lk, lr, ob, oe, p[0], p[1], p[2], st)
            if abs(f) <= PROJECT_EPS * size:
                inside = True
                for d in range(3):
                    if p[d] < clo[d] or p[d] > chi[d]:
                        inside = False
                if inside:
                    return True
                break
            g2 = gx * gx + gy * gy + gz * gz
            if not (g2 > 0.0) or not math.isfinite(f):
                break
            p[0] -= f * gx / g2
            p[1] -= f * gy / g2
            p[2] -= f * gz / g2
    return False


@njit(cache=True)
def _cell(P, clo, chi, lip, g5x, g5w, g7x, g7w, cen, st, S, seeds, nseed, a5, a7):
    """Integrate one cell into a5 / a7 (its raw moments by the 5- and 7-point rules; equal,
    and exact, for a cell the certificate decides). Returns the error estimate max |a7 - a5|,
    ``math.inf`` when the surface was found in the cell by projection but not by the rule
    (split it whatever the tolerance), or -1.0 on an overflow."""
    ops, lk, lr, ob, oe = P
    a5[:] = 0.0
    a7[:] = 0.0
    f, gx, gy, gz = K.eval_point(ops, lk, lr, ob, oe, 0.5 * (clo[0] + chi[0]),
                                 0.5 * (clo[1] + chi[1]), 0.5 * (clo[2] + chi[2]), st)
    hd = 0.5 * math.sqrt((chi[0] - clo[0]) ** 2 + (chi[1] - clo[1]) ** 2
                         + (chi[2] - clo[2]) ** 2)
    if lip > 0 and f >= hd:
        return 0.0
    if lip > 0 and f <= -hd:
        _box_moments(a5, clo, chi, cen)
        _box_moments(a7, clo, chi, cen)
        return 0.0
    ak, iv, iu = _axis_order(gx, gy, gz)
    ok = _cell_rules(P, clo, chi, ak, iu, iv, g5x, g5w, g7x, g7w, lip, cen, st, S, seeds,
                     nseed, U_REPROBES, a5, a7)
    if not ok:
        # re-probing can meet a many-way flicker at a tangency and run out of breakpoint
        # slots: the cell is done again without it
        a5[:] = 0.0
        a7[:] = 0.0
        ok = _cell_rules(P, clo, chi, ak, iu, iv, g5x, g5w, g7x, g7w, lip, cen, st, S,
                         seeds, nseed, 0, a5, a7)
    if not ok:
        return -1.0
    est = 0.0
    for m in range(10):
        est = max(est, abs(a7[m] - a5[m]))
    if lip > 0 and est == 0.0 and not _has_surface(a7, clo, chi):
        if _surface_in_cell(ops, lk, lr, ob, oe, clo, chi, st):
            return math.inf
    return est


@njit(cache=True, inline="always")
def _has_surface(a7, clo, chi):
    """Whether the rule's volume is strictly between empty and full (relative 1e-12)."""
    vol = (chi[0] - clo[0]) * (chi[1] - clo[1]) * (chi[2] - clo[2])
    return SURFACE_FRAC * vol < a7[0] < (1.0 - SURFACE_FRAC) * vol


@njit(cache=True, parallel=True)
def integrate_cells(ops, lk, lr, ob, oe, cells, lip, g5x, g5w, g7x, g7w, cen):
    """Integrate every cell of ``cells`` (N, 6: lo, hi) on its own.

    Returns the raw moments (N, 10: 1, x, y, z, x^2, y^2, z^2, xy, xz, yz, relative to cen)
    by the 7-point rules, their error estimates (N, 10) and a code per cell: 0 integrated;
    1 the surface was found in the cell by projection but not by its rule (the estimate is
    then the bound of the whole cell: split it); -1 an overflow (too many breakpoints).

    A cell's estimate is |I7 - I5| per moment, plus ROUND_ULPS ulps of the cell's moment
    bound where the two rules differ at all (each root is exact only to a few ulps of its
    coordinates, so the estimate still bounds the error once the rule error is below
    round-off). Cells are independent: the results do not depend on the thread count."""
    n = cells.shape[0]
    mom = np.zeros((n, 10))
    err = np.zeros((n, 10))
    code = np.zeros(n, dtype=np.int64)
    P = (ops, lk, lr, ob, oe)
    for c in prange(n):
        st = np.empty((K.MAX_STACK, K.STACK_COLS))
        S = np.empty((SCRATCH_ROWS, MAX_BREAKS))
        seeds = np.empty((MAX_BREAKS, SEEDS))
        nseed = np.zeros(MAX_BREAKS, dtype=np.int64)
        a5 = np.zeros(10)
        clo = cells[c, 0:3].copy()
        chi = cells[c, 3:6].copy()
        est = _cell(P, clo, chi, lip, g5x, g5w, g7x, g7w, cen, st, S, seeds, nseed, a5,
                    mom[c])
        if est < 0.0:
            code[c] = -1
        elif est == math.inf:
            code[c] = 1
            _cell_bound(err[c], clo, chi, cen, 1.0)
        else:
            rounded = False
            for m in range(10):
                err[c, m] = abs(mom[c, m] - a5[m])
                rounded = rounded or mom[c, m] != a5[m]
            if rounded:
                _cell_bound(err[c], clo, chi, cen, ROUND_ULPS * EPS)
    return mom, err, code


def _children(cells):
    """The 8 children of each cell of ``cells`` (N, 6), in a fixed order: (8 N, 6)."""
    lo, hi = cells[:, 0:3], cells[:, 3:6]
    mid = 0.5 * (lo + hi)
    out = np.empty((cells.shape[0], 8, 6))
    for c in range(8):
        bits = np.array([(c >> d) & 1 for d in range(3)], dtype=bool)
        out[:, c, 0:3] = np.where(bits, mid, lo)
        out[:, c, 3:6] = np.where(bits, hi, mid)
    return out.reshape(-1, 6)


def integrate_body(prog, lo, hi, n, lip, tol):
    """Raw moments (10,) of the solid relative to the box centre, their error estimates (10,)
    and diagnostics (cells integrated, deepest level, cells left unconverged at MAX_DEPTH,
    overflow flag), by global adaptive refinement.

    The box is split into n^3 top-level cells, each integrated once. Each cell's error is
    measured against the solid's own scale (volume V, raw second-moment trace T: a moment's
    error over V, V^1/2 T^1/2 or T), and while the sum over cells exceeds ``tol``, the cells
    with the largest errors are split until the rest add up to at most tol / 2 (cells where
    the surface was seen but not integrated are always split), down to MAX_DEPTH levels. So
    ``tol`` is the relative accuracy of the solid's moments, spent where the error is."""
    P = (prog.ops, prog.leaf_kind, prog.leaf_reals, prog.op_begin, prog.op_end)
    cen = 0.5 * (lo + hi)
    edges = [np.linspace(lo[d], hi[d], n + 1) for d in range(3)]
    for d in range(3):
        edges[d][-1] = hi[d]
    k, j, i = np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing="ij")
    i, j, k = i.ravel(), j.ravel(), k.ravel()              # x fastest
    new = np.column_stack([edges[0][i], edges[1][j], edges[2][k],
                           edges[0][i + 1], edges[1][j + 1], edges[2][k + 1]])
    new_depth = np.zeros(len(new), dtype=np.int64)
    cells = np.empty((0, 6))
    depth = np.empty(0, dtype=np.int64)
    mom = np.empty((0, 10))
    err = np.empty((0, 10))
    code = np.empty(0, dtype=np.int64)
    visited = 0
    unconverged = 0
    while len(new):
        m_new, e_new, c_new = integrate_cells(*P, new, lip, *_G5, *_G7, cen)
        visited += len(new)
        if np.any(c_new < 0):
            return np.zeros(10), np.zeros(10), np.array([visited, 0, 0, 1.0])
        cells = np.concatenate([cells, new])
        depth = np.concatenate([depth, new_depth])
        mom = np.concatenate([mom, m_new])
        err = np.concatenate([err, e_new])
        code = np.concatenate([code, c_new])
        vol = mom[:, 0].sum()
        trace = mom[:, 4:7].sum()
        if not (vol > 0.0 and trace > 0.0):
            # nothing seen yet: measure against the box
            vol = float(np.prod(hi - lo))
            trace = vol * float(np.sum((hi - lo) ** 2)) / 12.0
        w = np.r_[1.0 / vol, np.full(3, 1.0 / math.sqrt(vol * trace)), np.full(6, 1.0 / trace)]
        e = (err * w).max(axis=1)
        can = depth < MAX_DEPTH
        split = (code == 1) & can
        rest = float(e[~split].sum())
        if rest > tol:
            # the largest first (ties by position: deterministic), until the rest is tol / 2
            order = np.argsort(-e, kind="stable")
            order = order[can[order] & ~split[order] & (e[order] > 0.0)]
            drop = np.cumsum(e[order])
            take = int(np.searchsorted(drop, rest - 0.5 * tol, side="left")) + 1
            split[order[:take]] = True
        if not split.any():
            if rest > tol:      # what is left over tol sits at MAX_DEPTH
                unconverged = int(np.count_nonzero(~can & (e > 0.0)))
            break
        keep = ~split
        new = _children(cells[split])
        new_depth = np.repeat(depth[split] + 1, 8)
        cells, depth, mom, err, code = cells[keep], depth[keep], mom[keep], err[keep], code[keep]
    diag = np.array([visited, depth.max(initial=0), unconverged, 0.0], dtype=float)
    return _ordered_sum(mom), _ordered_sum(err), diag


def _ordered_sum(rows):
    """Column sums in row order (a plain loop: the same bits for the same rows)."""
    out = np.zeros(rows.shape[1])
    for r in rows:
        out += r
    return out


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


def body_properties(builder, root, lo, hi, density=1.0, n=32, tol=1e-8):
    """Mass properties of the solid ``phi < 0`` of ``root`` inside the box [lo, hi].

    Parameters
    ----------
    lo, hi : 3 finite numbers each, hi > lo; the box must contain the solid (phi >= 0 on its
        boundary, checked on a sample of the faces).
    density : > 0, mass per unit volume.
    n : int in [2, 4096], the sampling resolution: structure (where the solid's pieces start
        and end across the lines) is probed on ``n`` intervals per axis of the box, i.e. on
        ``ceil(n / 4)`` top-level cells of ``V_PROBES = 4`` probe intervals each. Cut cells
        refine adaptively below that; along a line nothing is sampled at all (roots are
        found by a certified search on 1-Lipschitz trees, steps of 1/64 of the cell
        otherwise). A piece of solid narrower than ``box / n`` across both transverse axes
        can be found late or missed; a finer ``n`` costs time roughly as ``n^2``.
    tol : in (0, 1e-3], the relative accuracy asked of the moments: cells are refined, the
        worst first, until their estimates add up to at most ``tol`` of the solid's volume
        (and of its first and second moments), so ``volume_error <= tol * volume`` unless a
        cell hit MAX_DEPTH (``diagnostics["unconverged_cells"]``).

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
    lip = bool(builder.is_lipschitz(root))
    budget = 0 if not lip else (LINE_EXTRA if tol < CERTIFY_TOL else LINE_EXTRA_LOOSE)
    prog = builder.program(root)
    top = max(1, -(-int(n) // V_PROBES))
    mom, err, diag = integrate_body(prog, lo_a, hi_a, top, budget, tol)
    cen = 0.5 * (lo_a + hi_a)
    if diag[3] != 0.0:
        raise ValueError(f"a line crossed the surface more than {MAX_BREAKS} times, or a cell "
                         f"had more than {MAX_BREAKS} breakpoints: the tree is pathological "
                         "for this box (or n is far too small)")
    vol = float(mom[0])
    if not vol > 0.0:
        raise ValueError("empty solid: no point of the box has phi < 0")
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
                                       "top_cells": top,
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
