"""Where the inner (v) integrand is smooth: knots, line signatures and the v-pieces' midpoints.

The break search (:mod:`.breaks`) probes the structure of the height lines across a cell.
This module holds what a probe sees and what is carried between probes: the *knots* (roots of
phi on a cell's faces or edges, where a face trace leaves the cell), a line's signature and
inside length, the Gauss node of a piece (smoothed at a tangency), and the midpoints of the
v-pieces, kept so that a piece narrower than the probe grid is looked for where it was seen.
"""
import numpy as np
from numba import njit

from .constants import I0, R_KLEAF, R_KROOT, R_LEAF, R_ROOT, R_VBRK, R_XP
from .line_search import Line, line_roots, run_moments, signature, sort_prefix


@njit(cache=True)
def knots(C, ax, f1, lo, hi, c1lo, c1hi, n1, row):
    """Sorted roots in (lo, hi) of phi along axis ``ax`` on the lines of the cut cell ``C``
    (a :data:`.cell_rule.Cell`) whose other two coordinates, on axes f1 and the height axis
    C.ak, are (c1, c2) for c1 in (c1lo, c1hi)[:n1] and c2 in (C.a, C.b) -- two lines on a
    cell face (n1 = 1) or a cell's four edges (n1 = 2): where the solid's trace on a cell face
    or edge changes sign. Written to S[row, 1:m+1] between S[row, 0] = lo and S[row, m+1] =
    hi; returns m + 2, or -1 on overflow. Found by the certified line search, so none is
    missed on a 1-Lipschitz tree."""
    S = C.S
    n = I0
    for i in range(2 * n1):
        c1 = c1lo if i < 2 else c1hi
        c2 = C.a if i % 2 == 0 else C.b
        nr, _ = line_roots(Line(C.P, ax, f1, C.ak, c1, c2, C.st), lo, hi, C.lip, S[R_KROOT],
                           S[R_KLEAF], n)
        if nr < 0:
            return -1
        n += nr
    if n + 2 > S.shape[1]:
        return -1
    kr = S[R_KROOT]
    sort_prefix(kr, n)
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
def vsig(C, u, v):
    """(signature, root count, inside length) of the height line at (u, v) of the cut cell
    ``C``; count -1 on overflow. The roots are left in S[R_ROOT], S[R_LEAF]."""
    S = C.S
    roots = S[R_ROOT]
    nr, ins = line_roots(Line(C.P, C.ak, C.iu, C.iv, u, v, C.st), C.a, C.b, C.lip, roots,
                         S[R_LEAF], I0)
    if nr < 0:
        return np.uint64(0), -1, 0.0
    length, _, _ = run_moments(nr, ins, roots, C.a, C.b, 0.0)
    return signature(nr, ins, S[R_LEAF]), nr, length


@njit(cache=True, inline="always")
def piece_node(p0, p1, x, s0, s1):
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
def piece_mids(S, m, row):
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
def narrowest_piece(S, m):
    """The width of the narrowest of the m - 1 v-pieces in S[R_VBRK] (of positive width)."""
    brk = S[R_VBRK]
    w = np.inf
    for i in range(m - 1):
        d = brk[i + 1] - brk[i]
        if 0.0 < d < w:
            w = d
    return w


@njit(cache=True)
def merge(S, ra, na, rb, nb, dst):
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
def extrapolate(S, rnow, nnow, unow, rprev, nprev, uprev, u, v0, v1, k):
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
def keep_seeds(seeds, nseed, piece, S, row, n):
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
def sorted_seeds(seeds, nseed, piece, S, row):
    """The seeds of u-piece ``piece``, sorted, into S[row]; returns their count."""
    n = nseed[piece]
    for k in range(n):      # element copies: a slice assignment compiles a shape-mismatch
        S[row, k] = seeds[piece, k]     # message (seconds of a cold start)
    sort_prefix(S[row], n)
    return n


