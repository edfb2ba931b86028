"""Engines that try to fool or stop the certifier (issue 45, class 4), each built on peclet's
own engine so that it fails for its trick alone; the certificates must catch every one:

- :class:`NeverReturningBackend` (``never_returning_backend``, ``--peclet-backend``): its
  ``evaluate`` waits forever on an event nobody sets; only the deadline of each call stops it;
- :func:`process_seeded_dem_backend` (``--peclet-dem-backend``): peclet.dem with every
  initial position moved by an offset drawn once per process from a generator seeded by the
  process id: bitwise deterministic within a process, different in another, so only a
  comparison across fresh processes sees it;
- :class:`FloorExcusedMassBackend` (``floor_excused_mass_backend``, ``--peclet-mass-backend``):
  peclet's quadrature with every volume 5 % too large, excused by a declared ``floor`` of 0.1
  (an error it claims it cannot get below).
"""
from __future__ import annotations

import os
import threading

import numpy as np

from .dem.backend import PageApiBackend, numba_thread_counts, numba_threads
from .geometry.backend import ReferenceBackend
from .mass.backend import PecletMassBackend

__all__ = ["NeverReturningBackend", "never_returning_backend", "PROCESS_OFFSET",
           "ProcessSeededSimulation", "process_seeded_dem_backend", "FloorExcusedMassBackend",
           "floor_excused_mass_backend"]


class NeverReturningBackend(ReferenceBackend):
    """The reference engine whose ``evaluate`` never returns (it waits on an event that is
    never set); ``evaluate_grad`` and ``bound`` are the reference's."""

    name = "planted: evaluate never returns"

    def __init__(self):
        super().__init__()
        self.never = threading.Event()

    def evaluate(self, node_ints, node_reals, root, points):
        self.never.wait()
        return super().evaluate(node_ints, node_reals, root, points)


def never_returning_backend():
    """Factory (``--peclet-backend``): :class:`NeverReturningBackend`."""
    return NeverReturningBackend()


#: The offset of this process (length units): drawn once, from a generator seeded by the pid.
PROCESS_OFFSET = float(np.random.default_rng(os.getpid()).uniform(1e-9, 2e-9))


class ProcessSeededSimulation:
    """peclet.dem.Simulation whose ``set_positions`` adds :data:`PROCESS_OFFSET` to every
    coordinate (everything else delegated)."""

    def __init__(self, capacity):
        from peclet.dem import Simulation
        self.sim = Simulation(capacity)

    def __getattr__(self, item):
        return getattr(self.sim, item)

    def set_positions(self, positions):
        self.sim.set_positions(np.asarray(positions, np.float64) + PROCESS_OFFSET)


def process_seeded_dem_backend():
    """Factory (``--peclet-dem-backend``): :class:`ProcessSeededSimulation` behind the page's
    API, deterministic within a process."""
    return PageApiBackend(ProcessSeededSimulation, numba_threads,
                          name="planted: seeded once per process", thread_counts=
                          numba_thread_counts())


class FloorExcusedMassBackend(PecletMassBackend):
    """peclet's quadrature (claiming nothing) with every volume 5 % too large, declaring a
    relative-error floor of 0.1 that would excuse it."""

    name = "planted: volume 5 % off, declares floor 0.1"
    floor = 0.1

    def __init__(self):
        super().__init__(claim=None)

    def mass_properties(self, node_ints, node_reals, root, lo, hi, resolution_or_tol):
        v, com, inertia, _ = super().mass_properties(node_ints, node_reals, root, lo, hi,
                                                     resolution_or_tol)
        return 1.05 * v, com, inertia, None


def floor_excused_mass_backend():
    """Factory (``--peclet-mass-backend``): :class:`FloorExcusedMassBackend`."""
    return FloorExcusedMassBackend()
