"""The cell rule and its error estimate: one cell's raw moments by 5- and 7-point rules.

A cell the certificate decides (|phi| at its centre above its half-diagonal, 1-Lipschitz tree)
is empty or full: its box moments are exact. In a cut cell the height axis k is the largest
component of grad phi at the centre (:func:`axis_order`); the break search (:mod:`.breaks`)
splits u and then v into smooth pieces, each integrated by Gauss-Legendre with q = 5 and q = 7
points per transverse axis, the height integral done exactly along each line. The value is the
q = 7 one and |I7 - I5| its error estimate. A cell whose rule saw no surface but a Newton
projection finds some is flagged for splitting.
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit

from .. import kernels as K
from .breaks import probe, ubreaks, vbreaks
from .constants import (BREAK_STEPS, HASH_STEPS, I0, PROJECT_EPS, PROJECT_STEPS, R_LEAF, R_MC,
                        R_MLO, R_ROOT, R_UBRK, R_UFLAG, R_VBRK, R_VFLAG, R_EXTRA, SURFACE_FRAC,
                        U_REPROBES)
from .line_search import Line, line_roots, run_moments
from .pieces import merge, piece_mids, piece_node, sorted_seeds

#: A cut cell's fixed data, passed to the break search and the rule as one value: the program
#: tuple P = (ops, leaf_kind, leaf_reals, op_begin, op_end, 1 / L) (L the tree's Lipschitz
#: constant, :meth:`SceneBuilder.lipschitz_constant`; 1.0 for a 1-Lipschitz tree), the height axis ak and the outer
#: and inner axes iu, iv, the cell's extent [a, b] on ak, [u0, u1] on iu, [v0, v1] on iv, the
#: line search's halving cap lip (0: not 1-Lipschitz), the moments' origin cen (3,), the
#: evaluator's stack st and the scratch S (SCRATCH_ROWS, MAX_BREAKS).
Cell = namedtuple("Cell", ["P", "ak", "iu", "iv", "a", "b", "u0", "u1", "v0", "v1", "lip",
                           "cen", "st", "S"])


@njit(cache=True)
def cell_rules(C, G, seeds, nseed, reprobes, a5, a7):
    """Integrate the cut cell ``C`` (a :data:`Cell`) with 5- and 7-point Gauss-Legendre rules
    (``G = (g5x, g5w, g7x, g7w)``, nodes and weights on [0, 1]) on every smooth piece in u and
    in v, adding the raw moments to a5 and a7. Returns False on an overflow; ``reprobes`` is
    passed to :func:`.breaks.ubreaks` (0: the plain scan, the fallback after an overflow).

    u-breakpoints: the knots (roots of phi along u on the four cell edges (v0|v1, a|b): a
    face trace leaves the cell there) and every other change of the v-structure hash between
    probes, located by bisection (smoothed: a piece appearing or vanishing behaves like a
    power 3/2).

    Seeds: the v-piece midpoints that the scan saw inside each u-piece (at its probes and on
    either side of its bisected ends) are kept in ``seeds[piece, :nseed[piece]]`` and probed
    again at the piece's centre: a v-piece narrower than the probe grid (a wedge at a vertex
    inside the cell), which the scan found by its hash, is then not lost by the rule."""
    mu = ubreaks(C, seeds, nseed, reprobes)
    if mu < 0:
        return False
    ubrk = C.S[R_UBRK]
    uflag = C.S[R_UFLAG]
    for pu in range(mu - 1):
        if ubrk[pu + 1] > ubrk[pu]:
            if not _u_piece_rules(C, G, seeds, nseed, pu, ubrk[pu], ubrk[pu + 1],
                                  uflag[pu] != 0.0, uflag[pu + 1] != 0.0, a5, a7):
                return False
    return True


@njit(cache=True, inline="always")
def _u_piece_rules(C, G, seeds, nseed, pu, pu0, pu1, s0, s1, a5, a7):
    """Both rules across the u-piece number ``pu``, [pu0, pu1] (s0 / s1: an end is a
    tangency, see :func:`.pieces.piece_node`), added to a5 / a7. False on an overflow.

    The piece's centre is probed first, with the seeds the scan kept for it, then the Gauss
    nodes outwards both ways, each probing where the previous one saw v-pieces (a narrow
    piece is followed towards the end it thins at)."""
    S = C.S
    um, _ = piece_node(pu0, pu1, 0.5, False, False)
    ns = sorted_seeds(seeds, nseed, pu, S, R_EXTRA)
    mc, _ = vbreaks(C, um, HASH_STEPS, ns)
    if mc < 0:
        return False
    nc = piece_mids(S, mc, R_MC)
    for rule in range(2):
        gx = G[0] if rule == 0 else G[2]
        gw = G[1] if rule == 0 else G[3]
        acc = a5 if rule == 0 else a7
        q = gx.shape[0]
        c = q // 2
        nprev = 0
        for k in range(q):
            i = c + k if c + k < q else q - 1 - k
            if k == 0 or i == c - 1:
                nprev = merge(S, R_MC, nc, R_MC, I0, R_MLO)
            u, wu = piece_node(pu0, pu1, gx[i], s0, s1)
            wu *= gw[i]
            m, _ = probe(C, u, BREAK_STEPS, R_MLO, nprev, R_MC, nc)
            if m < 0:
                return False
            nprev = piece_mids(S, m, R_MLO)
            if not _v_rule(C, gx, gw, u, wu, m, acc):
                return False
    return True


@njit(cache=True, inline="always")
def _v_rule(C, gx, gw, u, wu, m, acc):
    """The rule along v at outer node u (weight wu): Gauss nodes gx / weights gw on each
    v-piece of S[R_VBRK, :m], the height integral exact along each line, added to acc."""
    S = C.S
    brk = S[R_VBRK]
    flag = S[R_VFLAG]
    for pc in range(m - 1):
        p0 = brk[pc]
        p1 = brk[pc + 1]
        if p1 <= p0:
            continue
        for jv in range(gx.shape[0]):
            v, wv = piece_node(p0, p1, gx[jv], flag[pc] != 0.0, flag[pc + 1] != 0.0)
            nr, ins = line_roots(Line(C.P, C.ak, C.iu, C.iv, u, v, C.st), C.a, C.b, C.lip,
                                 S[R_ROOT], S[R_LEAF], I0)
            if nr < 0:
                return False
            _accumulate(acc, wu * wv * gw[jv], C, u, v, nr, ins)
    return True


@njit(cache=True)
def _accumulate(acc, w, C, u, v, nr, inside0):
    """Add w * (moments of the inside runs of the height line at (u, v) of the cut cell
    ``C``, its nr roots in S[R_ROOT]) to acc (10 raw moments)."""
    iu, iv, ak, a, b, cen = C.iu, C.iv, C.ak, C.a, C.b, C.cen
    m0, m1, m2 = run_moments(nr, inside0, C.S[R_ROOT], a, b, cen[ak])
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
def axis_order(gx, gy, gz):
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
def cell_bound(acc, clo, chi, cen, scale):
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
def surface_in_cell(ops, lk, lr, ob, oe, clo, chi, st):
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


@njit(cache=True, inline="always")
def integrate_cell(P, clo, chi, lip, G, cen, st, S, seeds, nseed, a5, a7):
    """Integrate one cell into a5 / a7 (its raw moments by the 5- and 7-point rules; equal,
    and exact, for a cell the certificate decides). Returns the error estimate max |a7 - a5|,
    ``math.inf`` when the surface was found in the cell by projection but not by the rule
    (split it whatever the tolerance), or -1.0 on an overflow."""
    ops, lk, lr, ob, oe, kinv = P
    a5[:] = 0.0
    a7[:] = 0.0
    f, gx, gy, gz = K.eval_point(ops, lk, lr, ob, oe, 0.5 * (clo[0] + chi[0]),
                                 0.5 * (clo[1] + chi[1]), 0.5 * (clo[2] + chi[2]), st)
    f = f * kinv            # phi / L: 1-Lipschitz (exact for L = 1)
    hd = 0.5 * math.sqrt((chi[0] - clo[0]) ** 2 + (chi[1] - clo[1]) ** 2
                         + (chi[2] - clo[2]) ** 2)
    if lip > 0 and f >= hd:
        return 0.0
    if lip > 0 and f <= -hd:
        _box_moments(a5, clo, chi, cen)
        _box_moments(a7, clo, chi, cen)
        return 0.0
    ak, iv, iu = axis_order(gx, gy, gz)
    C = Cell(P, ak, iu, iv, clo[ak], chi[ak], clo[iu], chi[iu], clo[iv], chi[iv], lip, cen, st,
             S)
    ok = cell_rules(C, G, seeds, nseed, U_REPROBES, a5, a7)
    if not ok:
        # re-probing can meet a many-way flicker at a tangency and run out of breakpoint
        # slots: the cell is done again without it
        a5[:] = 0.0
        a7[:] = 0.0
        ok = cell_rules(C, G, seeds, nseed, I0, a5, a7)
    if not ok:
        return -1.0
    est = 0.0
    for m in range(10):
        est = max(est, abs(a7[m] - a5[m]))
    if lip > 0 and est == 0.0 and not _has_surface(a7, clo, chi):
        if surface_in_cell(ops, lk, lr, ob, oe, clo, chi, st):
            return math.inf
    return est


@njit(cache=True, inline="always")
def _has_surface(a7, clo, chi):
    """Whether the rule's volume is strictly between empty and full (relative 1e-12)."""
    vol = (chi[0] - clo[0]) * (chi[1] - clo[1]) * (chi[2] - clo[2])
    return SURFACE_FRAC * vol < a7[0] < (1.0 - SURFACE_FRAC) * vol


