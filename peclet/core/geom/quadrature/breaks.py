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
omitted, which prunes the u-level branches before typing.
"""
import types
from collections import namedtuple

import numpy as np
from numba import njit

from .constants import (FLICKER, HASH_STEPS, I0, I1, I2, KINK_SLOPE, KINK_STEPS, R_EXTRA,
                        R_MHI, R_MHP, R_MLO, R_MLP, R_MX, R_MY, R_UBRK, R_UFLAG, R_UKNOT,
                        R_VBRK, R_VFLAG, R_VKNOT, R_XP, R_XT, TRACK_STEPS, U_BACKTRACKS,
                        U_BREAK_STEPS, U_FLICKER, U_FOLLOW, U_NUDGE, U_WIDE, U_ZONE,
                        U_ZONE_BREAKS, U_ZONE_MAX, V_NUDGE, V_PROBES)
from .line_search import mix
from .pieces import (extrapolate, keep_seeds, knots, merge, narrowest_piece, piece_mids,
                     sort_prefix, vsig)

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
    P, ak, iu, iv, a, b, lip, st, S = C.P, C.ak, C.iu, C.iv, C.a, C.b, C.lip, C.st, C.S
    if U is None:
        c0 = C.v0
        c1 = C.v1
        nk = knots(P, iv, iu, ak, c0, c1, u, u, I1, a, b, lip, st, S, R_VKNOT)
        knot = S[R_VKNOT]
        brk = S[R_VBRK]
        flag = S[R_VFLAG]
        nudge = V_NUDGE * (c1 - c0)
        flicker = FLICKER * (c1 - c0)
        step = FLICKER * (c1 - c0)
        track = steps
    else:
        c0 = C.u0
        c1 = C.u1
        nk = knots(P, iu, iv, ak, c0, c1, C.v0, C.v1, I2, a, b, lip, st, S, R_UKNOT)
        knot = S[R_UKNOT]
        brk = S[R_UBRK]
        flag = S[R_UFLAG]
        U.nseed[:] = 0
        nudge = U_NUDGE * (c1 - c0)
        # without re-probes (the fallback after an overflow) the scan is the plain one:
        # hash-level breaks while bisecting, and no probe just past a located break
        track = TRACK_STEPS if U.reprobes > 0 else HASH_STEPS
        flicker = (2.0 if U.reprobes > 0 else 1.0) * U_FLICKER * (c1 - c0)
        step = U_FLICKER * (c1 - c0)
    if nk < 0:
        return -1, _NO_HASH
    zone = U_ZONE * (c1 - c0)
    zone_max = U_ZONE_MAX * (c1 - c0)
    jump = step
    nshort = 0
    nback = 0
    ex = S[R_EXTRA]
    seq = np.uint64(1469598103934665603)
    brk[0] = c0
    flag[0] = 0.0
    m = I1
    # the structure at x (hash, count: v-level roots, u-level midpoints in S[R_MLO], inside
    # length: v-level only) and at the next probe y (u-level midpoints in S[R_MY])
    hx = _NO_HASH
    nx = I0
    lx = 0.0
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
            if U is None:
                hx, nx, lx = vsig(C, u, x)
            else:
                nx, hx = probe_mids(C, x, HASH_STEPS, R_MLO, nx, R_MLO, I0, R_MLO)
            if nx < 0:
                return -1, _NO_HASH
            if U is None:
                seq = mix(seq, hx)
            else:
                keep_seeds(U.seeds, U.nseed, m - 1, S, R_MLO, nx)
            j = int((x - c0) / (c1 - c0) * V_PROBES) + 1
            e = 0
            while e < nex and ex[e] <= x:
                e += 1
            while True:
                y = c0 + (c1 - c0) * j / V_PROBES
                use_extra = e < nex and ex[e] < y
                if use_extra:
                    y = ex[e]
                last = y >= s1 - nudge
                if last:
                    y = s1 - nudge
                if U is None:
                    hy, ny, ly = vsig(C, u, y)
                else:
                    ny, hy = probe_mids(C, y, HASH_STEPS, R_MLO, nx, R_MLO, I0, R_MY)
                    ly = 0.0
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
                            # hi_ was probed with the pieces tracked from a bracket end far
                            # away, so a narrow piece followed up to it may have been missed
                            # there: probe it again with the pieces seen just below it
                            # (2^-U_BREAK_STEPS away)
                            nre += 1
                            mr, hr = probe(C, hi_, track, R_MLO, nx, R_MLO, I0)
                            if mr < 0:
                                return -1, _NO_HASH
                            if hi_ == y:
                                hy = hr
                                ny = piece_mids(S, mr, R_MY)
                            if hr == hx:          # no change at hi_ after all: go on from there
                                x = hi_
                                nx = piece_mids(S, mr, R_MLO)
                                continue
                            if hr != h_hi:
                                h_hi = hr
                                nhi = piece_mids(S, mr, R_MHI)
                    gap = hi_ - brk[m - 1]
                    # a u-level zone lasts while its breaks keep following the step-over (they
                    # are its flicker, as far apart as the step), however wide it grows
                    zoned = False
                    if U is not None:
                        zoned = nshort >= U_ZONE_BREAKS and (gap <= zone or gap <= 4.0 * jump)
                    if gap <= flicker or zoned:
                        # the structure flickers at a tangency (round-off decides whether a
                        # grazing pair of roots is seen): step over the flicker; inside a zone
                        # where breaks keep coming closer than U_ZONE apart (a line family
                        # grazing the surface along u), in doubling steps
                        x = hi_ + (jump if zoned else step)
                        if zoned:
                            jump = min(2.0 * jump, zone_max)
                        if x >= y:
                            break
                        if U is None:
                            hx, nx, lx = vsig(C, u, x)
                        else:
                            nx, hx = probe_mids(C, x, HASH_STEPS, R_MLO, nx, R_MHI, nhi, R_MLO)
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
                        xs = hi_ + step
                        if U.reprobes > 0 and xs < y:
                            # right at the break the structure is degenerate (two creases
                            # crossing leave a piece of zero width), and it may hash like the
                            # structure at y by chance: the next bracket starts just past it
                            x = xs
                            nx, hx = probe_mids(C, x, track, R_MLO, nx, R_MLO, I0, R_MLO)
                            if nx < 0:
                                return -1, _NO_HASH
                x = y
                hx = hy
                if U is None:
                    nx = ny
                    lx = ly
                else:
                    nx = merge(S, R_MY, ny, R_MY, I0, R_MLO)
                    keep_seeds(U.seeds, U.nseed, m - 1, S, R_MLO, nx)
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
