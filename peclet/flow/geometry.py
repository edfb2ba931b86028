"""The lattice geometry: which nodes are fluid, and where each cut link meets the wall.

A :class:`Grid` is a box of nodes ``origin + h * (i, j, k)`` with ``dims`` nodes per axis; a
periodic axis wraps node ``dims - 1`` onto node 0 (period ``dims * h``). The solid is the set
``phi < 0`` of a field given as a callable ``phi(points (N, 3)) -> (N,)`` in the same (world)
frame, e.g. a peclet scene; a node is fluid when ``phi > 0`` there.

Links are tested, not node signs: a link from a fluid node along ``C[d]`` is *cut* when phi
goes negative anywhere on the segment, whether the far node is solid or fluid (a wall thinner
than a cell between two fluid nodes). Where phi is 1-Lipschitz (every exact leaf and the
shell bound), ``phi(a) + phi(b) > |b - a|`` proves the segment clear, so only the other links
are searched: ``samples`` evenly spaced points (catching any solid thicker than 1/samples of
the link even where phi is not Lipschitz), then the first sign change is refined by a
safeguarded regula falsi (Illinois) on the exact phi to round-off. The wall fraction ``q`` in
(0, 1] is the distance from the node to the first crossing over the link length.

The result, :class:`LatticeGeometry`, stores only fluid nodes: their cell coordinates, a pull
table ``nb[i, n]`` (the fluid node the population ``i`` streams from, or ``-1 - k`` where link
record ``k`` says it comes back from a wall) and per cut link its ``q``, its node, direction and
the second fluid node Bouzidi's interpolation uses.

A link that leaves the box through a non-periodic face into fluid would lose mass: that is
refused (:class:`~peclet.core.validation.PecletArgumentError` naming the axis), since such an
axis needs walls.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from peclet.core.validation import PecletArgumentError, check_array, check_float, check_int

from .lattice import C, OPP, Q

__all__ = ["Grid", "LatticeGeometry", "build_geometry", "crossing_fraction"]

_AXES = "xyz"


@dataclass(frozen=True)
class Grid:
    """``dims`` (nx, ny, nz) nodes at ``origin + h * (i, j, k)`` (world units), ``periodic``
    per axis (period ``dims[a] * h``)."""

    origin: tuple
    h: float
    dims: tuple
    periodic: tuple

    def __post_init__(self):
        object.__setattr__(self, "origin", tuple(check_array("origin", self.origin, (3,))
                                                 .tolist()))
        object.__setattr__(self, "h", check_float("h", self.h, 0.0, lo_open=True))
        dims = self.dims
        if isinstance(dims, (str, bytes)) or not hasattr(dims, "__len__") or len(dims) != 3:
            raise PecletArgumentError("dims", "3 node counts (nx, ny, nz)", dims)
        object.__setattr__(self, "dims", tuple(check_int(f"dims[{a}]", d, 2, 4096)
                                               for a, d in enumerate(dims)))
        per = self.periodic
        if isinstance(per, (str, bytes)) or not hasattr(per, "__len__") or len(per) != 3 \
                or not all(isinstance(p, (bool, np.bool_)) for p in per):
            raise PecletArgumentError("periodic", "3 bools, one per axis", per)
        object.__setattr__(self, "periodic", tuple(bool(p) for p in per))

    @property
    def n_cells(self) -> int:
        return int(np.prod(self.dims))

    def points(self, ijk):
        """World coordinates of (possibly unwrapped) integer node coordinates ``ijk`` (N, 3)."""
        return np.asarray(self.origin) + self.h * np.asarray(ijk, dtype=np.float64)


@dataclass
class LatticeGeometry:
    """Fluid nodes and cut links of a :class:`Grid` (see the module docstring).

    ijk (N, 3) int64 cell coordinates of the fluid nodes (lexicographic order, x fastest);
    phi (N,) the field at them; nb (19, N) int64 pull table; link_node, link_dir (K,) the node
    and the *pulled* population of each cut link (the wall lies along ``-C[link_dir]``);
    link_q (K,) wall fraction in (0, 1]; link_ff (K,) the fluid node at ``+C[link_dir]`` when
    it is reachable by an uncut link, else -1; link_fff (K,) likewise the node one further
    (``+2 C[link_dir]``) or -1; cell (nx*ny*nz,) fluid index of each cell or -1.
    """

    grid: Grid
    ijk: np.ndarray
    phi: np.ndarray
    nb: np.ndarray
    link_node: np.ndarray
    link_dir: np.ndarray
    link_q: np.ndarray
    link_ff: np.ndarray
    link_fff: np.ndarray
    cell: np.ndarray
    thin_links: int

    @property
    def n_fluid(self) -> int:
        return len(self.ijk)

    @property
    def porosity(self) -> float:
        """Fluid node fraction of the box (the lattice's own porosity)."""
        return self.n_fluid / self.grid.n_cells

    def wall_points(self):
        """(K, 3) world coordinates of the wall crossings of the cut links."""
        d = -C[self.link_dir]
        return self.grid.points(self.ijk[self.link_node] + self.link_q[:, None] * d)


def crossing_fraction(phi, a, b, samples=8, tol=1e-13, max_iter=200):
    """First crossing of phi < 0 on each segment a[k] -> b[k] (world points, (K, 3)).

    Returns (t (K,), cut (K,) bool): ``t`` in (0, 1] the fraction of the way from a to the
    first point where phi changes sign (NaN where not cut). ``phi(a)`` must be > 0. Segments
    are sampled at ``samples`` evenly spaced points and the first sign change is refined by
    the Illinois method to a bracket of ``tol`` (relative to the segment).
    """
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    k = len(a)
    t = np.full(k, np.nan)
    if k == 0:
        return t, np.zeros(0, bool)
    d = b - a
    ts = np.arange(1, samples + 1) / samples
    vals = phi((a[:, None, :] + ts[None, :, None] * d[:, None, :]).reshape(-1, 3))
    vals = np.asarray(vals, np.float64).reshape(k, samples)
    if not np.all(np.isfinite(vals)):
        raise PecletArgumentError("phi", "a field with finite values", "NaN or inf on a link")
    neg = vals < 0.0
    cut = neg.any(axis=1)
    idx = np.flatnonzero(cut)
    j = np.argmax(neg[idx], axis=1)
    lo = np.where(j > 0, ts[np.maximum(j - 1, 0)], 0.0)
    hi = ts[j]
    flo = np.where(j > 0, vals[idx, np.maximum(j - 1, 0)], phi(a[idx]))
    fhi = vals[idx, j]
    t[idx] = _illinois(phi, a[idx], d[idx], lo, hi, flo, fhi, tol, max_iter)
    return t, cut


def _illinois(phi, a, d, lo, hi, flo, fhi, tol, max_iter):
    """Refine brackets [lo, hi] (phi(lo) >= 0 > phi(hi)) to width tol; returns hi (the point
    is on the solid side or on the surface, so q never points past the wall)."""
    lo, hi, flo, fhi = lo.copy(), hi.copy(), flo.copy(), fhi.copy()
    side = np.zeros(len(lo), np.int8)
    act = (hi - lo > tol) & (flo > 0.0)
    hi[flo == 0.0] = lo[flo == 0.0]
    for _ in range(max_iter):
        ia = np.flatnonzero(act)
        if len(ia) == 0:
            break
        l, h, fl, fh = lo[ia], hi[ia], flo[ia], fhi[ia]
        m = h - fh * (h - l) / (fh - fl)
        # a secant step that lands on an end or outside makes no progress: bisect instead
        bad = ~((m > l) & (m < h))
        m[bad] = 0.5 * (l + h)[bad]
        fm = np.asarray(phi(a[ia] + m[:, None] * d[ia]), np.float64)
        pos = fm > 0.0
        zero = fm == 0.0
        # Illinois: halve the value at the end that stays, so the secant cannot stall
        s = side[ia]
        keep_h = pos
        fh_new = np.where(keep_h & (s == 1), fh * 0.5, fh)
        fl_new = np.where(~keep_h & (s == -1), fl * 0.5, fl)
        l = np.where(keep_h, m, l)
        fl = np.where(keep_h, fm, fl_new)
        h = np.where(keep_h, h, m)
        fh = np.where(keep_h, fh_new, fm)
        side[ia] = np.where(keep_h, 1, -1)
        h = np.where(zero, m, h)
        lo[ia], hi[ia], flo[ia], fhi[ia] = l, h, fl, fh
        act[ia] = ~zero & (h - l > tol)
    return hi


def build_geometry(grid: Grid, phi, samples=8, lipschitz=True, seams=(False, False, False)):
    """Classify the nodes of ``grid`` with the field ``phi`` and find every cut link.

    ``phi(points (N, 3)) -> (N,)`` world-frame field, solid where < 0 (periodic on the grid's
    periodic axes: the caller's field must repeat with the grid's period). ``samples`` points
    per link search for a crossing; ``lipschitz`` lets a link whose end values prove it clear
    (phi(a) + phi(b) > |b - a|) skip the search (pass False for a field that is not
    1-Lipschitz: every link near a wall is then searched). ``seams``: per axis, True where the
    field is discontinuous across the periodic wrap (a window wrapped onto itself): links
    that wrap on that axis are always searched. Returns a :class:`LatticeGeometry`.

    Every link is cut from both ends or from neither (a link's two searches see the same
    samples only up to round-off, and at a seam or a grazing wall they can disagree): where
    only one end found a crossing at q, the other end gets one at 1 - q. Without this a
    population would be both bounced back and streamed (or neither), and mass, momentum and
    the flux over uncut links would not balance.
    """
    if not isinstance(grid, Grid):
        raise PecletArgumentError("grid", "a peclet.flow.geometry.Grid", grid)
    samples = check_int("samples", samples, 2, 1024)
    if isinstance(seams, (str, bytes)) or not hasattr(seams, "__len__") or len(seams) != 3:
        raise PecletArgumentError("seams", "3 bools, one per axis", seams)
    seam = np.array([bool(v) for v in seams])
    nx, ny, nz = grid.dims
    dims = np.array(grid.dims)
    per = np.array(grid.periodic)
    g = np.stack(np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij"),
                 axis=-1)
    # x fastest: node order is lexicographic in (z, y, x), so +x neighbours are adjacent
    ijk_all = g.transpose(2, 1, 0, 3).reshape(-1, 3).astype(np.int64)
    phi_all = np.asarray(phi(grid.points(ijk_all)), np.float64)
    if phi_all.shape != (len(ijk_all),) or not np.all(np.isfinite(phi_all)):
        raise PecletArgumentError("phi", "a callable returning one finite value per point",
                                  f"shape {phi_all.shape}")
    fluid = phi_all > 0.0
    if not fluid.any():
        raise PecletArgumentError("geometry", "a domain with fluid nodes", "no fluid node")
    cell = np.full(len(ijk_all), -1, np.int64)
    cell[fluid] = np.arange(int(fluid.sum()))
    ijk = ijk_all[fluid]
    phi_f = phi_all[fluid]
    n = len(ijk)

    def flat(c):
        return c[:, 0] + nx * (c[:, 1] + ny * c[:, 2])

    # per direction: the neighbour's fluid index (-1 solid or outside) and whether cut
    nbr = np.full((Q, n), -1, np.int64)
    far = np.full((Q, n), -1, np.int64)
    cut_q = np.full((Q, n), np.nan)
    thin = 0
    for d in range(1, Q):
        c = ijk + C[d]
        inside = np.ones(n, bool)
        wraps = np.zeros(n, bool)
        for a in range(3):
            if seam[a]:
                wraps |= (c[:, a] < 0) | (c[:, a] >= dims[a])
            if per[a]:
                c[:, a] %= dims[a]
            else:
                inside &= (c[:, a] >= 0) & (c[:, a] < dims[a])
        other = np.full(n, -1, np.int64)
        other[inside] = cell[flat(c[inside])]
        far_phi = np.empty(n)
        far_phi[inside] = phi_all[flat(c[inside])]
        out = np.flatnonzero(~inside)
        if len(out):
            far_phi[out] = np.asarray(phi(grid.points(ijk[out] + C[d])), np.float64)
        length = grid.h * float(np.sqrt((C[d] ** 2).sum()))
        search = (far_phi <= 0.0) | wraps
        if lipschitz:
            search |= phi_f + far_phi <= length
        else:
            search |= np.abs(phi_f) + np.abs(far_phi) <= 4.0 * length
        idx = np.flatnonzero(search)
        a = grid.points(ijk[idx])
        t, cut = crossing_fraction(phi, a, a + grid.h * C[d], samples=samples)
        q = np.full(n, np.nan)
        q[idx[cut]] = t[cut]
        # a far node inside the solid is always a cut, even if the samples missed the sign
        miss = np.flatnonzero((far_phi <= 0.0) & np.isnan(q))
        if len(miss):
            q[miss] = 1.0
        leak = np.flatnonzero(~inside & np.isnan(q))
        if len(leak):
            a_ = int(np.flatnonzero(~per & ((ijk[leak[0]] + C[d] < 0)
                                            | (ijk[leak[0]] + C[d] >= dims)))[0])
            raise PecletArgumentError(
                "periodic", f"periodic on axis {_AXES[a_]} or walls closing it",
                grid.periodic, f"axis {_AXES[a_]} is not periodic and fluid leaves the box "
                f"through it at node {ijk[leak[0]].tolist()}: {len(leak)} links without a wall")
        far[d] = other
        cut_q[d] = q
    # one verdict per link: cut from both ends or neither
    for d in range(1, Q):
        o = OPP[d]
        m = far[d]
        has = np.flatnonzero(m >= 0)
        mine = ~np.isnan(cut_q[d][has])
        theirs = ~np.isnan(cut_q[o][m[has]])
        fix = has[theirs & ~mine]
        if len(fix):
            cut_q[d][fix] = np.clip(1.0 - cut_q[o][m[fix]], 1e-9, 1.0)
    for d in range(1, Q):
        other = far[d].copy()
        q = cut_q[d]
        thin += int(np.count_nonzero((other >= 0) & ~np.isnan(q)))
        other[~np.isnan(q)] = -1
        nbr[d] = other
    # pull table: f_i at n comes from n - C[i] along the link of n in direction OPP[i]
    nb = np.empty((Q, n), np.int64)
    nb[0] = np.arange(n)
    link_node, link_dir, link_q, link_ff, link_fff = [], [], [], [], []
    k0 = 0
    for i in range(1, Q):
        o = OPP[i]
        src = nbr[o].copy()
        wall = np.flatnonzero(~np.isnan(cut_q[o]))
        src[wall] = -1 - (k0 + np.arange(len(wall)))
        nb[i] = src
        link_node.append(wall)
        link_dir.append(np.full(len(wall), i, np.int64))
        link_q.append(cut_q[o][wall])
        ff = nbr[i][wall]
        link_ff.append(ff)
        link_fff.append(np.where(ff >= 0, nbr[i][np.maximum(ff, 0)], -1))
        k0 += len(wall)
    return LatticeGeometry(grid=grid, ijk=ijk, phi=phi_f, nb=nb,
                           link_node=np.concatenate(link_node).astype(np.int64),
                           link_dir=np.concatenate(link_dir), link_q=np.concatenate(link_q),
                           link_ff=np.concatenate(link_ff).astype(np.int64),
                           link_fff=np.concatenate(link_fff).astype(np.int64), cell=cell,
                           thin_links=thin)
