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

import math
import time
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from peclet.dem import broadphase, distgrid, narrowphase
from peclet.dem.reuse import Reuse
from peclet.dem.shapes import SCENE

#: A pair's manifold spreads over the hits within this fraction of the base margin of its
#: deepest point (the touching patch); farther speculative hits are represented by the deepest.
TOUCH_FRACTION = 0.1

#: The broad phase's Verlet skin, as a fraction of the smallest grown radius: larger, the list
#: lasts more steps and holds more pairs that give no contact. A sphere pair that gives none
#: costs one distance; a composed one a culling pass over its probes, so composed beds take a
#: thinner skin (the page's pour: 1.58 ms/step at 0.1, 1.68 at 0.25, 1.62 rebuilding every
#: step; a stirred sphere column gained most at 0.25). Either gives the same bits.
SKIN_FRACTION = 0.25
SKIN_FRACTION_COMPOSED = 0.1

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


def _tasks(pa, pb, shift, n, n_walls, base, reach, wall_reach, frozen, wall_static):
    # zero reaches give every task exactly ``base`` (base + 0.0 is base)
    if reach is None:
        reach = np.zeros(n)
    if wall_reach is None or wall_reach.shape[1] != n_walls:
        wall_reach = np.zeros((n, n_walls))
    if frozen is None:
        frozen = np.zeros(n, np.bool_)
    if wall_static is None:
        wall_static = np.ones(n_walls, np.bool_)
    return narrowphase.Tasks(*broadphase.task_list(pa, pb, shift, np.int64(n),
                                                   np.int64(n_walls), float(base), reach,
                                                   np.ascontiguousarray(wall_reach), frozen,
                                                   wall_static))


class Detector:
    """Contact detection with a growing slot buffer (``slot_capacity`` contacts)."""

    def __init__(self, slot_capacity):
        self.slot_capacity = int(slot_capacity)
        #: the probe lists carried between detections (exact: the contacts are the same
        #: with it disabled, only slower)
        self.reuse = Reuse(narrowphase.WORKERS)
        self._scratch = None
        self._walled = (None, None)     # (geometry given, the same with wall grids)
        self._slot_arrays = None
        self._pairs = None              # (margin, positions, build radii, (pa, pb, shift))

    def _slots(self, tasks, kind):
        ntask = len(tasks.a)
        first = narrowphase.slot_room(tasks.a, tasks.b, kind)
        need = int(first[ntask])
        if need > self.slot_capacity:
            self.slot_capacity = max(need, 2 * self.slot_capacity)
        cap = self.slot_capacity
        # the buffers are kept between detections: a fresh one of this size every step was
        # paid again in page faults inside the narrow phase (a task writes its slots before
        # anything reads them, so old contents never leak)
        kept = self._slot_arrays
        if kept is None or len(kept[2]) != cap:
            kept = (np.empty((cap, 3)), np.empty((cap, 3)), np.empty(cap),
                    np.empty(cap, np.int64))
            self._slot_arrays = kept
        return narrowphase.Slots(np.zeros(ntask, np.int64), *kept, first)

    def _with_wall_grids(self, geo, pos, reach):
        # baked once per geometry, when the body-wall tasks first pay for it; they only spare
        # evaluations, so when (and around which bodies) they are baked changes no contact
        given, walled = self._walled
        if given is geo and walled is not geo:
            return walled
        walled = distgrid.with_wall_grids(geo, pos, reach)
        self._walled = (geo, walled)
        return walled

    def _pair_list(self, pos, grown, margin, domain, skin_fraction=SKIN_FRACTION):
        """The broad phase's candidate pairs, kept between detections as a Verlet list.

        Built with each body's sphere grown by ``skin_fraction`` x the smallest radius (the
        build spheres G_i, at positions x_i), the list holds every pair a fresh broad phase
        would find as long as each body's current sphere (grown radius g_i, moved by d_i)
        stays inside its build sphere, g_i + d_i <= G_i: a pair not listed had
        |x_i - x_j| >= G_i + G_j + margin, so now it is at least (G_i - d_i) + (G_j - d_j) +
        margin >= g_i + g_j + margin apart. The extra pairs it holds give the narrow phase
        no hit (their gap exceeds their margin), so the contacts are the same bits as with
        a fresh list; only the work changes. On periodic axes distances and displacements
        are to the nearest image (a metric on the torus, so the argument holds), and a kept
        pair's image shift is computed afresh from the current positions, by the broad
        phase's own formula (:func:`~peclet.dem.broadphase.image_shifts`): a body that
        wrapped keeps its pairs."""
        keep = self._pairs
        n = len(pos)
        dlo, dhi = domain.grid_box()
        box = np.where(domain.periodic, dhi - dlo, 1.0)      # grid_for's box
        if keep is not None and keep[0] == margin and len(keep[1]) == n:
            x_ref, big, found = keep[1], keep[2], keep[3]
            d = pos - x_ref
            if domain.any_periodic:
                d = np.where(domain.periodic, d - box * np.floor(d / box + 0.5), d)
            moved = np.sqrt((d ** 2).sum(axis=1))
            # the test keeps a relative 1e-9 in hand against round-off in the distances
            if bool(np.all(grown + moved <= big * (1.0 - 1e-9))):
                if not domain.any_periodic:
                    return found
                return found[0], found[1], broadphase.image_shifts(found[0], found[1], pos,
                                                                   box, domain.periodic)
        skin = skin_fraction * float(grown.min()) if n else 0.0
        big = grown + skin
        cutoff = 2.0 * float(big.max()) + margin
        lo, cell, dims, box = broadphase.grid_for(pos, cutoff, dlo, dhi, domain.periodic,
                                                  max(64, 4 * n))
        found = broadphase.pairs(pos, big, margin, lo, cell, dims, box, domain.periodic)
        self._pairs = (margin, pos.copy(), big, found)
        return found

    def candidates(self, geo, shape_of, pos, margin, domain, reach=None, wall_reach=None,
                   frozen=None, wall_static=None):
        """The broad phase of :meth:`detect` (its arguments): (the candidate pairs as
        :class:`~peclet.dem.narrowphase.Tasks`, each with its own margin; the cutoff of the
        pair search; whether any shape is composed)."""
        n = len(pos)
        radii = geo.shape_rad[shape_of]
        # the broad phase's spheres grow by each body's reach: a pair is a candidate when
        # its bounding spheres come within its own margin
        grown = radii if reach is None else radii + reach
        cutoff = 2.0 * float(grown.max()) + margin
        domain.check_cutoff(cutoff)
        composed = bool(np.any(geo.shape_kind == SCENE))
        pa, pb, shift = self._pair_list(pos, grown, margin, domain,
                                        SKIN_FRACTION_COMPOSED if composed else SKIN_FRACTION)
        # each pair's margin: its base plus what its two members can close within the step
        tasks = _tasks(pa, pb, shift, n, len(geo.wall_op), margin, reach, wall_reach, frozen,
                       wall_static)
        return tasks, cutoff, composed

    def detect(self, geo, shape_of, pos, rot, margin, margin_fraction, domain, timings,
               reach=None, wall_reach=None, frozen=None, wall_static=None):
        """All contacts of the state (``pos`` (N, 3), ``rot`` (N, 3, 3)) within each pair's
        margin (:func:`peclet.dem.broadphase.task_list` of ``margin``, ``reach`` (N,) and
        ``wall_reach`` (N, W); with ``reach`` None, ``margin`` for every pair).
        ``margin_fraction`` sets the manifold's touching patch; ``timings`` accumulates the
        broad and narrow phases' seconds. ``frozen`` (N,) bool (sleepers) and ``wall_static``
        (W,) bool: the pairs of two frozen bodies and of a frozen body with a static wall are
        not examined (None: none frozen)."""
        t0 = time.perf_counter()
        tasks, cutoff, composed = self.candidates(geo, shape_of, pos, margin, domain, reach,
                                                  wall_reach, frozen, wall_static)
        geo = self._with_wall_grids(geo, pos, cutoff)
        t1 = time.perf_counter()
        ntask = len(tasks.a)
        slots = self._slots(tasks, geo.shape_kind[shape_of])
        scale = float(geo.shape_rad.min())
        prev, old, cur = self.reuse.prepare(geo, tasks, composed)
        if self._scratch is None or self._scratch.lab.shape[1] < geo.max_hits:
            self._scratch = narrowphase.scratch_for(geo.max_hits)
        narrowphase.narrow_phase(tasks, pos, rot, shape_of, geo, (1e-6 * scale) ** 2,
                                 TOUCH_FRACTION * margin_fraction * scale,
                                 _chunks(tasks, geo, shape_of), slots,
                                 self.reuse.delta(margin_fraction * scale), old, prev, cur,
                                 self._scratch)
        self.reuse.commit(cur)
        gather = (narrowphase.gather_parallel if ntask >= narrowphase.PARALLEL_GATHER_TASKS
                  else narrowphase.gather)
        c = Contacts(*gather(tasks, slots))
        t2 = time.perf_counter()
        timings["broad"] += t1 - t0
        timings["narrow"] += t2 - t1
        return c


def _chunks(tasks, geo, shape_of):
    # rough work estimate: a task with a tree costs ~50 sphere tasks; below SERIAL_WORK the
    # parallel launch costs more than it saves. Either path gives the same bits.
    kinds = geo.shape_kind[shape_of]
    work = len(tasks.a) + 49 * int(np.count_nonzero(kinds[tasks.a] == SCENE))
    return 1 if work < SERIAL_WORK else 2


def body_reach(radii, vel, omega, dt):
    """Per body (N,): its largest surface speed ``|v| + |omega| r`` times ``dt``, what it can
    move towards anything within one step (zeros for ``dt`` None)."""
    speed = np.sqrt((vel ** 2).sum(axis=1)) + np.sqrt((omega ** 2).sum(axis=1)) * radii
    return speed * (dt if dt is not None else 0.0)


def lever_arms(c, pos):
    """(ra, rb) (n, 3): each contact point relative to body a's and to body b's centre (b's
    periodic image; zero for a wall)."""
    return _lever_arms(c.a, c.b, c.point, c.shift, pos)


@njit(cache=True)
def _lever_arms(a, b, point, shift, pos):
    n = a.shape[0]
    ra = np.empty((n, 3))
    rb = np.empty((n, 3))
    for i in range(n):
        for e in range(3):
            ra[i, e] = point[i, e] - pos[a[i], e]
            rb[i, e] = 0.0 if b[i] < 0 else point[i, e] - (pos[b[i], e] + shift[i, e])
    return ra, rb


def reorder(c, order):
    """The :class:`Contacts` ``c`` rearranged: row u of the result is row ``order[u]`` of c
    (the colour order of the coloured solve, :func:`peclet.dem.solver.colors_for`)."""
    return Contacts(*_reorder(c.a, c.b, c.shift, c.point, c.normal, c.gap, c.feat, order))


_REORDER_CHUNK = 1024


@njit(cache=True, parallel=True)
def _reorder(a, b, shift, point, normal, gap, feat, order):
    # a gather: every row written by one task, so the same arrays at any thread count
    n = order.shape[0]
    ra = np.empty(n, np.int64)
    rb = np.empty(n, np.int64)
    rs = np.empty((n, 3))
    rp = np.empty((n, 3))
    rn = np.empty((n, 3))
    rg = np.empty(n)
    rf = np.empty(n, np.int64)
    for ch in prange((n + _REORDER_CHUNK - 1) // _REORDER_CHUNK):
        for u in range(ch * _REORDER_CHUNK, min(n, (ch + 1) * _REORDER_CHUNK)):
            i = order[u]
            ra[u] = a[i]
            rb[u] = b[i]
            rg[u] = gap[i]
            rf[u] = feat[i]
            for e in range(3):
                rs[u, e] = shift[i, e]
                rp[u, e] = point[i, e]
                rn[u, e] = normal[i, e]
    return ra, rb, rs, rp, rn, rg, rf


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


#: From this many contacts the warm start's lookups run in parallel (chunks of
#: _INITIAL_CHUNK contacts, each row written by its own contact: the same impulses).
PARALLEL_INITIAL_CONTACTS = 20000
_INITIAL_CHUNK = 2048


@njit(cache=True)
def _initial_impulses(old_keys, old_lam, keys, t1, t2, mu):
    """:meth:`WarmStart.initial`. The sums and products are NumPy's (a row sum starts from
    0.0 and adds left to right), so that the impulses keep the bits of the array form."""
    nc = keys.shape[0]
    lam = np.zeros((nc, 3))
    _initial_range(np.int64(0), nc, old_keys, old_lam, keys, t1, t2, mu, lam)
    return lam


@njit(cache=True, parallel=True)
def _initial_impulses_parallel(old_keys, old_lam, keys, t1, t2, mu):
    """:func:`_initial_impulses` over chunks of contacts in parallel (the same bits)."""
    nc = keys.shape[0]
    lam = np.zeros((nc, 3))
    for ch in prange((nc + _INITIAL_CHUNK - 1) // _INITIAL_CHUNK):
        _initial_range(ch * _INITIAL_CHUNK, min(nc, (ch + 1) * _INITIAL_CHUNK), old_keys,
                       old_lam, keys, t1, t2, mu, lam)
    return lam


@njit(cache=True)
def _initial_range(i0, i1, old_keys, old_lam, keys, t1, t2, mu, lam):
    # contacts i0..i1-1 of _initial_impulses, into lam (zeros where no key matches)
    nk = old_keys.shape[0]
    if nk == 0:
        return
    for i in range(i0, i1):
        j = np.searchsorted(old_keys, keys[i])
        if j >= nk or old_keys[j] != keys[i]:
            continue
        lam[i, 0] = old_lam[j, 0]
        lam[i, 1] = ((0.0 + old_lam[j, 1] * t1[i, 0]) + old_lam[j, 2] * t1[i, 1]) \
            + old_lam[j, 3] * t1[i, 2]
        lam[i, 2] = ((0.0 + old_lam[j, 1] * t2[i, 0]) + old_lam[j, 2] * t2[i, 1]) \
            + old_lam[j, 3] * t2[i, 2]
        # the Coulomb cone (a cached impulse must satisfy it at this step's friction too)
        tm = math.sqrt(lam[i, 1] * lam[i, 1] + lam[i, 2] * lam[i, 2])
        lim = mu[i] * lam[i, 0]
        if tm > lim:
            sc = lim / tm if tm > 0.0 else 0.0
            lam[i, 1] *= sc
            lam[i, 2] *= sc


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

    def initial(self, keys, t1, t2, mu):
        """Initial impulses (nc, 3) (normal, along t1, along t2): the cached ones where a key
        matches (the world-frame tangential impulse projected on this step's tangents), zero
        elsewhere, each scaled into its Coulomb cone ``|lam_t| <= mu lam_n`` (``mu`` (nc,))."""
        run = (_initial_impulses_parallel if len(keys) >= PARALLEL_INITIAL_CONTACTS
               else _initial_impulses)
        return run(self.keys, self.lam, keys, t1, t2, mu)

    def store(self, keys, lam, t1, t2):
        """Cache this step's impulses ``lam`` (nc, 3) in the tangent bases (t1, t2)."""
        o = np.argsort(keys, kind="stable")
        if len(keys) >= PARALLEL_INITIAL_CONTACTS:
            # the same rows, each computed where it lands, by a parallel twin
            self.keys, self.lam = _stored_rows(keys, lam, t1, t2, o)
            return
        world = np.empty((len(keys), 4))
        world[:, 0] = lam[:, 0]
        world[:, 1:] = lam[:, 1:2] * t1 + lam[:, 2:3] * t2
        self.keys = keys[o]
        self.lam = world[o]


@njit(cache=True, parallel=True)
def _stored_rows(keys, lam, t1, t2, o):
    """(keys[o], world[o]) of :meth:`WarmStart.store`, world = (lam_n, lam_1 t1 + lam_2 t2)
    (NumPy's element-wise products and sum: the same bits), each row written once."""
    n = o.shape[0]
    out_k = np.empty(n, np.int64)
    out = np.empty((n, 4))
    for ch in prange((n + _INITIAL_CHUNK - 1) // _INITIAL_CHUNK):
        for u in range(ch * _INITIAL_CHUNK, min(n, (ch + 1) * _INITIAL_CHUNK)):
            i = o[u]
            out_k[u] = keys[i]
            out[u, 0] = lam[i, 0]
            for e in range(3):
                out[u, 1 + e] = lam[i, 1] * t1[i, e] + lam[i, 2] * t2[i, e]
    return out_k, out
