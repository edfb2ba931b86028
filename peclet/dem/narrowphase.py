"""Narrow phase: contact manifolds for body-body and body-wall tasks.

Every task is one pair: (a, b) with b >= 0 a body (image shift given), or b = -1 - w a wall.

- sphere / sphere: the exact analytic contact along the centre line;
- sphere / tree: the sphere's centre against the tree's exact field, ``phi - radius``;
- tree / tree: each body's shell probes, mapped into the other's home frame, against the
  other's exact tree -- BOTH ways, so a thin rim pressed between one body's probes is still
  caught by the other's probes;
- body / wall: the body's probes (a sphere: its centre) against the wall's tree.

Normals are the analytic gradients of the tree (normalised), rotated to the world frame; the
stored normal always points from b to a (it pushes a away from b). ``gap`` is the signed
separation (< 0 is a penetration of depth -gap); the contact point is midway between the two
surfaces. Hits within the task's margin are kept (speculative contacts; each pair has its
own, see :func:`peclet.dem.broadphase.task_list`).

Probes are grouped into clusters with a bounding sphere, clusters into super-clusters. When the
tree's field is 1-Lipschitz, phi grows by at most the distance travelled, so a lower bound of
phi at a sphere's centre minus its radius bounds every point inside: the body, a super-cluster,
a cluster or a single probe is skipped once that bound exceeds the margin. The bounds come from
the tree's distance grid (:mod:`peclet.dem.distgrid`, one array read), or one evaluation where
a tree has no grid (walls), or the enclosing level's bound minus the offset. Only the probes
that survive are evaluated on the exact tree; a skipped probe cannot be a hit, and the hits are
put back in probe order, so the contacts are bit for bit those of evaluating every probe.

Between steps (:mod:`peclet.dem.reuse`): a direction scanned with the culling widened to
``reach`` lists the probes that survived it; while the bodies' relative motion since that scan
plus the margin stays within reach, only the listed probes are tested again, with the same
exact evaluation, so the hits are again those of a scan.

The hits are reduced to at most ``MAX_PER_TASK`` contacts per task (:mod:`peclet.dem.manifold`),
written into the task's own slots (one for a task with a sphere in it, which tests one point).

Determinism: tasks run in parallel (fixed-size chunks dealt to a fixed number of workers,
the workers to the threads),
every task writes only its own slots; all choices break ties by the lowest index.

Here: the tasks, slots and scratch, the workers (:func:`narrow_workers`, which take the step's
:class:`Job`) and the gather; the probing of a tree by a point or a body's probes (the culling
and the reuse) is :mod:`peclet.dem.probing`.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from peclet.core.shares import run_shares
from peclet.core.geom.kernels import MAX_STACK, STACK_COLS
from peclet.dem.manifold import HIT_COLS, MAX_CLUSTERS, MAX_PER_TASK, reduce_hits
from peclet.dem.probing import (Probing, ReuseStep, Worker, body_tree, direction, point_vs_tree,
                                wall_tree)
from peclet.dem.reuse import POSE
from peclet.dem.shapes import Geometry

#: Feature ids of the second direction (b's probes in a's tree) are offset by this.
FEATURE_DIR = 1 << 24
#: Smallest chunk of tasks a worker takes at a time; a large task list is cut into about
#: CHUNKS_PER_WORKER chunks per worker instead, so that each worker runs through long
#: contiguous stretches of the tasks and their slots (chunks of 8 on the 147,000 tasks of the
#: stirred column made the workers' strided walks through the slot buffers cost twice the
#: serial pass). The chunk size depends on the task count alone; every task writes only its
#: own slots, so no size changes a bit.
TASK_CHUNK = 8
CHUNKS_PER_WORKER = 4
#: From this many tasks the contacts are gathered in parallel (:func:`gather_parallel`), in
#: chunks of GATHER_CHUNK tasks; either way the same arrays.
PARALLEL_GATHER_TASKS = 20000
GATHER_CHUNK = 2048
#: Parallel workers (each takes every WORKERS-th chunk): enough to even out 2..16 threads.
WORKERS = 32


class Tasks(NamedTuple):
    """Candidate pairs: body ``a`` (T,), body ``b`` (T,) (a wall is -1 - index), the image
    ``shift`` (T, 3) added to b's position (periodic minimum image; zero for walls) and each
    pair's speculative ``margin`` (T,): its hits with a gap below it are kept."""
    a: np.ndarray
    b: np.ndarray
    shift: np.ndarray
    margin: np.ndarray


class Scratch(NamedTuple):
    """Per-worker scratch, kept between calls (an allocation per call and worker was a
    page-mapping system call each, which serialises the threads): ``hits`` (WORKERS, H,
    HIT_COLS), ``lab`` (WORKERS, H) with H >= the geometry's ``max_hits``, ``st`` (WORKERS,
    MAX_STACK, STACK_COLS) the evaluation stack."""
    hits: np.ndarray
    lab: np.ndarray
    st: np.ndarray


def scratch_for(max_hits):
    """A :class:`Scratch` for every worker, for tasks of at most ``max_hits`` hits."""
    return Scratch(np.empty((WORKERS, max_hits, HIT_COLS)), np.empty((WORKERS, max_hits),
                                                                       np.int64),
                   np.empty((WORKERS, MAX_STACK, STACK_COLS)))


class Slots(NamedTuple):
    """Output buffers: task t writes ``count[t]`` contacts from slot ``first[t]`` (room for
    :func:`slot_room` of them): ``point`` (S, 3) world, ``normal`` (S, 3) unit from b to a,
    ``gap`` (S,), ``feat`` (S,)."""
    count: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    gap: np.ndarray
    feat: np.ndarray
    first: np.ndarray


@njit(cache=True)
def slot_room(ta, tb, kind):
    """(T + 1,) each task's first slot (the last entry: the slots needed). A task with a
    sphere in it tests one point (the centre line, or the sphere's centre against a tree) and
    has at most one contact; any other at most MAX_PER_TASK. ``kind`` (N,) each body's shape
    kind (0: sphere). Packed this way the slots of a sphere bed are dense: the narrow phase
    writes, and the gather reads, consecutive rows rather than one row in MAX_PER_TASK."""
    ntask = ta.shape[0]
    first = np.empty(ntask + 1, np.int64)
    first[0] = 0
    for t in range(ntask):
        one = kind[ta[t]] == 0 or (tb[t] >= 0 and kind[tb[t]] == 0)
        first[t + 1] = first[t] + (1 if one else MAX_PER_TASK)
    return first


class Job(NamedTuple):
    """One narrow phase, bundled once per step by :func:`narrow_phase` (see its arguments):
    the ``tasks``, the bodies' ``pos``, ``rot`` and ``shape_of``, the ``geo``, the manifold's
    ``tol2`` and ``touch``, the output ``slots``, the step's probe lists ``reuse``
    (:class:`peclet.dem.probing.ReuseStep`) and the workers' ``scratch``."""
    tasks: Tasks
    pos: np.ndarray
    rot: np.ndarray
    shape_of: np.ndarray
    geo: Geometry
    tol2: float
    touch: float
    slots: Slots
    reuse: ReuseStep
    scratch: Scratch


@njit(cache=True, nogil=True)
def narrow_workers(first, step, nw, size, job):
    """Workers ``first``, ``first + step``, ... of ``nw`` (a share of
    :func:`peclet.core.shares.run_shares`) of the :class:`Job`. Worker ``worker`` takes the
    chunks worker, worker + nw, ... of ``size`` tasks (interleaved, so that the workers' loads
    even out); gathers each task's hits and reduces them into its own slots. It lists probes
    in its own share of ``job.reuse.cur``'s buffer and reports its use (or -1 on overflow) in
    ``cur.fill[worker]``. Its scratch is ``job.scratch``'s row ``worker``: a task's hit buffer
    is large enough for every probe of both bodies."""
    tasks, pos, rot, shape_of, geo, tol2, touch, slots, reuse, scratch = job
    # the tables read by every task are taken out of the tuple once: a field read costs a
    # reference-count update (a tree's tables are read only where its task evaluates a tree)
    shape_kind, shape_rad = geo.shape_kind, geo.shape_rad
    cur = reuse.cur
    nogrid = np.zeros(3, np.int64)
    reps = np.empty(MAX_CLUSTERS, np.int64)
    pose = np.empty(POSE)
    xb = np.empty(3)
    origin = np.zeros(3)
    nolattice = np.ones(5)
    # integer arguments as int64 values, never literals: Numba compiles a callee once per
    # literal value (and per tuple type), and each copy of direction costs ~20 s of a cold
    # first run (docs/architecture.md §7)
    zero_i = np.int64(0)
    one_i = np.int64(1)
    feat_dir = np.int64(FEATURE_DIR)
    share = cur.probe.shape[0] // nw
    ntask = tasks.a.shape[0]
    nchunk = (ntask + size - 1) // size
    for worker in range(first, nw, step):
        st = scratch.st[worker]
        hits = scratch.hits[worker]
        lab = scratch.lab[worker]
        lpos = worker * share
        own = Worker(st, hits, origin, pose, lpos + share)
        for ch in range(worker, nchunk, nw):
            for t in range(ch * size, min(ntask, (ch + 1) * size)):
                a = tasks.a[t]
                b = tasks.b[t]
                margin = tasks.margin[t]
                sa = shape_of[a]
                nh = zero_i
                if b >= 0 and shape_kind[sa] == 0 and shape_kind[shape_of[b]] == 0:
                    # two spheres: the centre line, read straight from the arrays (the views and
                    # trees of the other cases cost more than this whole test)
                    sb = shape_of[b]
                    dx = pos[a, 0] - (pos[b, 0] + tasks.shift[t, 0])
                    dy = pos[a, 1] - (pos[b, 1] + tasks.shift[t, 1])
                    dz = pos[a, 2] - (pos[b, 2] + tasks.shift[t, 2])
                    dist = math.sqrt(dx * dx + dy * dy + dz * dz)
                    gap = dist - shape_rad[sa] - shape_rad[sb]
                    # at most one hit, written straight into the task's slot (what the manifold
                    # reduction makes of a single hit)
                    slots.count[t] = 0
                    if gap < margin:
                        if dist > 0.0:
                            nx = dx / dist
                            ny = dy / dist
                            nz = dz / dist
                        else:
                            nx, ny, nz = 0.0, 1.0, 0.0
                        h = shape_rad[sa] + 0.5 * gap
                        o = slots.first[t]
                        slots.point[o, 0] = pos[a, 0] - h * nx
                        slots.point[o, 1] = pos[a, 1] - h * ny
                        slots.point[o, 2] = pos[a, 2] - h * nz
                        slots.normal[o, 0] = nx
                        slots.normal[o, 1] = ny
                        slots.normal[o, 2] = nz
                        slots.gap[o] = gap
                        slots.feat[o] = 0
                        slots.count[t] = 1
                    continue
                xa = pos[a]
                Ra = rot[a]
                if b >= 0:
                    sb = shape_of[b]
                    for e in range(3):
                        xb[e] = pos[b, e] + tasks.shift[t, e]
                    Rb = rot[b]
                    if shape_kind[sa] == 0:
                        nh, _ = point_vs_tree(xa[0], xa[1], xa[2], shape_rad[sa],
                                              body_tree(geo, xb, Rb, sb), 1.0, zero_i, margin,
                                              margin, st, hits, nh)
                    elif shape_kind[sb] == 0:
                        nh, _ = point_vs_tree(xb[0], xb[1], xb[2], shape_rad[sb],
                                              body_tree(geo, xa, Ra, sa), -1.0, feat_dir,
                                              margin, margin, st, hits, nh)
                    else:
                        # both ways: a's probes in b's tree (normals as they are, features
                        # from 0), then b's probes in a's tree (normals turned, from FEATURE_DIR)
                        side_a = Probing(zero_i, xa, Ra, sa, 1.0, zero_i)
                        nh, lpos = direction(t, geo, reuse, own, side_a,
                                             body_tree(geo, xb, Rb, sb), margin, nh, lpos)
                        side_b = Probing(one_i, xb, Rb, sb, -1.0, feat_dir)
                        nh, lpos = direction(t, geo, reuse, own, side_b,
                                             body_tree(geo, xa, Ra, sa), margin, nh, lpos)
                else:
                    wall = wall_tree(geo, b, nolattice, nogrid)
                    if shape_kind[sa] == 0:
                        nh, _ = point_vs_tree(xa[0], xa[1], xa[2], shape_rad[sa], wall, 1.0,
                                              zero_i, margin, margin, st, hits, nh)
                    else:
                        side_a = Probing(zero_i, xa, Ra, sa, 1.0, zero_i)
                        nh, lpos = direction(t, geo, reuse, own, side_a, wall, margin, nh,
                                             lpos)
                slots.count[t] = reduce_hits(hits, nh, lab, reps, tol2, touch, slots.first[t],
                                             slots.point, slots.normal, slots.gap, slots.feat)
        cur.fill[worker] = lpos - worker * share if lpos <= own.lend else -1


def narrow_phase(tasks, pos, rot, shape_of, geo, tol2, touch, chunks, slots, delta, old, prev,
                 cur, scratch):
    """Contacts of every task into its own slots (from ``slots.first[t]``, at most
    :func:`slot_room`'s room); ``slots.count[t]`` = used.

    ``tasks`` a :class:`Tasks`; ``pos`` (N, 3) and ``rot`` (N, 3, 3) the bodies' centres and
    home -> world rotations, ``shape_of`` (N,) their shape ids; ``geo`` the
    :class:`peclet.dem.shapes.Geometry`; hits within the task's margin are kept; ``tol2``
    and ``touch`` tune the manifold reduction; ``slots`` a :class:`Slots`. Reuse between steps
    (:mod:`peclet.dem.reuse`): ``old`` (T,) each task's index in ``prev`` (last step's
    :class:`peclet.dem.reuse.ReuseCache`, -1: none), ``cur`` this step's (filled here),
    ``delta`` the scans' extra reach (< 0: nothing listed, every direction scanned).
    ``scratch``: a :class:`Scratch` for at least ``geo.max_hits`` hits.
    ``chunks`` = 1 runs serially in the calling thread (small problems, where a parallel launch
    costs more than it saves), otherwise WORKERS workers, each taking every WORKERS-th chunk
    of tasks (TASK_CHUNK, or about CHUNKS_PER_WORKER chunks per worker on a large task list),
    are dealt to the threads (:func:`peclet.core.shares.run_shares`). Either way every task
    writes only its own slots, and its hits are those of a scan, so the result is identical."""
    nw = WORKERS if chunks > 1 else 1
    cur.fill[nw:] = 0
    size = max(TASK_CHUNK, tasks.a.shape[0] // (WORKERS * CHUNKS_PER_WORKER))
    job = Job(tasks, pos, rot, shape_of, geo, tol2, touch, slots,
              ReuseStep(old, prev, cur, delta), scratch)
    run_shares(narrow_workers, nw, nw, size, job)


@njit(cache=True)
def gather(tasks, slots):
    """The contacts of :func:`narrow_phase` packed in task order: (a, b, shift (n, 3), point
    (n, 3), normal (n, 3), gap, feat), one row per used slot."""
    ntask = tasks.a.shape[0]
    first = np.empty(ntask + 1, np.int64)
    first[0] = 0
    for t in range(ntask):
        first[t + 1] = first[t] + slots.count[t]
    out = _gather_arrays(first[ntask])
    _gather_tasks(0, ntask, tasks, slots, first, *out)
    return out


@njit(cache=True, parallel=True)
def gather_parallel(tasks, slots):
    """:func:`gather` with the tasks dealt in chunks to parallel workers: each row is written
    by the one task it comes from, so the arrays are the same, bit for bit."""
    ntask = tasks.a.shape[0]
    first = np.empty(ntask + 1, np.int64)
    first[0] = 0
    for t in range(ntask):
        first[t + 1] = first[t] + slots.count[t]
    a, b, shift, point, normal, gap, feat = _gather_arrays(first[ntask])
    for ch in prange((ntask + GATHER_CHUNK - 1) // GATHER_CHUNK):
        _gather_tasks(ch * GATHER_CHUNK, min(ntask, (ch + 1) * GATHER_CHUNK), tasks, slots,
                      first, a, b, shift, point, normal, gap, feat)
    return a, b, shift, point, normal, gap, feat


@njit(cache=True)
def _gather_arrays(total):
    return (np.empty(total, np.int64), np.empty(total, np.int64), np.empty((total, 3)),
            np.empty((total, 3)), np.empty((total, 3)), np.empty(total),
            np.empty(total, np.int64))


@njit(cache=True)
def _gather_tasks(t0, t1, tasks, slots, first, a, b, shift, point, normal, gap, feat):
    """Tasks t0..t1-1: their used slots into rows from ``first[t]``."""
    for t in range(t0, t1):
        k = first[t]
        for u in range(slots.count[t]):
            o = slots.first[t] + u
            a[k] = tasks.a[t]
            b[k] = tasks.b[t]
            for e in range(3):
                shift[k, e] = tasks.shift[t, e]
                point[k, e] = slots.point[o, e]
                normal[k, e] = slots.normal[o, e]
            gap[k] = slots.gap[o]
            feat[k] = slots.feat[o]
            k += 1
