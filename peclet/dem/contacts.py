"""Contacts of a state: broad phase -> task list -> narrow phase, and the warm-start cache.

:class:`Detector` turns a state (positions, rotations, a speculative margin) into
:class:`Contacts`, one row per manifold point, in task order (pairs sorted by (a, b) with the
wall tasks interleaved). Its slot buffer grows from the measured task count before it is
filled, so the contacts never depend on the capacity.

:class:`WarmStart` keeps the last step's impulses by contact key (pair and feature) so that the
next step's velocity solve starts from them. Impulses are cached in the world frame and
re-expressed in each contact's new tangent basis on lookup.
"""
from __future__ import annotations

import time
from typing import NamedTuple

import numpy as np

from peclet.dem import broadphase, narrowphase
from peclet.dem.reuse import Reuse
from peclet.dem.shapes import SCENE

#: A pair's manifold spreads over the hits within this fraction of the base margin of its
#: deepest point (the touching patch); farther speculative hits are represented by the deepest.
TOUCH_FRACTION = 0.1

#: Below this estimated work (sphere-task units) the narrow phase runs serially.
SERIAL_WORK = 4000

# key packing for the warm-start cache: ((a * WALL_BASE + b + n_walls + 1) << FEATURE_BITS) + f
_WALL_BASE = 1 << 22
_FEATURE_BITS = 26


class Contacts(NamedTuple):
    """Per contact: bodies ``a``, ``b`` (a wall is -1 - index), b's image ``shift`` (3,),
    ``point`` (3,) world, ``normal`` (3,) unit from b towards a, signed ``gap`` (< 0 is a
    penetration), ``feat`` the probe id (offset by narrowphase.FEATURE_DIR for b's probes)."""
    a: np.ndarray
    b: np.ndarray
    shift: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    gap: np.ndarray
    feat: np.ndarray


def _tasks(pa, pb, shift, n, n_walls):
    # body-wall tasks for every body and wall, merged into the pair list in (a, b) order
    if not n_walls:
        return narrowphase.Tasks(pa, pb, shift)
    wa = np.repeat(np.arange(n, dtype=np.int64), n_walls)
    wb = np.tile(-1 - np.arange(n_walls, dtype=np.int64), n)
    ta = np.concatenate([pa, wa])
    tb = np.concatenate([pb, wb])
    ts = np.concatenate([shift, np.zeros((len(wa), 3))])
    order = np.lexsort((tb, ta))
    return narrowphase.Tasks(ta[order], tb[order], np.ascontiguousarray(ts[order]))


class Detector:
    """Contact detection with a growing slot buffer (``slot_capacity`` contacts)."""

    def __init__(self, slot_capacity):
        self.slot_capacity = int(slot_capacity)
        #: the probe lists carried between detections (exact: the contacts are the same
        #: with it disabled, only slower)
        self.reuse = Reuse(narrowphase.WORKERS)
        self._scratch = None

    def _slots(self, ntask):
        need = ntask * narrowphase.MAX_PER_TASK
        if need > self.slot_capacity:
            self.slot_capacity = max(need, 2 * self.slot_capacity)
        cap = self.slot_capacity
        return narrowphase.Slots(np.zeros(ntask, np.int64), np.empty((cap, 3)),
                                 np.empty((cap, 3)), np.empty(cap), np.empty(cap, np.int64))

    def detect(self, geo, shape_of, pos, rot, margin, margin_fraction, domain, timings):
        """All contacts of the state (``pos`` (N, 3), ``rot`` (N, 3, 3)) within ``margin``.
        ``margin_fraction`` sets the manifold's touching patch; ``timings`` accumulates the
        broad and narrow phases' seconds."""
        t0 = time.perf_counter()
        n = len(pos)
        radii = geo.shape_rad[shape_of]
        cutoff = 2.0 * float(radii.max()) + margin
        domain.check_cutoff(cutoff)
        dlo, dhi = domain.grid_box()
        lo, cell, dims, box = broadphase.grid_for(pos, cutoff, dlo, dhi, domain.periodic,
                                                  max(64, 4 * n))
        pa, pb, shift = broadphase.find_pairs(pos, radii, margin, lo, cell, dims, box,
                                              domain.periodic)
        tasks = _tasks(pa, pb, shift, n, len(geo.wall_op))
        t1 = time.perf_counter()
        ntask = len(tasks.a)
        slots = self._slots(ntask)
        scale = float(geo.shape_rad.min())
        prev, old, cur = self.reuse.prepare(geo, tasks)
        if self._scratch is None or self._scratch.lab.shape[1] < geo.max_hits:
            self._scratch = narrowphase.scratch_for(geo.max_hits)
        narrowphase.narrow_phase(tasks, pos, rot, shape_of, geo, margin, (1e-6 * scale) ** 2,
                                 TOUCH_FRACTION * margin_fraction * scale,
                                 _chunks(tasks, geo, shape_of), slots,
                                 self.reuse.delta(margin_fraction * scale), old, prev, cur,
                                 self._scratch)
        self.reuse.commit(cur)
        count = slots.count
        total = int(count.sum())
        excl = np.concatenate([[0], np.cumsum(count)[:-1]]) if ntask else np.zeros(0, np.int64)
        idx = (np.repeat(np.arange(ntask, dtype=np.int64) * narrowphase.MAX_PER_TASK - excl,
                         count) + np.arange(total, dtype=np.int64))
        t2 = time.perf_counter()
        timings["broad"] += t1 - t0
        timings["narrow"] += t2 - t1
        return Contacts(np.repeat(tasks.a, count), np.repeat(tasks.b, count),
                        np.repeat(tasks.shift, count, axis=0), slots.point[idx],
                        slots.normal[idx], slots.gap[idx], slots.feat[idx])


def _chunks(tasks, geo, shape_of):
    # rough work estimate: a task with a tree costs ~50 sphere tasks; below SERIAL_WORK the
    # parallel launch costs more than it saves. Either path gives the same bits.
    kinds = geo.shape_kind[shape_of]
    work = len(tasks.a) + 49 * int(np.count_nonzero(kinds[tasks.a] == SCENE))
    return 1 if work < SERIAL_WORK else 2


def speculative_margin(base, radii, vel, omega, dt):
    """The detection margin: ``base`` plus twice the largest surface speed (|v| + |omega| r)
    times ``dt`` (None = 0), so that no approach within one step goes unseen."""
    speed = np.sqrt((vel ** 2).sum(axis=1)) + np.sqrt((omega ** 2).sum(axis=1)) * radii
    vmax = float(speed.max()) if len(speed) else 0.0
    return base + 2.0 * vmax * (dt if dt is not None else 0.0)


def lever_arms(c, pos):
    """(ra, rb) (n, 3): each contact point relative to body a's and to body b's centre (b's
    periodic image; zero for a wall)."""
    isw = c.b < 0
    bidx = np.where(isw, 0, c.b)
    ra = np.ascontiguousarray(c.point - pos[c.a])
    rb = np.ascontiguousarray(np.where(isw[:, None], 0.0, c.point - (pos[bidx] + c.shift)))
    return ra, rb


def listing(c):
    """The public dict of contacts sorted by (body_a, body_b, feature); ``depth`` = -gap."""
    if c is None:
        return {"body_a": np.zeros(0, np.int64), "body_b": np.zeros(0, np.int64),
                "point": np.zeros((0, 3)), "normal": np.zeros((0, 3)),
                "depth": np.zeros(0), "feature": np.zeros(0, np.int64)}
    o = np.lexsort((c.feat, c.b, c.a))
    return {"body_a": c.a[o], "body_b": c.b[o], "point": c.point[o], "normal": c.normal[o],
            "depth": -c.gap[o], "feature": c.feat[o]}


def overlap_pairs(lst):
    """Per pair (body_a, body_b, max depth) of a :func:`listing` whose contacts overlap."""
    m = lst["depth"] > 0
    a, b, d = lst["body_a"][m], lst["body_b"][m], lst["depth"][m]
    if len(a) == 0:
        return {"body_a": a, "body_b": b, "depth": d}
    key = np.stack([a, b], axis=1)
    uk, inv = np.unique(key, axis=0, return_inverse=True)
    mx = np.full(len(uk), -np.inf)
    np.maximum.at(mx, inv.reshape(-1), d)
    return {"body_a": uk[:, 0], "body_b": uk[:, 1], "depth": mx}


class WarmStart:
    """Last step's impulses by contact key: ``keys`` (K,) sorted int64, ``lam`` (K, 4) as
    (normal impulse, world-frame tangential impulse (3,))."""

    def __init__(self, keys=None, lam=None):
        self.keys = np.zeros(0, np.int64) if keys is None else keys
        self.lam = np.zeros((0, 4)) if lam is None else lam

    def clear(self):
        self.keys = np.zeros(0, np.int64)
        self.lam = np.zeros((0, 4))

    @staticmethod
    def keys_of(c, n_walls):
        """One int64 key per contact: the pair (a, b) and the feature."""
        return ((c.a * _WALL_BASE + (c.b + n_walls + 1)) << _FEATURE_BITS) + c.feat

    def lookup(self, keys, t1, t2):
        """Initial impulses (nc, 3) (normal, along t1, along t2): the cached ones where a key
        matches, zero elsewhere."""
        nc = len(keys)
        lam = np.zeros((nc, 3))
        if nc and len(self.keys):
            j = np.searchsorted(self.keys, keys)
            j = np.minimum(j, len(self.keys) - 1)
            hit = self.keys[j] == keys
            old = self.lam[j[hit]]
            lam[hit, 0] = old[:, 0]
            lam[hit, 1] = (old[:, 1:] * t1[hit]).sum(axis=1)
            lam[hit, 2] = (old[:, 1:] * t2[hit]).sum(axis=1)
        return lam

    def store(self, keys, lam, t1, t2):
        """Cache this step's impulses ``lam`` (nc, 3) in the tangent bases (t1, t2)."""
        world = np.empty((len(keys), 4))
        world[:, 0] = lam[:, 0]
        world[:, 1:] = lam[:, 1:2] * t1 + lam[:, 2:3] * t2
        o = np.argsort(keys, kind="stable")
        self.keys = keys[o]
        self.lam = world[o]
