"""What the break scan's two levels differ in, its probe grid, and its step over a flicker.

Helpers of :func:`.breaks._scan` (see there and :mod:`.breaks` for the scan itself): the
extent, knots, scratch rows and thresholds of the v-level (``U`` None) or the u-level (``U`` a
:data:`.breaks.ULevel`), where a segment's probes go, and whether a located change is a
tangency's flicker to step over. ``U`` is passed so that Numba prunes the other level's
branches before typing (a None argument), as in the scan.
"""
from numba import njit

from .constants import (FLICKER, HASH_STEPS, I1, I2, R_UBRK, R_UFLAG, R_UKNOT, R_VBRK, R_VFLAG,
                        R_VKNOT, TRACK_STEPS, U_FLICKER, U_NUDGE, U_ZONE, U_ZONE_BREAKS,
                        U_ZONE_MAX, V_NUDGE, V_PROBES)
from .pieces import knots


@njit(cache=True)
def level(C, U, u, steps):
    """What differs by level in the scan of the cut cell ``C`` (``U`` None: the v-level at
    outer coordinate u; a :data:`.breaks.ULevel`: the u-level): (the knot count, -1 on
    overflow; the extent c0, c1 along the level's axis; its rows of S for the knots, the
    breaks and their flags; the nudge of a segment's end probes inside it, the flicker
    threshold and the step over a flicker; the bisection depth of the probes that track
    pieces; the u-level's zone threshold and widest step in a zone), lengths along that
    axis."""
    S = C.S
    if U is None:
        c0 = C.v0
        c1 = C.v1
        nk = knots(C, C.iv, C.iu, c0, c1, u, u, I1, R_VKNOT)
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
        nk = knots(C, C.iu, C.iv, c0, c1, C.v0, C.v1, I2, R_UKNOT)
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
    zone = U_ZONE * (c1 - c0)
    zone_max = U_ZONE_MAX * (c1 - c0)
    return nk, c0, c1, knot, brk, flag, nudge, flicker, step, track, zone, zone_max


@njit(cache=True)
def first_probes(c0, c1, x, ex, nex):
    """The first grid point j (of the V_PROBES intervals of [c0, c1]) and the first extra
    probe e (in ex[:nex], sorted) above a segment's first probe x."""
    j = int((x - c0) / (c1 - c0) * V_PROBES) + 1
    e = 0
    while e < nex and ex[e] <= x:
        e += 1
    return j, e


@njit(cache=True)
def next_probe(c0, c1, j, ex, e, nex, end):
    """The scan's next probe in a segment whose last probe is ``end``: grid point j of the
    V_PROBES intervals of [c0, c1], or the extra probe ex[e] (e < nex) if it lies below that,
    or ``end`` if that is not below it. Returns (the probe, whether it is ex[e], whether it
    is the segment's last)."""
    y = c0 + (c1 - c0) * j / V_PROBES
    use_extra = e < nex and ex[e] < y
    if use_extra:
        y = ex[e]
    last = y >= end
    if last:
        y = end
    return y, use_extra, last


@njit(cache=True)
def step_over(U, hi_, gap, nshort, jump, step, flicker, zone, zone_max):
    """Whether the change at hi_, ``gap`` past the scan's last break, is a flicker to step
    over, and where the scan goes on: the structure flickers at a tangency (round-off decides
    whether a grazing pair of roots is seen), so a change closer than ``flicker`` to the last
    break is stepped over by ``step``. On the u-level (``U`` not None), inside a zone where
    ``nshort`` breaks in a row came closer than ``zone`` apart (a line family grazing the
    surface along u), in doubling steps ``jump`` (up to ``zone_max``): a zone lasts while its
    breaks keep following the step-over (they are its flicker, as far apart as the step),
    however wide it grows. Returns (step over?, where to go on, the next jump)."""
    zoned = False
    if U is not None:
        zoned = nshort >= U_ZONE_BREAKS and (gap <= zone or gap <= 4.0 * jump)
    if gap <= flicker or zoned:
        x = hi_ + (jump if zoned else step)
        if zoned:
            jump = min(2.0 * jump, zone_max)
        return True, x, jump
    return False, hi_, jump
