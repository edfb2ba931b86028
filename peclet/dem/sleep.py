"""Deterministic sleeping of bodies at rest (off by default; with it off nothing changes).

A settled bed spends most of its step on contacts that do nothing. With sleeping on
(:meth:`peclet.dem.Simulation.set_sleeping`), a body whose surface speed ``|v| + |omega| r``
stayed below ``speed`` for ``steps`` consecutive steps, and whose every contact partner did
too (or sleeps), falls asleep: its velocities are set to exactly zero and, until it wakes, the
step treats it as fixed (inverse mass and inertia 0 in the solves, no gravity, no motion) and
skips the narrow phase of its pairs with other sleepers and with static walls.

It wakes, at the end of a step, when a contact partner is awake and not yet still (an awake
body that moved within the last ``steps`` steps), when a moving wall touches it, when a load is
set on it, or when anything about the bodies is set through the API (every body wakes). A body
woken this way counts from zero, so waking spreads through a touching cluster one layer per
step. The decision uses only the step's contacts and state, computed on whole arrays in body
order: the same bits at any thread count, and a saved state resumes bit for bit.

What sleeping changes: a sleeper is an obstacle for one step before it wakes (a body landing on
a sleeping pile meets a fixed pile for that step), and residual creep below ``speed`` stops.
"""
from __future__ import annotations

import numpy as np

from peclet.core.validation import PecletArgumentError, check_float, check_int

#: Largest ``steps`` accepted.
MAX_STILL_STEPS = 1_000_000


class Sleep:
    """The sleeping state: ``speed`` (0 = off) and ``steps``, per body ``asleep`` (N,) bool
    and ``count`` (N,) int64 (consecutive still steps)."""

    def __init__(self):
        self.speed = 0.0
        self.steps = 0
        self.asleep = np.zeros(0, bool)
        self.count = np.zeros(0, np.int64)

    def configure(self, speed, steps):
        """Turn sleeping on with a threshold ``speed`` > 0 (length/time, finite) held for
        ``steps`` in [1, MAX_STILL_STEPS] steps. Every body starts awake, counting from 0."""
        self.speed = check_float("speed", speed, 0.0, lo_open=True)
        self.steps = check_int("steps", steps, 1, MAX_STILL_STEPS)
        self.asleep = np.zeros(0, bool)
        self.count = np.zeros(0, np.int64)

    def disable(self):
        """Sleeping off; every body awake."""
        self.__init__()

    @property
    def on(self):
        return self.steps > 0

    def wake_all(self):
        """Every body awake, counting from 0 (a body was set through the API)."""
        self.asleep = np.zeros(0, bool)
        self.count = np.zeros(0, np.int64)

    def sized(self, n):
        """The (asleep, count) arrays for ``n`` bodies (all awake after a change of n)."""
        if len(self.asleep) != n:
            self.asleep = np.zeros(n, bool)
            self.count = np.zeros(n, np.int64)
        return self.asleep, self.count

    def frozen(self, n, loaded=None):
        """(N,) bool: the bodies that sleep through this step, or None with sleeping off.
        ``loaded`` (N,) bool: bodies with an external load, woken first."""
        if not self.on:
            return None
        asleep, count = self.sized(n)
        if loaded is not None and np.any(asleep & loaded):
            count[asleep & loaded] = 0
            asleep &= ~loaded
        return asleep.copy()

    def update(self, a, b, surface_speed, wall_moving, vel, omega):
        """End of a step: count still steps, wake and put to sleep (module notes). ``a``,
        ``b`` the step's contacts (b < 0: wall -1 - b), ``surface_speed`` (N,) after the
        solve, ``wall_moving`` (W,) bool. Sleepers' ``vel``/``omega`` rows are set to 0."""
        asleep, count = self.asleep, self.count
        n = len(asleep)
        still = surface_speed < self.speed
        count[:] = np.where(asleep, count, np.where(still, count + 1, 0))
        settled = asleep | (count >= self.steps)
        isw = b < 0
        bb = np.where(isw, 0, b)
        # contacts that keep a body awake: an unsettled body partner, or a moving wall
        restless_b = np.where(isw, False, ~settled[bb])
        restless_a = ~settled[a]
        moving = np.zeros(len(a), bool)
        if len(wall_moving):
            moving = isw & wall_moving[np.where(isw, -1 - b, 0)]
        disturbed = np.zeros(n, bool)
        np.logical_or.at(disturbed, a, restless_b | moving)
        np.logical_or.at(disturbed, bb[~isw], restless_a[~isw])
        wake = asleep & disturbed
        fall = ~asleep & (count >= self.steps) & ~disturbed
        count[wake] = 0
        asleep[wake] = False
        asleep[fall] = True
        vel[asleep] = 0.0
        omega[asleep] = 0.0

    def arrays(self):
        """(params (2,) speed and steps, asleep (N,) int64 0/1, count (N,)) for a save."""
        return (np.array([self.speed, float(self.steps)]), self.asleep.astype(np.int64),
                self.count.copy())

    def load(self, params, asleep, count, n):
        """Restore a save's arrays (see :meth:`arrays`) for ``n`` bodies."""
        if params.shape != (2,) or not np.all(np.isfinite(params)):
            raise PecletArgumentError("sleep_params", "(speed, steps), finite", params.shape)
        if params[1] == 0:
            self.disable()
            return
        self.configure(float(params[0]), int(params[1]))
        if len(asleep) not in (0, n) or len(count) != len(asleep):
            raise PecletArgumentError("sleep_asleep", f"0 or {n} entries", len(asleep))
        if np.any((asleep != 0) & (asleep != 1)) or np.any(count < 0):
            raise PecletArgumentError("sleep_asleep", "0/1 flags and counts >= 0", "other")
        if len(asleep):
            self.asleep = asleep.astype(bool)
            self.count = count.astype(np.int64)
