"""The simulation's box: an axis-aligned domain [lo, hi) and which of its axes are periodic."""
from __future__ import annotations

import numpy as np
from numba import njit

from peclet.core.validation import PecletArgumentError, check_array, check_bool
from peclet.dem.limits import MIN_LENGTH, check_magnitudes


class Domain:
    """``lo``/``hi`` (3,) world-frame bounds (None until set) and ``periodic`` (3,) bools.

    The box is used by periodic axes (wrap, minimum images) and by the speed guard (its size);
    a periodic axis needs the box before stepping."""

    def __init__(self):
        self.lo = None
        self.hi = None
        self.periodic = np.zeros(3, np.bool_)

    @property
    def periodic(self):
        """(3,) bools: which axes are periodic (set through :meth:`set_periodic`)."""
        return self._periodic

    @periodic.setter
    def periodic(self, value):
        self._periodic = np.asarray(value, np.bool_)
        #: whether any axis is periodic (a step asks several times)
        self.any_periodic = bool(self._periodic.any())

    def set_box(self, lo, hi):
        """The box [lo, hi): coordinates of magnitude <= 1e100, each side hi - lo in
        [1e-100, 2e100] (length; :mod:`peclet.dem.limits`)."""
        lo = check_array("lo", lo, (3,))
        hi = check_array("hi", hi, (3,))
        if not np.all(hi > lo):
            raise PecletArgumentError("hi", "greater than lo on every axis of the domain",
                                      hi.tolist(), f"lo = {lo.tolist()}")
        check_magnitudes("lo", lo, lo.tolist(), "coordinates")
        check_magnitudes("hi", hi, hi.tolist(), "coordinates")
        if not np.all(hi - lo >= MIN_LENGTH):
            raise PecletArgumentError("hi", f"at least {MIN_LENGTH:g} above lo on every axis "
                                      "(a domain side is a length)", hi.tolist(),
                                      f"lo = {lo.tolist()}")
        self.lo, self.hi = lo.copy(), hi.copy()

    def set_periodic(self, px, py, pz):
        self.periodic = np.array([check_bool("px", px), check_bool("py", py),
                                  check_bool("pz", pz)], np.bool_)

    def check_ready(self):
        if self.any_periodic and self.lo is None:
            raise PecletArgumentError("periodic axes", "used with a domain: call "
                                      "set_domain(lo, hi) first", self.periodic.tolist())

    def check_cutoff(self, cutoff):
        """A periodic axis must be longer than twice the interaction cutoff (minimum image)."""
        for a in np.flatnonzero(self.periodic):
            L = self.hi[a] - self.lo[a]
            if L <= 2.0 * cutoff:
                raise PecletArgumentError(
                    f"domain (periodic axis {a})", f"longer than twice the interaction "
                    f"cutoff {cutoff} (2 * largest bounding radius + margin)", float(L))

    def wrap(self, pos):
        """Move ``pos`` (N, 3) into [lo, hi) along every periodic axis, in place; returns it."""
        if self.any_periodic:
            wrap_into(pos, self.lo, self.hi, self.periodic)
        return pos

    def grid_box(self):
        """(lo, hi) for the broad phase's grid: the domain, else the unit box."""
        return (self.lo if self.lo is not None else np.zeros(3),
                self.hi if self.hi is not None else np.ones(3))


@njit(cache=True)
def wrap_into(pos, lo, hi, periodic):
    """:meth:`Domain.wrap` on (N, 3) ``pos`` in place: lo + (p - lo) mod L (Python's and
    NumPy's float modulo: the result takes L's sign), and lo where that rounds up to hi."""
    for a in range(3):
        if not periodic[a]:
            continue
        L = hi[a] - lo[a]
        for i in range(pos.shape[0]):
            p = lo[a] + (pos[i, a] - lo[a]) % L
            pos[i, a] = lo[a] if p >= hi[a] else p
