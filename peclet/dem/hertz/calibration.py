"""The Hertz engine's calibrations: the dashpot coefficient that rebounds at a pair's ``e_n``
(Hertz law and the distributed contacts' linear law), the elliptical Hertz correction table,
and the Rayleigh time of the step-size check (docstring of :mod:`peclet.dem.hertz`, "Damping
law and why", "Step-size check"; :mod:`peclet.dem.hertz.patch` for the elliptical table)."""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from numba import njit

from peclet.core.validation import check_float

#: dt may be at most this fraction of the smallest Rayleigh time of the bodies.
RAYLEIGH_FRACTION = 0.3

#: Restitution coefficients the damping can reproduce (below, gamma grows without bound).
E_MIN = 0.01

#: Dimensionless RK4 step of the restitution calibration (the undamped contact lasts 3.218).
_CAL_STEP = 2e-5

#: The elliptical table's largest ratio of the principal radii of relative curvature (a patch
#: beyond it is refused as line-like, :mod:`peclet.dem.hertz.patch`).
RATIO_LIMIT = 100.0


@njit(cache=True)
def _rhs(x, u, g, linear):
    # overlap x, approach speed u: x' = u, u' = -max(0, x^1.5 + g x^0.25 u) (Hertz), or
    # u' = -max(0, x + g u) (linear: the distributed contact's calibration)
    if x <= 0.0:
        return 0.0
    f = x + g * u if linear else x ** 1.5 + g * x ** 0.25 * u
    return -f if f > 0.0 else 0.0


@njit(cache=True)
def rebound_speed(g, h, linear):
    """Rebound speed of the dimensionless damped impact (approach speed 1) with the
    coefficient ``g`` of the damping term (Hertz: ``g`` = sqrt(3/2) gamma in front of
    ``x^(1/4) x'``; ``linear``: in front of ``x'`` of ``x'' = -max(0, x + g x')``), by RK4 of
    step ``h``; the exit is interpolated linearly in the last step."""
    x = 0.0
    u = 1.0
    for _ in range(100_000_000):
        k1x = u
        k1u = _rhs(x, u, g, linear)
        k2x = u + 0.5 * h * k1u
        k2u = _rhs(x + 0.5 * h * k1x, u + 0.5 * h * k1u, g, linear)
        k3x = u + 0.5 * h * k2u
        k3u = _rhs(x + 0.5 * h * k2x, u + 0.5 * h * k2u, g, linear)
        k4x = u + h * k3u
        k4u = _rhs(x + h * k3x, u + h * k3u, g, linear)
        xn = x + h / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x)
        un = u + h / 6.0 * (k1u + 2.0 * k2u + 2.0 * k3u + k4u)
        if xn <= 0.0 and un < 0.0:
            return -un
        x = xn
        u = un
    return 0.0


def _restitution(gamma):
    return float(rebound_speed(math.sqrt(1.5) * gamma, _CAL_STEP, False))


@lru_cache(maxsize=4096)
def damping_gamma(e):
    """The dimensionless damping ``gamma`` (>= 0) with which the clamped Hertz law rebounds at
    ``e`` times the approach speed (``e`` in [E_MIN, 1]; 1 gives 0): Brent's root of the
    calibration ODE of the module docstring, to 1e-12 relative (the ODE itself is good to
    ~1e-7)."""
    e = check_float("e_n", e, E_MIN, 1.0)
    if e == 1.0:
        return 0.0
    from scipy.optimize import brentq
    hi = 1.0
    while _restitution(hi) > e:
        hi *= 2.0
    return float(brentq(lambda g: _restitution(g) - e, 0.0, hi, xtol=1e-14, rtol=1e-12))


def edem_gamma(e):
    """The linear-spring coefficient used by EDEM/LIGGGHTS, ``2 sqrt(5/6) |beta|`` with
    ``beta = ln e / sqrt(ln^2 e + pi^2)`` (for comparison; the engine uses
    :func:`damping_gamma`)."""
    if e >= 1.0:
        return 0.0
    le = math.log(e)
    return 2.0 * math.sqrt(5.0 / 6.0) * (-le) / math.sqrt(le * le + math.pi ** 2)


def restitution_of(gamma):
    """The restitution the clamped damped Hertz law gives with ``gamma`` (calibration ODE)."""
    return _restitution(float(gamma))


def rayleigh_time(radius, density, youngs, poisson):
    """Rayleigh-wave time ``pi R sqrt(rho / G) / (0.1631 nu + 0.8766)``, ``G = E / (2 (1 +
    nu))`` (s, for SI input); arrays broadcast."""
    g = youngs / (2.0 * (1.0 + poisson))
    return math.pi * radius * np.sqrt(density / g) / (0.1631 * poisson + 0.8766)



@lru_cache(maxsize=4096)
def damping_gamma_linear(e):
    """:func:`damping_gamma` for a distributed contact: the ``gamma`` with which the clamped
    linear law ``F = S delta + gamma sqrt(S m*) delta'`` (S constant) rebounds at ``e``."""
    e = check_float("e_n", e, E_MIN, 1.0)
    if e == 1.0:
        return 0.0
    from scipy.optimize import brentq

    def rest(g):
        return float(rebound_speed(g, _CAL_STEP, True))
    hi = 1.0
    while rest(hi) > e:
        hi *= 2.0
    return float(brentq(lambda g: rest(g) - e, 0.0, hi, xtol=1e-14, rtol=1e-12))


@lru_cache(maxsize=1)
def elliptic_table():
    """(t (K,), c (K,)): the elliptical Hertz correction ``c = F2^-3`` at ``t = ln(R''/R')``,
    R'' >= R' the principal radii of relative curvature, on a uniform grid of t in [0,
    ln RATIO_LIMIT]. Exact elliptical Hertz theory (Johnson, Contact Mechanics, 1985, §4.2)
    gives ``F = 4/3 E* sqrt(R_e / F2^3) delta^(3/2)`` with ``R_e = sqrt(R' R'')``; F2 (<= 1,
    0.993 at a ratio 2, 0.93 at 10, 0.79 at 100) is found here from the ellipse's
    eccentricity (complete elliptic integrals, Brent's method)."""
    from scipy.optimize import brentq
    from scipy.special import ellipe, ellipk

    def ratio(m):       # B / A of the contact ellipse of eccentricity^2 m
        k, e = ellipk(m), ellipe(m)
        return (e / (1.0 - m) - k) / (k - e)

    t = np.linspace(0.0, math.log(RATIO_LIMIT), 401)
    c = np.ones_like(t)
    for i in range(1, len(t)):
        lam = math.exp(t[i])
        m = brentq(lambda m: ratio(m) - lam, 1e-12, 1.0 - 1e-15, xtol=1e-15, rtol=1e-14)
        k, e = ellipk(m), ellipe(m)
        b = math.sqrt(1.0 - m)                  # a = 1, p0 = 1, E* = 1
        fa = b / m * (k - e)
        fb = b / m * (e / (1.0 - m) - k)
        force = 2.0 / 3.0 * math.pi * b
        delta = b * k
        re = 1.0 / (2.0 * math.sqrt(fa * fb))
        f2 = delta / (9.0 * force * force / (16.0 * re)) ** (1.0 / 3.0)
        c[i] = f2 ** -3.0
    return t, c
