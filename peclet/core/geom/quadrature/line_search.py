"""The certified 1-D line search: every root of phi along one axis-parallel line, to round-off.

A height line (u, v, .) of a cut cell is stepped by ``max(|phi|, hmin)``; on a 1-Lipschitz tree
a step with no sign change is *proved* root-free or bisected until any hidden run is below
LINE_EPS of the line (see :func:`line_roots`). Roots are refined by safeguarded Newton. The
inside runs of a line then give the moments of 1, t, t^2 in closed form (:func:`run_moments`),
and the line's *signature* (root count, starting side, active leaf feature per root) tells the
break search where the integrand stops being smooth.
"""
import math
from typing import NamedTuple

import numpy as np
from numba import njit

from .. import kernels as K
from .constants import DIP_BUDGET, DIP_STEPS, I0, LINE_EPS, LINE_STACK


class Line(NamedTuple):
    """One axis-parallel line of the search: the program tuple ``P`` (ops, leaf_kind,
    leaf_reals, op_begin, op_end) of :mod:`peclet.core.geom.kernels`, the line's axis ``ak``
    (0, 1 or 2), its coordinates ``u`` on axis ``iu`` and ``v`` on axis ``iv`` (world frame,
    the program's length unit) and the evaluator's scratch stack ``st`` (MAX_STACK,
    STACK_COLS). Built per line, in the kernel that walks the lines."""
    P: tuple
    ak: int
    iu: int
    iv: int
    u: float
    v: float
    st: np.ndarray


@njit(cache=True)
def _phi_d(line, t):
    """(phi, d phi / d t) at the point of ``line`` (a :class:`Line`) with coordinate t on its
    axis ak."""
    P, ak, iu, iv, u, v, st = line
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
    # P[5] = 1 / L (the tree's Lipschitz constant): the searched field is phi / L, 1-Lipschitz
    # with phi's zero set; exact (x * 1.0) for a 1-Lipschitz tree
    k = P[5]
    if ak == 0:
        return f * k, g0 * k
    if ak == 1:
        return f * k, g1 * k
    return f * k, g2 * k


@njit(cache=True, inline="always")
def _phi(line, t):
    """phi at the point of ``line`` with coordinate t on its axis (see :func:`_phi_d`)."""
    return _phi_d(line, t)[0]


@njit(cache=True)
def _refine(line, a, fa, b, fb):
    """A root of phi in [a, b] of ``line`` (fa, fb of opposite signs) to round-off.

    Safeguarded Newton along the line (the evaluator returns the gradient with phi): a Newton
    step is taken when it stays inside the bracket and the previous one at least halved |phi|,
    a bisection otherwise, so the bracket always shrinks and a crease inside it (where the
    derivative jumps) costs at most a bisection's worth of steps. Starts at the secant point.
    Returns (root, active leaf feature at the root)."""
    st = line.st
    x = (a * fb - b * fa) / (fb - fa)
    if not (a < x < b):
        x = 0.5 * (a + b)
    fprev = math.inf
    for _ in range(200):
        f, d = _phi_d(line, x)
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
    _phi(line, r)
    return r, st[0, 4]


@njit(cache=True)
def _add_root(line, x, fx, y, fy, roots, leaves, r0, nr, eps):
    """Refine the root in [x, y] of ``line`` (fx, fy of opposite signs) and append it to
    roots/leaves after slot r0 + nr; a root within ``eps`` of the previous one annihilates
    with it (a grazing pair, or round-off noise at a tangency: the run between them carries
    no measurable length). Returns the new count, -1 on overflow."""
    if r0 + nr >= roots.shape[0]:
        return -1
    r, lf = _refine(line, x, fx, y, fy)
    if nr > 0 and r - roots[r0 + nr - 1] <= eps:
        return nr - 1
    roots[r0 + nr] = r
    leaves[r0 + nr] = lf
    return nr + 1


@njit(cache=True)
def _dip(line, x, fx, dx, y, fy, dy, eps):
    """Search [x, y] of ``line``, whose ends have the same sign and slopes pointing at an extremum
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
        f, d = _phi_d(line, t)
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
def line_roots(line, a, b, lip, roots, leaves, r0):
    """Roots of phi along ``line`` (a :class:`Line`) over [a, b] of its axis, written to
    roots/leaves from slot r0.

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
    f, df = _phi_d(line, t)
    inside0 = f < 0.0
    nr = I0                  # an int64, not a literal: _add_root is compiled once
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
        f2, d2 = _phi_d(line, t2)
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
                nr = _add_root(line, x, fx, y, fy, roots, leaves, r0, nr, eps)
                if nr < 0:
                    return -1, inside0
                continue
            unproved = lip == 0 or (y - x) - (abs(fx) + abs(fy)) > eps
            if not unproved:
                continue
            if lip > 0 and ns + 2 <= LINE_STACK and extra < lip:
                extra += 1
                m = 0.5 * (x + y)
                fm, dm = _phi_d(line, m)
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
                tm, fm, used = _dip(line, x, fx, dx, y, fy, dy, eps)
                dips += used
                if (fm < 0.0) != (fx < 0.0):
                    nr = _add_root(line, x, fx, tm, fm, roots, leaves, r0, nr, eps)
                    if nr >= 0:
                        nr = _add_root(line, tm, fm, y, fy, roots, leaves, r0, nr, eps)
                    if nr < 0:
                        return -1, inside0
        t = t2
        f = f2
        df = d2
    return nr, inside0


@njit(cache=True, inline="always")
def mix(h, x):
    """One FNV-1a style step on uint64 (wrapping): order-sensitive, and no value maps to the
    identity, so an empty line and a missing piece cannot cancel out."""
    return (h ^ np.uint64(x)) * np.uint64(1099511628211)


@njit(cache=True)
def signature(nr, inside0, leaves):
    """Hash of a line's root structure: root count, starting side, active feature per root."""
    h = mix(np.uint64(14695981039346656037), nr * 2 + (1 if inside0 else 0))
    for i in range(nr):
        h = mix(h, np.int64(leaves[i]) + 1)
    return h


@njit(cache=True)
def run_moments(nr, inside0, roots, a, b, c):
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
def sort_prefix(x, n):
    """Sort x[:n] in place (insertion sort: a handful of roots or probes)."""
    for i in range(1, n):
        y = x[i]
        j = i - 1
        while j >= 0 and x[j] > y:
            x[j + 1] = x[j]
            j -= 1
        x[j + 1] = y


