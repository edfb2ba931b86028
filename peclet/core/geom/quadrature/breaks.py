"""The break search: where the integrand of each level stops being smooth.

One scan serves both levels of a cut cell (:func:`_scan`):

- the **v-level** (:func:`vbreaks`): at a fixed u, the changes of the height line's *signature*
  (root count, starting side, active leaf feature per root) along v;
- the **u-level** (:func:`ubreaks`): the changes of the *v-structure* (the hash of the
  v-level's sequence of piece signatures) along u.

Either way the scan walks the knot segments of the cell's extent along its axis (knots: where
a face trace leaves the cell, exact), probes each segment just inside its ends and on the
regular grid of V_PROBES intervals, locates every change between two probes by bisection
(:func:`_locate_v`, :func:`_locate_u`), steps over a change closer to the last break than the
level's flicker threshold (round-off at a tangency deciding what the probe sees), and records
the rest as breaks. What differs by level is marked ``if U is None`` (v-level) in the scan.

Numba cannot type a function calling itself, and the u-level probes the v-level, so the one
scan is compiled as two functions (:func:`_instance`); the v-level one is compiled with ``U``
omitted, which prunes the u-level branches before typing. The scan's helpers that differ by
level take ``U`` too (None there: pruned alike); those that need no probe are in
:mod:`.levels`.
"""
import types
from collections import namedtuple

import numpy as np
from numba import njit
from numba.core import types as nbtypes
from numba.extending import overload

from .constants import (HASH_STEPS, I0, I1, KINK_SLOPE, KINK_STEPS, R_EXTRA, R_MHI, R_MHP,
                        R_MLO, R_MLP, R_MX, R_MY, R_XP, R_XT, U_BACKTRACKS, U_BREAK_STEPS,
                        U_FLICKER, U_FOLLOW, U_WIDE)
from .levels import first_probes, level, next_probe, step_over
from .line_search import mix
from .pieces import extrapolate, keep_seeds, merge, narrowest_piece, piece_mids, sort_prefix, vsig

#: What only the u-level scan carries: the v-piece midpoints seen per u-piece (``seeds``
#: (MAX_BREAKS, SEEDS), their counts ``nseed``) and the number of re-probes per probe interval
#: (0: the plain scan, the fallback after an overflow).
ULevel = namedtuple("ULevel", ["seeds", "nseed", "reprobes"])

_NO_HASH = np.uint64(0)


def _scan(C, u, steps, nex, U=None):
    """Breaks of one level of the cut cell ``C`` (a :data:`.cell_rule.Cell`).

    v-level (``U`` omitted): along v at outer coordinate ``u``. Breaks: the knots (roots of
    phi on the cell's k-faces along v) and every other change of the line signature (a
    crease: the active feature at a root changes; a tangency: two roots merge), located by
    bisection to 2^-steps of the probe interval. S[R_VBRK, 0:m] gets the breaks and
    S[R_VFLAG, 0:m] 1.0 where a break is a tangency (square-root behaviour: the piece is
    smoothed there). Probes: the regular grid and S[R_EXTRA, 0:nex] (sorted), where the
    caller saw pieces at a nearby u: a piece narrower than the grid spacing (vanishing at a
    vertex inside the cell) is followed there instead of being lost between grid points.

    u-level (``U`` a :data:`ULevel`; ``u`` and ``nex`` unused): along u. Breaks: the knots
    (roots of phi along u on the four cell edges (v0|v1, a|b)) and every other change of the
    v-structure hash, into S[R_UBRK], flagged 1.0 in S[R_UFLAG] (a piece appearing or
    vanishing behaves like a power 3/2: smoothed). The v-piece midpoints each u-piece's probes
    saw are kept in ``U.seeds`` (see :func:`.cell_rule.cell_rules`); a run of breaks closer
    than U_ZONE is a flicker zone, stepped over in doubling steps.

    Returns (m, hash of the sequence of piece signatures; v-level only); m = -1 on overflow.
    """
    S = C.S
    (nk, c0, c1, knot, brk, flag, nudge, flicker, step, track, zone,
     zone_max) = level(C, U, u, steps)
    if nk < 0:
        return -1, _NO_HASH
    jump = step
    nshort = 0
    nback = 0
    ex = S[R_EXTRA]
    seq = np.uint64(1469598103934665603)
    brk[0] = c0
    flag[0] = 0.0
    m = I1
    # the structure at x (hash, count: v-level roots, u-level midpoints in S[R_MLO], inside
    # length: v-level only), at the next probe y (S[R_MY]) and at a change (S[R_MHI]: u-level)
    hx = _NO_HASH
    nx = I0
    lx = 0.0
    nhi = I0
    for s in range(nk - 1):
        s0 = knot[s]
        s1 = knot[s + 1]
        if s1 - s0 > 2.0 * nudge:
            # probes: the segment's ends (nudged inside) and the regular grid points in it.
            # The u-level probes the v-structure with extra v-probes at the piece midpoints
            # seen at the neighbouring u (rows R_MLO / R_MHI / R_MY: bracket ends and the next
            # probe), at the segment's start with those seen at the end of the previous
            # segment (a knot ends a face trace, not the narrow pieces that cross it)
            x = s0 + nudge
            hx, nx, lx = _probe(C, U, u, x, nx, R_MLO, I0, R_MLO)
            if nx < 0:
                return -1, _NO_HASH
            if U is None:
                seq = mix(seq, hx)
            else:
                keep_seeds(U.seeds, U.nseed, m - 1, S, R_MLO, nx)
            j, e = first_probes(c0, c1, x, ex, nex)
            while True:
                y, use_extra, last = next_probe(c0, c1, j, ex, e, nex, s1 - nudge)
                hy, ny, ly = _probe(C, U, u, y, nx, R_MLO, I0, R_MY)
                if ny < 0:
                    return -1, _NO_HASH
                nre = 0
                while hx != hy:                   # every change in (x, y], left to right
                    if U is None:
                        hi_, h_hi, n_hi, l_hi = _locate_v(C, u, steps, x, hx, lx, y, hy, ny,
                                                           ly)
                        if n_hi < 0:
                            return -1, _NO_HASH
                    else:
                        # the search may go below x (to just above the last break) a few
                        # times per scan (each such search costs up to ~50 probes)
                        floor = x
                        if nback < U_BACKTRACKS:
                            floor = min(x, brk[m - 1] + max(nudge, step))
                        hi_, h_hi, nx, nhi = _locate_u(C, U, steps, track, x, hx, nx, y, hy,
                                                       ny, floor)
                        if hi_ < x:
                            nback += 1
                        if nx < 0:
                            return -1, _NO_HASH
                        if nre < U.reprobes and hi_ - x > 4.0 * U_FLICKER * (c1 - c0):
                            nre += 1
                            mr, hr, hy, ny, h_hi, nhi, nx = _reprobe(C, track, hx, hi_, h_hi,
                                                                     nhi, nx, y, hy, ny)
                            if mr < 0:
                                return -1, _NO_HASH
                            if hr == hx:          # no change at hi_ after all: go on from there
                                x = hi_
                                continue
                    gap = hi_ - brk[m - 1]
                    over, xs, jump = step_over(U, hi_, gap, nshort, jump, step, flicker, zone,
                                                zone_max)
                    if over:
                        x = xs
                        if x >= y:
                            break
                        hx, nx, lx = _probe(C, U, u, x, nx, R_MHI, nhi, R_MLO)
                        if nx < 0:
                            return -1, _NO_HASH
                        continue
                    if m >= S.shape[1] - 2:
                        return -1, _NO_HASH
                    if U is None:
                        flag[m] = 1.0 if n_hi != nx else 0.0
                    else:
                        nshort = nshort + 1 if gap <= zone else 0
                        jump = step
                        keep_seeds(U.seeds, U.nseed, m - 1, S, R_MLO, nx)
                        keep_seeds(U.seeds, U.nseed, m, S, R_MHI, nhi)
                        flag[m] = 1.0
                    brk[m] = hi_
                    m += 1
                    x = hi_
                    hx = h_hi
                    if U is None:
                        nx = n_hi
                        lx = l_hi
                        seq = mix(seq, hx)
                    else:
                        nx = merge(S, R_MHI, nhi, R_MHI, I0, R_MLO)
                    if hi_ >= y:
                        break
                    if U is not None:
                        x, hx, nx = _past_break(C, U.reprobes, hi_ + step, y, track, x, hx, nx)
                        if nx < 0:
                            return -1, _NO_HASH
                x = y
                hx = hy
                lx = ly                           # 0.0 on the u-level, as from the start
                nx = _carry(C, U, m, ny)
                if last:
                    break
                if use_extra:
                    e += 1
                else:
                    j += 1
        if s < nk - 2:                            # the knot itself closes this segment
            if m >= S.shape[1] - 2:
                return -1, _NO_HASH
            brk[m] = s1
            flag[m] = 0.0
            m += 1
            if U is None:
                seq = mix(seq, 7)
    brk[m] = c1
    flag[m] = 0.0
    return m + 1, seq


def _probe(C, U, u, x, na, rb, nb, dst):
    """The structure at x of the level :func:`_scan` walks. v-level (``U`` None): the line
    signature at (u, x) (:func:`.pieces.vsig`). u-level: the v-structure at x, probed also at
    the piece midpoints S[R_MLO, :na] and S[rb, :nb], its own midpoints kept in S[dst]
    (:func:`probe_mids`). Returns (hash, count, inside length: v-level only, else 0.0);
    count -1 on overflow. Jitted code only (see :func:`_probe_level`)."""
    raise NotImplementedError("_probe is called from jitted code only")


@overload(_probe)
def _probe_level(C, U, u, x, na, rb, nb, dst):
    # one function per level, chosen by U's type as the caller is typed: the u-level's probes
    # the v-level, whose scan calls _probe too, and a single njit function would then be
    # compiling while it is called again, which Numba takes for recursion (an unresolved
    # symbol at run time)
    if isinstance(U, (nbtypes.NoneType, nbtypes.Omitted)):
        def v_level(C, U, u, x, na, rb, nb, dst):
            h, n, length = vsig(C, u, x)
            return h, n, length
        return v_level

    def u_level(C, U, u, x, na, rb, nb, dst):
        n, h = probe_mids(C, x, HASH_STEPS, R_MLO, na, rb, nb, dst)
        return h, n, 0.0
    return u_level


@njit(cache=True)
def _past_break(C, reprobes, xs, y, track, x, hx, nx):
    """Where the u-level's next bracket starts after a break (at x, with hash hx and nx
    midpoints in S[R_MLO]): with re-probes, at xs just past it if that is below y, with the
    v-structure probed there, since right at the break the structure is degenerate (two
    creases crossing leave a piece of zero width) and may hash like the structure at y by
    chance. Returns (x, hx, nx); nx -1 on overflow."""
    if reprobes > 0 and xs < y:
        nx, hx = probe_mids(C, xs, track, R_MLO, nx, R_MLO, I0, R_MLO)
        return xs, hx, nx
    return x, hx, nx


@njit(cache=True)
def _carry(C, U, m, n):
    """The count at x once the scan moves x to its next probe (count n there): v-level the
    roots', u-level the v-piece midpoints', moved from S[R_MY] to S[R_MLO] and kept as seeds
    of the u-piece m - 1."""
    if U is None:
        nx = n
    else:
        S = C.S
        nx = merge(S, R_MY, n, R_MY, I0, R_MLO)
        keep_seeds(U.seeds, U.nseed, m - 1, S, R_MLO, nx)
    return nx


@njit(cache=True)
def _reprobe(C, track, hx, hi_, h_hi, nhi, nx, y, hy, ny):
    """The u-level's change hi_, located by :func:`_locate_u`, probed again with the v-pieces
    seen just below it (S[R_MLO, :nx], 2^-U_BREAK_STEPS away): hi_ was probed with the pieces
    tracked from a bracket end far away, so a narrow piece followed up to it may have been
    missed there. Returns (the probe's break count, -1 on overflow; its hash; hy, ny and
    S[R_MY] updated when hi_ is y; h_hi, nhi and S[R_MHI] updated when the hash at hi_ is
    another; nx, with S[R_MLO] the midpoints at hi_ when the hash there is hx (no change at
    hi_ after all), else as given)."""
    S = C.S
    mr, hr = probe(C, hi_, track, R_MLO, nx, R_MLO, I0)
    if mr < 0:
        return mr, hr, hy, ny, h_hi, nhi, nx
    if hi_ == y:
        hy = hr
        ny = piece_mids(S, mr, R_MY)
    if hr == hx:
        return mr, hr, hy, ny, h_hi, nhi, piece_mids(S, mr, R_MLO)
    if hr != h_hi:
        h_hi = hr
        nhi = piece_mids(S, mr, R_MHI)
    return mr, hr, hy, ny, h_hi, nhi, nx


@njit(cache=True)
def _locate_v(C, u, steps, x, hx, lx, y, hy, ny, ly):
    """The first change of the line signature in (x, y] at outer coordinate u (hx at x, a
    hy at y), by bisection to 2^-steps of the interval, stopped early (past
    KINK_STEPS) where the inside length is continuous across the bracket: a kink, whose
    misplacement costs O(width^2). Returns (the bracket's upper end, its signature, root count
    and inside length); count -1 on overflow."""
    lo_ = x
    hi_ = y
    h_hi = hy
    n_hi = ny
    l_lo = lx
    l_hi = ly
    for it in range(steps):
        if it >= KINK_STEPS and abs(l_hi - l_lo) <= KINK_SLOPE * (hi_ - lo_):
            break                                 # the integrand is continuous here: a kink
        mid = 0.5 * (lo_ + hi_)
        hm, nm, lm = vsig(C, u, mid)
        if nm < 0:
            return hi_, h_hi, -1, l_hi
        if hm == hx:
            lo_ = mid
            l_lo = lm
        else:
            hi_ = mid
            h_hi = hm
            n_hi = nm
            l_hi = lm
    return hi_, h_hi, n_hi, l_hi


@njit(cache=True, inline="always")
def _locate_u(C, U, steps, track, x, hx, nlo, y, hy, ny, floor):
    """The first change of the v-structure hash in (x, y] (hx at x, with its v-piece
    midpoints S[R_MLO, :nlo]; hy at y, midpoints S[R_MY, :ny]), by bisection to 2^-steps.

    Each bisection probe looks for v-pieces at the midpoints seen at both bracket ends and,
    with re-probes, at those extrapolated from each end's previous position (a wedge closing
    at a vertex: its midpoint moves along a line). With re-probes, the lower end is probed
    again with the upper end's pieces, and the search restarts if the change lies below: from
    x, or from ``floor`` (just above the scan's last break) when it lies below x itself (x's
    probe, without those pieces, missed them), following the pieces down from the upper end
    first. Returns (upper end, its hash, count of the lower end's midpoints now in S[R_MLO],
    count of the upper end's in S[R_MHI]); the third is -1 on overflow."""
    S = C.S
    v0 = C.v0
    v1 = C.v1
    lo_ = x
    hi_ = y
    h_hi = hy
    nhi = merge(S, R_MY, ny, R_MY, I0, R_MHI)
    nx0 = merge(S, R_MLO, nlo, R_MLO, I0, R_MX)
    for attempt in range(U.reprobes + 1):
        # each end's previous midpoints (count -1: none yet) to extrapolate
        nlp = -I1
        nhp = -I1
        ulp = lo_
        uhp = hi_
        # a later attempt first follows hi_'s pieces down from hi_ in doubling steps (each
        # probe where the extrapolation from the last two puts them) until they are gone,
        # then bisects that last step: a wedge whose midpoint runs faster than it closes is
        # lost by a bisection's first probes, far from hi_, but not by small steps from it
        h = U_FOLLOW * (hi_ - lo_) if attempt > 0 else 0.0
        it = 0
        while it < steps:
            if h > 0.0 and hi_ - h > lo_:
                mid = hi_ - h
            else:
                h = 0.0
                mid = 0.5 * (lo_ + hi_)
                it += 1
            nxp = I0
            if U.reprobes > 0:
                nxp = extrapolate(S, R_MLO, nlo, lo_, R_MLP, nlp, ulp, mid, v0, v1, I0)
                nxp = extrapolate(S, R_MHI, nhi, hi_, R_MHP, nhp, uhp, mid, v0, v1, nxp)
            sort_prefix(S[R_XP], nxp)
            nt = merge(S, R_MLO, nlo, R_MHI, nhi, R_XT)
            mm, hm = probe(C, mid, track, R_XT, nt, R_XP, nxp)
            if mm < 0:
                return hi_, h_hi, -1, nhi
            if hm == hx:
                nlp = merge(S, R_MLO, nlo, R_MLO, I0, R_MLP)
                ulp = lo_
                lo_ = mid
                nlo = piece_mids(S, mm, R_MLO)
                h = 0.0
            else:
                nhp = merge(S, R_MHI, nhi, R_MHI, I0, R_MHP)
                uhp = hi_
                hi_ = mid
                h_hi = hm
                nhi = piece_mids(S, mm, R_MHI)
                h *= 2.0
        if attempt == U.reprobes or lo_ <= floor:
            break
        # lo_ was probed with the pieces tracked from its own side, so a piece thinning
        # towards lo_ (a wedge closing at a vertex further down, whose midpoint moves faster
        # than it opens) may have been missed there: probe lo_ with hi_'s pieces, and if the
        # change lies below, search again
        mr, hr = probe(C, lo_, track, R_MLO, nlo, R_MHI, nhi)
        if mr < 0:
            return hi_, h_hi, -1, nhi
        if hr == hx:
            break
        if lo_ <= x and narrowest_piece(S, mr) <= U_WIDE * (v1 - v0):
            # at x itself only a structure of wide pieces is followed below it: a narrow
            # one is a tangency's flicker (round-off deciding a grazing pair of roots), and
            # following each of those down through a grazing zone costs minutes
            break
        hi_ = lo_
        h_hi = hr
        nhi = piece_mids(S, mr, R_MHI)
        # the change lies below: in (x, hi_), or below x, which the scan passed as unchanged
        # because x's probe did not look where hi_'s pieces are
        lo_ = x if hi_ > x else floor
        nlo = merge(S, R_MX, nx0, R_MX, I0, R_MLO)
    return hi_, h_hi, nlo, nhi


def _instance(fn, name):
    """A separately compiled copy of ``fn`` named ``name`` (its own cache entry)."""
    f = types.FunctionType(fn.__code__, fn.__globals__, name, fn.__defaults__)
    f.__qualname__ = name
    f.__doc__ = fn.__doc__
    return njit(cache=True)(f)


#: The v-level scan: ``vbreaks(C, u, steps, nex) -> (m, hash)`` (see :func:`_scan`).
vbreaks = _instance(_scan, "vbreaks")
_uscan = _instance(_scan, "ubreaks_scan")


@njit(cache=True, inline="always")
def probe(C, u, steps, ra, na, rb, nb):
    """The v-structure at u (:func:`vbreaks`), probed also at S[ra, :na] and S[rb, :nb]
    (each sorted): (break count, hash); count -1 on overflow."""
    nex = merge(C.S, ra, na, rb, nb, R_EXTRA)
    return vbreaks(C, u, steps, nex)


@njit(cache=True, inline="always")
def probe_mids(C, u, steps, ra, na, rb, nb, dst):
    """:func:`probe`, keeping the piece midpoints (either source row may be dst): (count of
    the midpoints, now in S[dst], hash); count -1 on overflow."""
    m, h = probe(C, u, steps, ra, na, rb, nb)
    if m < 0:
        return -1, h
    return piece_mids(C.S, m, dst), h


@njit(cache=True, inline="always")
def ubreaks(C, seeds, nseed, reprobes):
    """The u-level scan of the cut cell ``C`` (see :func:`_scan`): the count m of u-breaks
    in S[R_UBRK, :m] (flags in S[R_UFLAG]), -1 on overflow."""
    return _uscan(C, 0.0, U_BREAK_STEPS, 0, ULevel(seeds, nseed, reprobes))[0]
