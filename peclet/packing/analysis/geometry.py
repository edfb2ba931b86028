"""Pack analysis on the exact trees (page Steps 5 and 6; Step 2's Equation 1 check is
:func:`peclet.core.geom.certificate.check_equation1`, re-exported here as
``certificate_check``, and the marching-cubes area is :mod:`peclet.core.geom.mesh`'s).

All measurements are taken on a :class:`~peclet.packing.bed.freeze.Pack` (world frame: y up, floor
at y = 0, periodic in x and z with sides ``pack.box``), so they are reproducible from the frozen
file alone. Two Numba kernels do the work, both over the flat program arrays of the geometry core
(one compiled kernel for every tree) and both writing only their own output slots, so results
are bitwise the same at any thread count:

- :func:`_cover_kernel`: for each sample point, how many element images contain it (phi < 0)
  and whether it lies in some element's envelope (phi_env <= 0). Porosity, envelope packing
  fraction and doubly-covered volume are fractions of these, with binomial standard errors.
- :func:`_probe_min_kernel`: for each (probing body, target body) pair, the minimum of the
  target's phi over the prober's shell probes: the deepest probe gives the overlap depth
  (:func:`probe_overlap`). It is NOT a contact count: two convex curved surfaces touch at a
  point no probe sits on, so coordination comes from the engine's own contact detection
  (:func:`peclet.packing.analysis.coordination.engine_coordination`).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from peclet.core.geom import kernels as K
from peclet.core.geom.certificate import check_equation1 as certificate_check
from peclet.core.geom.program import concatenate

from ..bed.freeze import Pack

__all__ = ["PackGeometry", "compile_kernels", "bulk_windows", "cover_fractions", "probe_overlap",
           "orientation", "floor_and_box", "certificate_check", "wall_sweep", "sweep_fractions",
           "sweep_voidage", "fraction_se"]


class Trees(NamedTuple):
    """The element's and its envelope's trees as flat programs (home frame): the program
    tables ``ops``, ``lk``, ``lr`` (:func:`peclet.core.geom.program.concatenate`), the element's
    rows [``s0``, ``s1``) and the envelope's [``e0``, ``e1``) (``e0 < 0``: no envelope)."""
    ops: np.ndarray
    lk: np.ndarray
    lr: np.ndarray
    s0: int
    s1: int
    e0: int
    e1: int


@njit(cache=True, parallel=True)
def _cover_kernel(trees, img_pos, img_rot, cutoff, pts, nin, inenv):
    """nin[q] = #images with phi < 0 at pts[q]; inenv[q] = 1 if some envelope has phi <= 0.

    ``trees`` a :class:`Trees`; img_pos[i] (world) and img_rot[i] (the row-major home->world
    rotation) the pose of image i; cutoff the distance (length) beyond which an image cannot
    contain a point.
    """
    ops, lk, lr, s0, s1, e0, e1 = trees
    n = pts.shape[0]
    m = img_pos.shape[0]
    c2 = cutoff * cutoff
    nchunk = (n + K.CHUNK - 1) // K.CHUNK
    for c in prange(nchunk):
        st = np.empty((K.MAX_STACK, K.STACK_COLS))
        for q in range(c * K.CHUNK, min(n, (c + 1) * K.CHUNK)):
            cnt = 0
            env = 0
            for i in range(m):
                dx = pts[q, 0] - img_pos[i, 0]
                dy = pts[q, 1] - img_pos[i, 1]
                dz = pts[q, 2] - img_pos[i, 2]
                if dx * dx + dy * dy + dz * dz > c2:
                    continue
                R = img_rot[i]
                lx = R[0] * dx + R[3] * dy + R[6] * dz
                ly = R[1] * dx + R[4] * dy + R[7] * dz
                lz = R[2] * dx + R[5] * dy + R[8] * dz
                v = K.eval_point(ops, lk, lr, s0, s1, lx, ly, lz, st)[0]
                if v < 0.0:
                    cnt += 1
                if e0 >= 0 and env == 0:
                    if K.eval_point(ops, lk, lr, e0, e1, lx, ly, lz, st)[0] <= 0.0:
                        env = 1
            nin[q] = cnt
            inenv[q] = env


@njit(cache=True, parallel=True)
def _probe_min_kernel(ops, lk, lr, s0, s1, shell, pa, ra, pb, rb, out):
    """out[k] = min over probes s of phi_b(R_b^T (p_a + R_a s - p_b)) for pair k.

    pa/pb (npair, 3) positions, ra/rb (npair, 9) row-major home->world rotations of the probing
    body a and the target body b.
    """
    npair = pa.shape[0]
    ns = shell.shape[0]
    for k in prange(npair):
        st = np.empty((K.MAX_STACK, K.STACK_COLS))
        A = ra[k]
        B = rb[k]
        best = np.inf
        for s in range(ns):
            sx = shell[s, 0]
            sy = shell[s, 1]
            sz = shell[s, 2]
            wx = pa[k, 0] + A[0] * sx + A[1] * sy + A[2] * sz - pb[k, 0]
            wy = pa[k, 1] + A[3] * sx + A[4] * sy + A[5] * sz - pb[k, 1]
            wz = pa[k, 2] + A[6] * sx + A[7] * sy + A[8] * sz - pb[k, 2]
            lx = B[0] * wx + B[3] * wy + B[6] * wz
            ly = B[1] * wx + B[4] * wy + B[7] * wz
            lz = B[2] * wx + B[5] * wy + B[8] * wz
            v = K.eval_point(ops, lk, lr, s0, s1, lx, ly, lz, st)[0]
            if v < best:
                best = v
        out[k] = best


def fraction_se(p, n):
    """Binomial standard error of a Monte Carlo fraction ``p`` from ``n`` samples."""
    return math.sqrt(max(p * (1.0 - p), 0.0) / n)


class PackGeometry:
    """The pack's trees compiled once, and its periodic images (3 x 3 in x and z)."""

    def __init__(self, pack: Pack):
        self.pack = pack
        b = pack.builder()
        progs = [b.program(pack.home_root)]
        if pack.envelope_root >= 0:
            progs.append(b.program(pack.envelope_root))
        self.ops, self.lk, self.lr, self.ranges = concatenate(progs)
        self.has_env = pack.envelope_root >= 0
        s0, s1 = self.ranges[0]
        e0, e1 = self.ranges[1] if self.has_env else (-1, -1)
        self.trees = Trees(self.ops, self.lk, self.lr, s0, s1, e0, e1)
        Lx, Lz = pack.box
        self.R = pack.rotations()
        shifts = np.array([[i * Lx, 0.0, j * Lz] for i in (-1, 0, 1) for j in (-1, 0, 1)])
        self.img_pos = np.ascontiguousarray(
            (pack.positions[None, :, :] + shifts[:, None, :]).reshape(-1, 3))
        self.img_rot = np.ascontiguousarray(np.tile(self.R.reshape(pack.n, 9), (9, 1)))
        self.owner = np.tile(np.arange(pack.n), 9)
        cutoff = pack.bounding_radius
        if self.has_env:
            c, r, _ = b.node_bound(pack.envelope_root)
            cutoff = max(cutoff, float(np.linalg.norm(c)) + r)
        self.cutoff = float(cutoff)

    def cover(self, pts):
        """(n_inside (K,) int, in_envelope (K,) bool) at world points ``pts`` (K, 3)."""
        pts = np.ascontiguousarray(pts, dtype=np.float64)
        nin = np.empty(len(pts), np.int64)
        env = np.empty(len(pts), np.int64)
        _cover_kernel(self.trees, self.img_pos, self.img_rot, self.cutoff, pts, nin, env)
        return nin, env.astype(bool)

    def probe_min(self, a_idx, b_img):
        """Min of body ``b_img`` (image index)'s phi over body ``a_idx``'s probes, per pair."""
        a_idx = np.asarray(a_idx, np.int64)
        b_img = np.asarray(b_img, np.int64)
        out = np.empty(len(a_idx))
        if len(a_idx) == 0:
            return out
        s0, s1 = self.ranges[0]
        _probe_min_kernel(self.ops, self.lk, self.lr, s0, s1, self.pack.shell,
                          np.ascontiguousarray(self.pack.positions[a_idx]),
                          np.ascontiguousarray(self.R[a_idx].reshape(-1, 9)),
                          np.ascontiguousarray(self.img_pos[b_img]),
                          np.ascontiguousarray(self.img_rot[b_img]), out)
        return out


def compile_kernels(pack: Pack):
    """Compile (or load from Numba's cache) the kernels of :class:`PackGeometry`'s queries
    for packs of ``pack``'s kind (its element and envelope) by querying ``pack`` once at one
    point and one pair: a pack of one element does, since the kernels' signatures depend only
    on the kinds of the arrays. A cold first run does this while the DEM's kernels compile in
    other processes, instead of after the pour with a core idle."""
    geo = PackGeometry(pack)
    geo.cover(pack.positions[:1])
    geo.probe_min([0], [0])


def bulk_windows(pack: Pack, floor_cut=(1.0, 0.8, 1.2), top_cut=(0.8, 0.6, 1.0)):
    """The page's three bulk windows ``(floor_cut[k], y_top - top_cut[k])``, y_top the highest
    centre. A bed too shallow for them (reduced runs) gets the cuts scaled down by the same
    factor so every window keeps at least half the bed height; returns (windows, scale).

    A degenerate window is refused (PecletArgumentError naming "pack"): a bed whose highest
    centre is not above the floor (y = 0), or a window that no element's bounding sphere
    reaches (its voidage would be 1 +- 0: a film or a gap, not a bed)."""
    from peclet.core.validation import PecletArgumentError

    ys = pack.positions[:, 1]
    ytop = float(ys.max())
    if not ytop > 0.0:
        raise PecletArgumentError("pack", "a bed above the floor y = 0", f"{pack.n} elements",
                                  f"highest centre at y = {ytop:.4g}")
    need = max(f + t for f, t in zip(floor_cut, top_cut))
    scale = 1.0 if ytop - need >= 0.5 * ytop else 0.5 * ytop / need
    windows = [(f * scale, ytop - t * scale) for f, t in zip(floor_cut, top_cut)]
    rb = float(pack.bounding_radius)
    for a, b in windows:
        if not (b > a and np.any((ys - rb < b) & (ys + rb > a))):
            raise PecletArgumentError(
                "pack", f"a bed that reaches its bulk window y in [{a:.4g}, {b:.4g}) (else "
                "eps would be 1 +- 0: a film or a gap, not a bed)", f"{pack.n} elements",
                f"centres from y = {ys.min():.4g} to {ytop:.4g}, bounding radius {rb:.4g}")
    return windows, scale


def cover_fractions(geo: PackGeometry, window, n_samples=400_000, seed=0):
    """Porosity, envelope packing fraction and doubly-covered fraction over one bulk window.

    Samples are uniform in [0, L_x) x [y0, y1) x [0, L_z) (numpy ``default_rng(seed)``).
    Returns a dict: eps, f_env (NaN without an envelope), double, each with its binomial
    standard error (``*_se``), and the window.
    """
    y0, y1 = (float(v) for v in window)
    if not y1 > y0:
        raise ValueError(f"window must be (y0, y1) with y1 > y0, got {window!r}")
    if int(n_samples) < 1:
        raise ValueError(f"n_samples must be >= 1, got {n_samples!r}")
    n = int(n_samples)
    Lx, Lz = geo.pack.box
    g = np.random.default_rng(seed)
    pts = np.column_stack([g.uniform(0, Lx, n), g.uniform(y0, y1, n), g.uniform(0, Lz, n)])
    nin, env = geo.cover(pts)
    eps = 1.0 - float((nin > 0).mean())
    dbl = float((nin >= 2).mean())
    f_env = float(env.mean()) if geo.has_env else math.nan
    return dict(window=[y0, y1], eps=eps, eps_se=fraction_se(eps, n), f_env=f_env,
                f_env_se=fraction_se(f_env, n) if geo.has_env else math.nan,
                double=dbl, double_se=fraction_se(dbl, n), n_samples=n)


def probe_overlap(geo: PackGeometry, gap=0.0):
    """The probe overlap depth: the probe-inside test run BOTH ways over every candidate pair.

    A pair (i, image j), j's owner != i, with centres closer than two bounding radii is
    "probe-touching" if a probe of either comes closer than ``gap`` (a length >= 0) to the
    other's tree (``gap = 0``: the page's strictly-inside test). Its purpose is the overlap
    depth; its per-body counts (``probe_counts``, ``probe_z_mean``) are NOT a coordination
    number: they miss every point contact between curved surfaces (a sphere bed reads
    Z ~ 1.2 instead of 4.6), see :mod:`peclet.packing.analysis.coordination`. Returns a dict:
    probe_counts (N,), probe_z_mean, pairs (ordered candidate pairs), max_depth (deepest probe
    of any body inside another, a length) and depths (per probe-touching pair).
    """
    from scipy.spatial import cKDTree

    pack = geo.pack
    tree = cKDTree(geo.img_pos)
    ai, bj = [], []
    for i in range(pack.n):
        for j in sorted(tree.query_ball_point(pack.positions[i], 2 * pack.bounding_radius)):
            if geo.owner[j] != i:
                ai.append(i)
                bj.append(j)
    ai = np.asarray(ai, np.int64)
    bj = np.asarray(bj, np.int64)
    m_ab = geo.probe_min(ai, bj)
    # the reverse direction: body j's probes (carried by its image) inside body i
    m_ba = _probe_min_reverse(geo, ai, bj)
    if not (np.isfinite(gap) and gap >= 0.0):
        raise ValueError(f"gap must be a finite length >= 0, got {gap!r}")
    touch = (m_ab < gap) | (m_ba < gap)
    cnt = np.bincount(ai[touch], minlength=pack.n) if len(ai) else np.zeros(pack.n, int)
    depth = np.maximum(-np.minimum(m_ab, m_ba), 0.0)
    return dict(probe_counts=cnt, probe_z_mean=float(cnt.mean()), pairs=int(len(ai)),
                max_depth=float(depth.max(initial=0.0)), depths=depth[touch])


def _probe_min_reverse(geo, ai, bj):
    out = np.empty(len(ai))
    if len(ai) == 0:
        return out
    s0, s1 = geo.ranges[0]
    _probe_min_kernel(geo.ops, geo.lk, geo.lr, s0, s1, geo.pack.shell,
                      np.ascontiguousarray(geo.img_pos[bj]),
                      np.ascontiguousarray(geo.img_rot[bj]),
                      np.ascontiguousarray(geo.pack.positions[ai]),
                      np.ascontiguousarray(geo.R[ai].reshape(-1, 9)), out)
    return out


def orientation(pack: Pack):
    """|cos theta| of each element axis from vertical (world y).

    The axis in the world is R(q_i) @ pack.axis_home. Returns a dict: cos (N,), mean, sem (the
    sample standard error) and sem_iso = (1/sqrt 12)/sqrt N, the standard error of the mean for
    an isotropic axis, whose |cos| is uniform on [0, 1] with mean 1/2.
    """
    ax = pack.rotations() @ pack.axis_home
    c = np.abs(ax[:, 1])
    n = len(c)
    return dict(cos=c, mean=float(c.mean()),
                sem=float(c.std(ddof=1) / math.sqrt(n)) if n > 1 else math.nan,
                sem_iso=float(1.0 / math.sqrt(12.0) / math.sqrt(n)))


def floor_and_box(pack: Pack, y_top=None):
    """Containment: the lowest probe of each body (world y; the floor is y = 0) and whether every
    centre lies in the periodic box [0, L_x) x [0, L_z) (and below ``y_top`` if given)."""
    world_y = pack.positions[:, 1, None] + np.einsum("nj,mj->nm", pack.rotations()[:, 1, :],
                                                     pack.shell)
    low = world_y.min(axis=1) if pack.shell.size else pack.positions[:, 1]
    Lx, Lz = pack.box
    x, y, z = pack.positions.T
    inside = (x >= 0) & (x < Lx) & (z >= 0) & (z < Lz) & (y > 0)
    if y_top is not None:
        inside &= y < y_top
    return dict(lowest_probe=low, min_lowest_probe=float(low.min()),
                all_in_box=bool(inside.all()), n_outside=int((~inside).sum()))


def wall_sweep(thicknesses, f_env, f_env_se=0.0, make=None, **quad_kw):
    """eps(t) = 1 - f_env s(t) with s(t) = V_solid(t) / V_env by implicit quadrature.

    ``make(t)`` returns an :class:`~peclet.packing.bed.elements.Element` (default: the page's sweep
    ring :func:`~peclet.packing.bed.elements.pall_ring_of_thickness`). Volumes come from
    ``SceneBuilder.body_properties`` (quadrature, not Monte Carlo) with its volume_error.
    Returns a list of dicts: t, t_over_d, s, s_err, eps, eps_err (propagated from s_err and
    f_env_se, added in quadrature). The same as :func:`sweep_voidage` of
    :func:`sweep_fractions` (which needs no pack: a run computes it while it waits).
    """
    return sweep_voidage(sweep_fractions(thicknesses, make, **quad_kw), f_env, f_env_se)


def sweep_fractions(thicknesses, make=None, **quad_kw):
    """Per wall thickness t (in D): t, t_over_d, s = V_solid(t) / V_env and its error s_err, by
    quadrature (see :func:`wall_sweep` for ``make`` and ``quad_kw``)."""
    from ..bed.elements import pall_ring_of_thickness

    make = pall_ring_of_thickness if make is None else make
    rows = []
    for t in thicknesses:
        el = make(float(t))
        lo, hi = el.bounds
        props = el.builder.body_properties(el.root, lo, hi, **quad_kw)
        d = 2.0 * el.params["r_outer"]
        rows.append(dict(t=float(t), t_over_d=float(t) / d,
                         s=float(props.volume / el.envelope_volume),
                         s_err=float(props.volume_error) / el.envelope_volume))
    return rows


def sweep_voidage(fractions, f_env, f_env_se=0.0):
    """:func:`sweep_fractions`' rows with eps = 1 - f_env s and eps_err (from s_err and
    f_env_se, added in quadrature) for a pack of envelope fraction ``f_env``."""
    return [dict(r, eps=float(1.0 - f_env * r["s"]),
                 eps_err=float(math.hypot(r["s"] * f_env_se, f_env * r["s_err"])))
            for r in fractions]
