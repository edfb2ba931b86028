"""The scene query: phi of many placed trees, pruned by the certificate.

The scene value at p is the minimum, over instances and their periodic images, of each
instance's phi. Certified instances (Equation 1 holds for their ball) sit in a bounding-volume
hierarchy of axis-aligned boxes around their balls; a subtree is skipped when the distance from
p to its box exceeds the best value found so far. Uncertified instances ride an *always* list
and are evaluated for every point. Since the pruned images provably exceed the minimum, and
ties are broken by image index in both paths, the pruned query returns bitwise what the brute
force returns.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from peclet.core.validation import (PecletArgumentError, as_points, check_array, check_bool,
                                    check_choice)

from . import kernels as K
from .encoding import INST_ROOT, instance_transform
from .program import concatenate
from .transforms import quat_to_matrix, transform_ball

_LEAF_SIZE = 4


@njit(cache=True)
def _image_phi(ops, lk, lr, ranges, img_inst, img_frame, inst_prog, i, x, y, z, st):
    """phi of image ``i`` at world point (x, y, z)."""
    f = img_frame[i]
    dx = x - f[0]
    dy = y - f[1]
    dz = z - f[2]
    s = f[12]
    lx = (f[3] * dx + f[6] * dy + f[9] * dz) / s
    ly = (f[4] * dx + f[7] * dy + f[10] * dz) / s
    lz = (f[5] * dx + f[8] * dy + f[11] * dz) / s
    p = inst_prog[img_inst[i]]
    v, gx, gy, gz = K.eval_point(ops, lk, lr, ranges[p, 0], ranges[p, 1], lx, ly, lz, st)
    return s * v


class Images(NamedTuple):
    """A scene's trees and their placed images, what :func:`_image_phi` reads: the
    concatenated programs ``ops`` (n, 2) int32, ``lk`` (L,) int32, ``lr`` (L, LEAF_COLS)
    float64 and ``ranges`` (n_programs, 2) int64 of :func:`.program.concatenate`; per image
    (an instance, or one of its periodic copies) its instance ``img_inst`` (n_img,) int64 and
    frame ``img_frame`` (n_img, 13) float64 (world translation (3), rotation R (9,
    row-major), scale: world = t + s R local); per instance its program ``inst_prog``
    (n_inst,) int64."""
    ops: np.ndarray
    lk: np.ndarray
    lr: np.ndarray
    ranges: np.ndarray
    img_inst: np.ndarray
    img_frame: np.ndarray
    inst_prog: np.ndarray


class Bvh(NamedTuple):
    """What prunes the scene query: the images evaluated at every point ``always`` (int64,
    the uncertified ones), the certified images in leaf order ``order`` (int64), the
    hierarchy's node boxes ``bvh_box`` (m, 7) (centre lo (3), centre hi (3), max radius) and
    children ``bvh_child`` (m, 2) int64 (see :func:`_build_bvh`), each image's bounding ball
    ``ball`` (n_img, 4) (world centre, radius) and the tolerance ``tol`` (world length) a
    lower bound must clear to skip."""
    always: np.ndarray
    order: np.ndarray
    bvh_box: np.ndarray
    bvh_child: np.ndarray
    ball: np.ndarray
    tol: float


@njit(cache=True, parallel=True)
def _scene_brute(images, points, out):
    ops, lk, lr, ranges, img_inst, img_frame, inst_prog = images
    n = points.shape[0]
    nimg = img_inst.shape[0]
    nchunk = (n + K.CHUNK - 1) // K.CHUNK
    for c in prange(nchunk):
        st = np.empty((K.MAX_STACK, K.STACK_COLS))
        for q in range(c * K.CHUNK, min(n, (c + 1) * K.CHUNK)):
            best = np.inf
            for i in range(nimg):
                v = _image_phi(ops, lk, lr, ranges, img_inst, img_frame, inst_prog, i,
                               points[q, 0], points[q, 1], points[q, 2], st)
                if v < best:
                    best = v
            out[q] = best


@njit(cache=True)
def _node_lower_bound(bb, node, x, y, z):
    """A lower bound of |p - c| - r over the balls of a BVH node (negative inside a ball).

    ``bb[node]`` is the box of the balls' centres (lo, hi) and their largest radius.
    """
    dx = max(bb[node, 0] - x, 0.0, x - bb[node, 3])
    dy = max(bb[node, 1] - y, 0.0, y - bb[node, 4])
    dz = max(bb[node, 2] - z, 0.0, z - bb[node, 5])
    return math.sqrt(dx * dx + dy * dy + dz * dz) - bb[node, 6]


@njit(cache=True, parallel=True)
def _scene_pruned(images, bvh, points, out):
    """BVH traversal; bvh_child[node] = (left, right) or (-1 - first, count) for a leaf."""
    ops, lk, lr, ranges, img_inst, img_frame, inst_prog = images
    always, order, bvh_box, bvh_child, ball, tol = bvh
    n = points.shape[0]
    nchunk = (n + K.CHUNK - 1) // K.CHUNK
    nnode = bvh_child.shape[0]
    for c in prange(nchunk):
        st = np.empty((K.MAX_STACK, K.STACK_COLS))
        todo = np.empty(max(nnode, 1), dtype=np.int64)
        for q in range(c * K.CHUNK, min(n, (c + 1) * K.CHUNK)):
            x = points[q, 0]
            y = points[q, 1]
            z = points[q, 2]
            best = np.inf
            best_i = -1
            for a in range(always.shape[0]):
                i = always[a]
                v = _image_phi(ops, lk, lr, ranges, img_inst, img_frame, inst_prog, i, x, y, z,
                               st)
                if v < best or (v == best and i < best_i):
                    best = v
                    best_i = i
            top = 0
            if nnode > 0:
                todo[0] = 0
                top = 1
            while top > 0:
                top -= 1
                node = todo[top]
                if _node_lower_bound(bvh_box, node, x, y, z) - tol > best:
                    continue
                a0 = bvh_child[node, 0]
                if a0 < 0:
                    first = -1 - a0
                    for k in range(first, first + bvh_child[node, 1]):
                        i = order[k]
                        dx = x - ball[i, 0]
                        dy = y - ball[i, 1]
                        dz = z - ball[i, 2]
                        if math.sqrt(dx * dx + dy * dy + dz * dz) - ball[i, 3] - tol > best:
                            continue
                        v = _image_phi(ops, lk, lr, ranges, img_inst, img_frame, inst_prog, i,
                                       x, y, z, st)
                        if v < best or (v == best and i < best_i):
                            best = v
                            best_i = i
                else:
                    a1 = bvh_child[node, 1]
                    # visit the nearer child first so that ``best`` falls early
                    if _node_lower_bound(bvh_box, a0, x, y, z) <= _node_lower_bound(bvh_box, a1, x, y, z):
                        todo[top] = a1
                        todo[top + 1] = a0
                    else:
                        todo[top] = a0
                        todo[top + 1] = a1
                    top += 2
            out[q] = best


def _build_bvh(centres, radii, ids):
    """Median-split BVH over balls. Returns (order, boxes (m, 7), child (m, 2)).

    A node's box row is (centre lo[3], centre hi[3], max radius).
    """
    boxes, child = [], []
    order = []

    def make(idx):
        node = len(boxes)
        boxes.append(np.concatenate([centres[idx].min(axis=0), centres[idx].max(axis=0),
                                     [radii[idx].max()]]))
        child.append([0, 0])
        return node

    if len(ids) == 0:
        return (np.zeros(0, np.int64), np.zeros((0, 7)), np.zeros((0, 2), np.int64))
    work = [(make(ids), ids)]
    while work:
        node, idx = work.pop()
        if len(idx) <= _LEAF_SIZE:
            child[node] = [-1 - len(order), len(idx)]
            order.extend(idx.tolist())
            continue
        ext = centres[idx].max(axis=0) - centres[idx].min(axis=0)
        ax = int(np.argmax(ext))
        srt = idx[np.argsort(centres[idx, ax], kind="stable")]
        half = len(srt) // 2
        left, right = srt[:half], srt[half:]
        ln, rn = make(left), make(right)
        child[node] = [ln, rn]
        work.append((ln, left))
        work.append((rn, right))
    return (np.asarray(order, np.int64), np.asarray(boxes, np.float64),
            np.asarray(child, np.int64))


def as_box(box):
    """``box`` as (lo (3,), hi (3,)) float64 with finite lo < hi, or None."""
    if box is None:
        return None
    if isinstance(box, (str, bytes)) or not hasattr(box, "__len__") or len(box) != 2:
        raise PecletArgumentError("box", "(lo, hi), two points of 3 finite numbers", box)
    lo = check_array("box lo", box[0], (3,))
    hi = check_array("box hi", box[1], (3,))
    if not np.all(hi > lo):
        raise PecletArgumentError("box", "(lo, hi) with hi > lo on every axis", box)
    return lo, hi


def as_periodic(periodic):
    """``periodic`` as a tuple of 3 bools (exactly bools: the string "False" is an error)."""
    if isinstance(periodic, (str, bytes)) or not hasattr(periodic, "__len__") \
            or len(periodic) != 3:
        raise PecletArgumentError("periodic", "3 flags (bools), one per axis", periodic)
    return tuple(check_bool(f"periodic[{a}]", p) for a, p in enumerate(periodic))


class Scene:
    """Instances of one builder, flattened for the query kernels."""

    def __init__(self, programs, inst_prog, frames, balls, certified, box, periodic):
        ops, lk, lr, ranges = concatenate(programs)
        self.box = box
        self.periodic = np.asarray(periodic, dtype=bool)
        shifts = [np.zeros(3)]
        if box is not None:
            lo, hi = box
            length = hi - lo
            grid = [(-1, 0, 1) if p else (0,) for p in self.periodic]
            shifts = [np.array([i, j, k], float) * length
                      for i in grid[0] for j in grid[1] for k in grid[2]]
        img_inst, img_frame, img_ball, img_cert = [], [], [], []
        for inst in range(len(frames)):
            for sh in shifts:
                f = frames[inst].copy()
                f[0:3] += sh
                img_inst.append(inst)
                img_frame.append(f)
                img_ball.append(np.concatenate([balls[inst][:3] + sh, balls[inst][3:]]))
                img_cert.append(certified[inst])
        self.img_inst = np.asarray(img_inst, np.int64)
        self.img_frame = np.asarray(img_frame, np.float64).reshape(-1, 13)
        self.ball = np.asarray(img_ball, np.float64).reshape(-1, 4)
        cert = np.asarray(img_cert, bool)
        self.inst_prog = np.asarray(inst_prog, np.int64)
        self.always = np.flatnonzero(~cert).astype(np.int64)
        ids = np.flatnonzero(cert)
        self.order, self.bvh_box, self.bvh_child = _build_bvh(self.ball[:, :3], self.ball[:, 3],
                                                              ids)
        rmax = float(self.ball[:, 3][np.isfinite(self.ball[:, 3])].max(initial=1.0))
        self.tol = 1e-9 * (1.0 + rmax)
        self.images = Images(ops, lk, lr, ranges, self.img_inst, self.img_frame,
                             self.inst_prog)
        self.bvh = Bvh(self.always, self.order, self.bvh_box, self.bvh_child, self.ball,
                       self.tol)

    @classmethod
    def from_builder(cls, builder, box=None, periodic=(False, False, False)):
        n = builder.num_instances()
        if n == 0:
            raise ValueError("the scene has no instances: call add_instance first")
        per = as_periodic(periodic)
        box = as_box(box)
        if box is None and any(per):
            raise PecletArgumentError("box", "(lo, hi) when an axis is periodic", None)
        _, _, ii, ir = builder.encode()
        roots = sorted(set(ii[:, 0].tolist()))
        prog_of = {r: k for k, r in enumerate(roots)}
        programs = [builder.program(r) for r in roots]
        frames, balls, cert, inst_prog = [], [], [], []
        for k in range(n):
            root = int(ii[k, INST_ROOT])
            t, q, s = instance_transform(ir[k])
            R = quat_to_matrix(q)
            frames.append(np.concatenate([t, R.reshape(-1), [s]]))
            c0, r0, certified = builder.node_bound(root)
            c, r = transform_ball(c0, r0, t, q, s)
            if box is not None:
                length = box[1] - box[0]
                for a in range(3):
                    if per[a] and not (box[0][a] <= t[a] < box[1][a]):
                        raise PecletArgumentError(
                            "box", f"a box whose periodic axis {a} holds instance {k}'s "
                            f"translation[{a}]={t[a]} in [lo, hi)", (box[0].tolist(),
                                                                     box[1].tolist()))
                    if per[a] and not r <= length[a]:
                        raise PecletArgumentError(
                            "box", f"a box whose periodic length on axis {a} is at least "
                            f"instance {k}'s bounding radius {r}", (box[0].tolist(),
                                                                     box[1].tolist()))
            balls.append(np.concatenate([c, [r]]))
            cert.append(certified and np.isfinite(r))
            inst_prog.append(prog_of[root])
        return cls(programs, inst_prog, frames, balls, cert, box, per)

    def _wrap(self, points):
        pts = as_points(points)
        if self.box is not None and self.periodic.any():
            lo, hi = self.box
            length = hi - lo
            pts = pts.copy()
            for a in np.flatnonzero(self.periodic):
                pts[:, a] = lo[a] + np.mod(pts[:, a] - lo[a], length[a])
        return np.ascontiguousarray(pts)

    def evaluate(self, points, method="pruned"):
        method = check_choice("method", method, ("pruned", "brute"))
        pts = self._wrap(points)
        out = np.empty(len(pts))
        if method == "brute":
            _scene_brute(self.images, pts, out)
        else:
            _scene_pruned(self.images, self.bvh, pts, out)
        return out
