"""Known-bad impact engines, and their correct twin, for the family's own tests: a normal-only
two-body Hertz integrator (no friction, no spin: it declares neither, so tests 4-8 are "not
claimed") whose effective radius and damping form can be planted wrong.

- :func:`twin`: R* = R1 R2 / (R1 + R2), Tsuji-form damping c = gamma sqrt(m* k_n(delta))
  (k_n = 2 E* sqrt(R* delta)), gamma calibrated to e once: a restitution independent of speed.
  Passes tests 1-3.
- :func:`wrong_radius`: R* = R1 + R2 (the sum, a classic slip for the harmonic mean) between
  two spheres (right against a plane). Fails test 1 only.
- :func:`speed_dependent_damping`: a constant viscous coefficient c, calibrated to e at the
  benchmark's 3.9 m/s: e then depends on speed (1 - e grows as v^(1/5)). It still declares
  "restitution", which is the false claim test 3 catches. Fails test 3 only.
"""
from __future__ import annotations

import math

import numpy as np

from .backend import follow_impact

__all__ = ["TwoBodyHertz", "twin", "wrong_radius", "speed_dependent_damping"]

#: the speed (m/s) a constant damping coefficient is calibrated at (test 3's nominal)
CALIBRATION_SPEED = 3.9


class TwoBodyHertz:
    """Normal impacts of two balls (or a ball and the plane) by a semi-implicit Euler step of
    the relative motion: m* delta'' = -max(0, 4/3 E* sqrt(R*) delta^1.5 + c delta')."""

    model = {"normal": "hertz", "damping": "", "tangential": "none"}
    capabilities = frozenset({"sphere_sphere", "sphere_wall", "unequal_spheres", "restitution"})

    def __init__(self, radius_rule="harmonic", damping="tsuji", name=None):
        self.radius_rule, self.damping = radius_rule, damping
        self.model = dict(self.model, damping=damping)
        self.name = name or f"two-body Hertz ({radius_rule} R*, {damping} damping)"
        self._gamma = {}

    def _rstar(self, case):
        r = [b.radius for b in case.balls]
        if case.wall:
            return r[0]
        return r[0] + r[1] if self.radius_rule == "sum" else r[0] * r[1] / (r[0] + r[1])

    def _run(self, m, rstar, estar, v, dt, gamma, record=False):
        """(e, delta_max, f_max, contact_time) of one impact at approach speed v."""
        state = {"d": 0.0, "dv": v, "f": 0.0}

        def advance():
            d, dv = state["d"], state["dv"]
            if d > 0.0:
                k = 4.0 / 3.0 * estar * math.sqrt(rstar) * d ** 1.5
                c = gamma * (math.sqrt(m * 2.0 * estar * math.sqrt(rstar * d))
                             if self.damping == "tsuji" else 1.0)
                f = max(0.0, k + c * dv)
            else:
                f = 0.0
            state["f"] = f
            state["dv"] = dv - f / m * dt
            state["d"] = d + state["dv"] * dt

        tc = 3.0 * (m * m / (rstar * estar * estar * v)) ** 0.2
        dmax, fmax, t = follow_impact(advance, lambda: state["d"], lambda: state["f"], dt,
                                      int(50 * tc / dt) + 100)
        return -state["dv"] / v, dmax, fmax, t

    def _calibrate(self, m, rstar, estar, e, v, dt):
        """gamma giving restitution e at speed v (bisection on the run itself)."""
        if e >= 1.0:
            return 0.0
        lo, hi = 0.0, 1.0
        while self._run(m, rstar, estar, v, dt, hi)[0] > e:
            hi *= 2.0
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if self._run(m, rstar, estar, v, dt, mid)[0] > e else (lo, mid)
        return 0.5 * (lo + hi)

    def impact(self, case):
        m, _, estar = case.effective()
        rstar = self._rstar(case)
        v = case.approach
        v_cal = v if self.damping == "tsuji" else CALIBRATION_SPEED
        dt_cal = case.dt * (v / v_cal) ** 0.2   # t_c ~ v^(-1/5): the same resolution
        key = (m, rstar, estar, case.e, v_cal if self.damping != "tsuji" else None)
        if key not in self._gamma:
            self._gamma[key] = self._calibrate(m, rstar, estar, case.e, v_cal, dt_cal)
        e, dmax, fmax, t = self._run(m, rstar, estar, v, case.dt, self._gamma[key])
        p = m * v * (1.0 + e)               # the normal impulse, along +x on ball 1
        vel = np.array([b.v for b in case.balls], float)
        vel[0, 0] -= p / case.balls[0].mass
        if not case.wall:
            vel[1, 0] += p / case.balls[1].mass
        return {"v": vel, "w": np.array([b.w for b in case.balls], float), "delta_max": dmax,
                "f_max": fmax, "contact_time": math.nan if t is None else t}


def twin():
    """The correct two-body engine (passes tests 1-3)."""
    return TwoBodyHertz()


def wrong_radius():
    """R* = R1 + R2 between two spheres (fails test 1)."""
    return TwoBodyHertz(radius_rule="sum", name="planted: R* = R1 + R2")


def speed_dependent_damping():
    """A constant viscous coefficient calibrated at 3.9 m/s, claiming restitution (fails
    test 3)."""
    return TwoBodyHertz(damping="viscous", name="planted: constant viscous damping")
