"""The extreme-but-finite numbers a DEM simulation accepts (issue 45, class 3), in one place.

A step forms products and quotients of the user's numbers: volumes and inertias (r^3, r^5),
the default inverse moment ``2.5 inv_mass / r^2``, kinetic energies ``v^2 / inv_mass``, the
speculative reach ``|v| dt``, a wall's surface speed ``|omega| |p - c|``, gaps over ``dt``.
Each of those stays a normal float64 (between about 1e-308 and 1.8e308) when every factor is
a magnitude within [:data:`MIN_MAGNITUDE`, :data:`MAX_MAGNITUDE`] = [1e-100, 1e100] (or an
exact 0 where 0 has a meaning): a product or quotient of three such numbers is within
[1e-300, 1e300]. So, in the units the caller uses consistently:

- lengths that are divided by or raised to powers (sphere radii, a composed particle's
  bounding radius, a scaled body's radius, the domain's sides) lie in [1e-100, 1e100], and
  positions, domain bounds and a wall's centre have magnitudes <= 1e100;
- the bounding radii in use span at most :data:`MAX_SIZE_RATIO` = 1e6 (largest over
  smallest): the broad phase's cells follow the largest, the speculative margin and the slop
  follow the smallest, and beyond a millionfold neither means anything for the other;
- scales lie in [:data:`MIN_SCALE`, 1000] (1e-6: a millionth of the shape, the size ratio);
- inverse masses and inverse moments are 0 or in [1e-100, 1e100], also after a scale change
  divides them by (s'/s)^3 and (s'/s)^5;
- body speeds |v| and angular speeds |omega| are <= 1e100 (length/time, rad/time), a wall's
  linear and angular speeds too; a wall whose surface speed at a body exceeds the step's speed
  bound (the guard's 1e3 domain sizes per unit time) is refused when the step starts;
- a time step lies in [1e-100, 1e100].

Gravity and external loads keep any finite value (an overflowing ``g dt`` is caught by the
step's guard, whose :class:`~peclet.dem.guards.StepError` then names the gravity or load).
"""
from __future__ import annotations

import numpy as np

from peclet.core.validation import PecletArgumentError

__all__ = ["MIN_MAGNITUDE", "MAX_MAGNITUDE", "MIN_LENGTH", "MAX_LENGTH", "MAX_SIZE_RATIO",
           "MIN_SCALE", "MIN_INVERSE", "MAX_INVERSE", "MAX_SPEED", "MIN_DT", "MAX_DT",
           "check_length", "check_magnitudes", "check_inverses", "check_row_norms",
           "check_size_ratio"]

#: The smallest and largest non-zero magnitude of a number a step divides by or multiplies.
MIN_MAGNITUDE = 1e-100
MAX_MAGNITUDE = 1e100
#: Radii, bounding radii and domain sides (length).
MIN_LENGTH, MAX_LENGTH = MIN_MAGNITUDE, MAX_MAGNITUDE
#: Largest over smallest bounding radius in use (registered shapes and scaled bodies).
MAX_SIZE_RATIO = 1e6
#: The smallest scale (the largest is :data:`peclet.dem.scales.MAX_SCALE`).
MIN_SCALE = 1e-6
#: Non-zero inverse masses (1/mass) and inverse principal moments (1/(mass length^2)).
MIN_INVERSE, MAX_INVERSE = MIN_MAGNITUDE, MAX_MAGNITUDE
#: Body and wall speeds (length/time) and angular speeds (rad/time).
MAX_SPEED = MAX_MAGNITUDE
#: Time steps (time).
MIN_DT, MAX_DT = MIN_MAGNITUDE, MAX_MAGNITUDE


def check_length(name, value):
    """``value`` (already a finite float > 0) checked to lie in [MIN_LENGTH, MAX_LENGTH]."""
    if not MIN_LENGTH <= value <= MAX_LENGTH:
        raise PecletArgumentError(name, f"a finite number in [{MIN_LENGTH:g}, {MAX_LENGTH:g}]"
                                  " (a length: its volume and inertia, r^3 and r^5, must stay "
                                  "float64 numbers)", value)
    return value


def check_magnitudes(name, arr, original, what="entries"):
    """Refuse an array (finite float64) holding a magnitude above MAX_MAGNITUDE."""
    if arr.size and float(np.abs(arr).max()) > MAX_MAGNITUDE:
        i = int(np.argmax(np.abs(arr).ravel()))
        raise PecletArgumentError(name, f"{what} of magnitude <= {MAX_MAGNITUDE:g}", original,
                                  f"entry {tuple(int(k) for k in np.unravel_index(i, arr.shape))}"
                                  f" is "
                                  f"{arr.ravel()[i]:g}")


def check_inverses(name, arr, original, detail=""):
    """Refuse non-zero entries of ``arr`` (>= 0) outside [MIN_INVERSE, MAX_INVERSE]."""
    bad = (arr != 0.0) & ((arr < MIN_INVERSE) | ~(arr <= MAX_INVERSE))
    if np.any(bad):
        i = int(np.flatnonzero(bad.ravel())[0])
        row = np.unravel_index(i, arr.shape)[0]
        raise PecletArgumentError(name, f"entries that are 0 or in [{MIN_INVERSE:g}, "
                                  f"{MAX_INVERSE:g}] (a mass or moment whose inverse, square "
                                  "and products stay float64 numbers)", original,
                                  f"body {row}: {arr.ravel()[i]:g}{detail}")


def check_row_norms(name, arr, original, bound=MAX_SPEED, unit="length/time"):
    """Refuse rows of ``arr`` (N, 3) whose Euclidean norm exceeds ``bound``."""
    if not len(arr):
        return
    norms = np.hypot(np.hypot(arr[:, 0], arr[:, 1]), arr[:, 2])     # never overflows
    if float(norms.max()) > bound:
        i = int(np.argmax(norms))
        raise PecletArgumentError(name, f"rows of norm <= {bound:g} ({unit})", original,
                                  f"row {i} has norm {norms[i]:g}")


def check_size_ratio(name, value, radii, detail=""):
    """Refuse ``value`` when the bounding radii ``radii`` (in use) together with it span more
    than MAX_SIZE_RATIO."""
    r = np.asarray(radii, np.float64)
    if not r.size:
        return
    lo, hi = min(float(r.min()), float(np.min(value))), max(float(r.max()),
                                                           float(np.max(value)))
    if hi > MAX_SIZE_RATIO * lo * (1.0 + 1e-12):       # the bound itself is accepted
        raise PecletArgumentError(name, f"within a factor {MAX_SIZE_RATIO:g} of every other "
                                  f"bounding radius in use (now [{float(r.min()):g}, "
                                  f"{float(r.max()):g}]: the broad phase's cells follow the "
                                  "largest, the contact margins the smallest)",
                                  _scalar(value), detail)


def _scalar(value):
    a = np.asarray(value)
    return float(a) if a.ndim == 0 else value
