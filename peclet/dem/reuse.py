"""Reuse between steps: which probes of a body pair need evaluating again.

A *direction* of a task is one body's shell probes against the other's tree (a wall's tree for
a body-wall task). Its pose is the map q = M p + t from the probing body's home frame to the
tree's home frame (``M`` = R_tree^T R_probe, ``t`` = R_tree^T (x_probe - x_tree)), stored as
12 floats (M row-major, then t).

When a direction is *scanned* (the hierarchical culling of :mod:`peclet.dem.narrowphase`), the
culling uses ``reach = margin + delta`` instead of the margin, and every probe that survives
it (its bound of phi, or phi itself, below reach) is listed with that bound: the *live* list.
At a later step with margin m and pose moved by at most ``mu`` at any point of the probing body
(:func:`motion_bound`), every probe off the list still has phi > reach - mu (phi is
1-Lipschitz and q moved by at most mu; a probe outside the tree's bounding sphere by reach is
outside it by reach - mu), so when ``m + mu <= reach`` only the listed probes can be hits, and a
listed probe whose stored bound minus mu exceeds m cannot be one either. The remaining probes
are evaluated exactly as a scan would, and the hits are sorted into probe order: the contacts
are bit for bit those of a scan (:func:`peclet.dem.narrowphase.narrow_phase`), whatever the
history of the cache, the thread count or the layout of its buffers.

:class:`Reuse` carries the lists from one step to the next: it matches this step's tasks to
last step's by key (bodies and periodic image) and keeps two buffers that the narrow phase
reads from and writes to in turn.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

#: A scan lists the probes within margin + REUSE_FRACTION * base margin: the larger, the
#: longer a list stays valid (relative motion) and the more probes it lists.
REUSE_FRACTION = 0.5
#: Initial live-list capacity (entries); doubled whenever a step overflows it.
INITIAL_CAPACITY = 1 << 14
POSE = 12


class ReuseCache(NamedTuple):
    """Per task and direction d (0: a's probes in b's tree or the wall; 1: b's probes in a's
    tree): ``pose`` (T, 2, 12) at the scan, ``reach`` (T, 2) of the scan, ``shape`` (T, 2, 2)
    the (probing, tree) shape ids (a wall: -1 - index), ``start``/``count`` (T, 2) of its live
    list in ``probe`` (global probe ids) and ``bound`` (their lower bounds of phi at the scan);
    ``count`` -1: nothing listed. ``fill`` (W,): entries each worker used (-1: overflowed)."""
    pose: np.ndarray
    reach: np.ndarray
    shape: np.ndarray
    start: np.ndarray
    count: np.ndarray
    probe: np.ndarray
    bound: np.ndarray
    fill: np.ndarray


def empty_cache(ntask, capacity, workers):
    """A cache for ``ntask`` tasks with nothing listed and ``capacity`` list entries."""
    return ReuseCache(np.zeros((ntask, 2, POSE)), np.full((ntask, 2), -np.inf),
                      np.full((ntask, 2, 2), -1 << 40, np.int64), np.zeros((ntask, 2), np.int64),
                      np.full((ntask, 2), -1, np.int64), np.empty(capacity, np.int64),
                      np.empty(capacity), np.zeros(workers, np.int64))


@njit(cache=True, inline="always")
def relative_pose(xp, Rp, xt, Rt, out):
    """Write into ``out`` (12,) the pose q = M p + t of the probing body (``xp``, ``Rp``) in
    the home frame of the tree at (``xt``, ``Rt``)."""
    dx = xp[0] - xt[0]
    dy = xp[1] - xt[1]
    dz = xp[2] - xt[2]
    for i in range(3):
        for j in range(3):
            out[3 * i + j] = Rt[0, i] * Rp[0, j] + Rt[1, i] * Rp[1, j] + Rt[2, i] * Rp[2, j]
        out[9 + i] = Rt[0, i] * dx + Rt[1, i] * dy + Rt[2, i] * dz


@njit(cache=True, inline="always")
def motion_bound(now, then, radius, xp, xt):
    """An upper bound (length) of |q_now - q_then| over the home-frame points p, |p| <= radius,
    of the probing body: |dM|_F radius + |dt|, inflated for the round-off of the probes' world
    coordinates (``xp``, ``xt``: the two centres now)."""
    dm = 0.0
    for k in range(9):
        e = now[k] - then[k]
        dm += e * e
    dt = 0.0
    for k in range(9, POSE):
        e = now[k] - then[k]
        dt += e * e
    scale = 1.0 + radius + abs(xp[0]) + abs(xp[1]) + abs(xp[2]) + abs(xt[0]) + abs(xt[1]) \
        + abs(xt[2])
    return (math.sqrt(dm) * radius + math.sqrt(dt)) * (1.0 + 1e-9) + 1e-10 * scale


class Reuse:
    """The live lists carried from one detection to the next (see the module notes).

    ``enabled`` False: every direction is scanned at the margin (what the narrow phase does
    without this module); the contacts are the same either way."""

    def __init__(self, workers, enabled=True):
        self.workers = int(workers)
        self.enabled = bool(enabled)
        self.capacity = INITIAL_CAPACITY
        self.reset()

    def reset(self):
        """Forget every list (the next detection scans everything)."""
        self._geo = None
        self._keys = np.zeros(0, np.int64)
        self._order = np.zeros(0, np.int64)
        self.prev = empty_cache(0, 1, self.workers)
        self._spare = None

    @staticmethod
    def keys_of(tasks):
        """One int64 per task: bodies a and b (a wall is negative) and the periodic image."""
        code = ((np.sign(tasks.shift) + 1.0) @ np.array([1.0, 3.0, 9.0])).astype(np.int64)
        return ((tasks.a << 23) + (tasks.b + (1 << 22))) * 27 + code

    def prepare(self, geo, tasks, lists=True):
        """(prev, index, cur): last step's cache, for each task the index of the same task in
        it (-1: none) and a cache for this step's tasks to be filled by the narrow phase.
        ``lists`` False (no composed shape in the geometry): an empty cache."""
        if geo is not self._geo:
            self.reset()
            self._geo = geo
        ntask = len(tasks.a)
        if not lists:
            # nothing to list (only spheres: no task scans probes); an empty cache spares the
            # per-task arrays, tens of megabytes a step on a large bed
            self._pending = np.zeros(0, np.int64)
            return self.prev, np.full(ntask, -1, np.int64), empty_cache(0, 1, self.workers)
        keys = self.keys_of(tasks)
        index = np.full(ntask, -1, np.int64)
        if len(self._keys) and ntask:
            j = np.minimum(np.searchsorted(self._keys, keys), len(self._keys) - 1)
            hit = self._keys[j] == keys
            index[hit] = self._order[j[hit]]
        spare = self._spare
        if spare is None or len(spare[0]) < self.capacity:
            spare = (np.empty(self.capacity, np.int64), np.empty(self.capacity))
        cur = empty_cache(ntask, 1, self.workers)._replace(probe=spare[0], bound=spare[1])
        self._pending = keys
        return self.prev, index, cur

    def commit(self, cur):
        """Make ``cur`` (filled by the narrow phase) the cache the next step reads."""
        if (cur.fill < 0).any():
            self.capacity *= 2          # the overflowed directions rescan next step
        self._spare = (self.prev.probe, self.prev.bound) if len(self.prev.probe) > 1 else None
        self.prev = cur
        self._order = np.argsort(self._pending, kind="stable")
        self._keys = self._pending[self._order]

    def delta(self, base_margin):
        """The scan's extra reach (length): -1 (no lists) when disabled."""
        return REUSE_FRACTION * base_margin if self.enabled else -1.0


@njit(cache=True)
def sort_list(probe, bound, i0, i1):
    """Insertion sort of the list entries [i0, i1) by probe id, so that a replay meets its
    hits already in probe order (the scan lists them cluster by cluster)."""
    for i in range(i0 + 1, i1):
        p = probe[i]
        b = bound[i]
        j = i
        while j > i0 and probe[j - 1] > p:
            probe[j] = probe[j - 1]
            bound[j] = bound[j - 1]
            j -= 1
        probe[j] = p
        bound[j] = b
