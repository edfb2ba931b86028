"""Surface probes ("shell") of a CSG solid: evenly spread points with |phi| <= 1e-6.

Pipeline: bake phi on a lattice (x fastest) -> marching cubes (scikit-image) -> dense
area-weighted sampling of the triangles -> Newton projection onto phi = 0 along the analytic
gradient (``p -= phi g / |g|^2``) -> farthest-point thinning to exactly the requested count.
Farthest-point thinning works in 3-D distance, so the two faces of a wall or web thicker than
the spacing both receive probes. Deterministic for a given seed.

Spacing: N probes spread evenly (hexagonally) over area A have nearest-neighbour spacing
``sqrt(2 A / (sqrt(3) N))`` (:func:`even_spacing`); :func:`count_for_spacing` inverts it.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from peclet.core.validation import as_points, check_float, check_int

from .mesh import MAX_LATTICE, surface_mesh

#: Probes must satisfy |phi| <= this after projection.
PROBE_TOL = 1e-6
#: Most probes one call may ask for (thinning costs ~ oversample * target^2).
MAX_PROBES = 1_000_000


def even_spacing(area, count):
    """Nearest-neighbour spacing of ``count`` points in a hexagonal packing over ``area``."""
    area = check_float("area", area, 0.0, math.inf, lo_open=True)
    count = check_int("count", count, 1)
    return math.sqrt(2.0 * area / (math.sqrt(3.0) * count))


def count_for_spacing(area, spacing):
    """Probe count whose even (hexagonal) spread over ``area`` has NN spacing ``spacing``."""
    area = check_float("area", area, 0.0, math.inf, lo_open=True)
    spacing = check_float("spacing", spacing, 0.0, math.inf, lo_open=True)
    return int(math.ceil(2.0 * area / (math.sqrt(3.0) * spacing * spacing)))


def project(builder, root, points, iters=8):
    """Newton-project ``points`` (N, 3) onto phi = 0; returns (points, |phi|) after ``iters``
    (an int in [0, 1000]) steps along the analytic gradient."""
    p = as_points(points).copy()
    for _ in range(check_int("iters", iters, 0, 1000)):
        phi, g = builder.eval_root_grad(root, p)
        gg = np.einsum("ij,ij->i", g, g)
        gg[gg == 0.0] = 1.0
        p -= (phi / gg)[:, None] * g
    phi = builder.eval_root(root, p)
    return p, np.abs(phi)


def farthest_point_order(points, count, start):
    """Indices of ``count`` points chosen greedily farthest from those already chosen
    (ties: the lowest index), starting at index ``start``."""
    pts = as_points(points)
    count = check_int("count", count, 1, max(len(pts), 1))
    start = check_int("start", start, 0, len(pts) - 1)
    return _farthest_point_order(pts, count, start)


@njit(cache=True)
def _farthest_point_order(pts, count, start):
    n = pts.shape[0]
    d = np.full(n, np.inf)
    out = np.empty(count, dtype=np.int64)
    i = start
    for k in range(count):
        out[k] = i
        x = pts[i, 0]
        y = pts[i, 1]
        z = pts[i, 2]
        best = -1.0
        nxt = 0
        for j in range(n):
            dx = pts[j, 0] - x
            dy = pts[j, 1] - y
            dz = pts[j, 2] - z
            e = dx * dx + dy * dy + dz * dz
            if e < d[j]:
                d[j] = e
            if d[j] > best:
                best = d[j]
                nxt = j
        i = nxt
    return out


def shell_probes(builder, root, target, resolution, lo, hi, seed=0, oversample=16):
    """(probes (M, 3), stats dict) on the surface of ``root``; M == ``target``.

    ``resolution`` (int in [8, 1024]) is the marching-cubes lattice size per axis over
    [lo, hi]; ``target`` (int in [4, 1e6]) the probe count; ``seed`` (int >= 0) the numpy
    generator seed; ``oversample`` (int in [1, 1024]) dense samples per probe before thinning. Every probe has |phi| <= 1e-6 (Newton-projected;
    samples that do not converge, e.g. at a sharp crease, are dropped before thinning).
    ``stats``: area (marching-cubes), median / p90 / mean nearest-neighbour spacing, the even-
    spread spacing for this count and area, and the count an even spread needs for a given
    spacing is :func:`count_for_spacing`. Coordinates are those of the root's parent frame.
    """
    from scipy.spatial import cKDTree
    target = check_int("target", target, 4, MAX_PROBES)
    resolution = check_int("resolution", resolution, 8, MAX_LATTICE)
    seed = check_int("seed", seed, 0)
    oversample = check_int("oversample", oversample, 1, 1024)
    # open at the box: a probe must lie on phi = 0, never on a cut face
    verts, faces, area = surface_mesh(builder, root, lo, hi, resolution, close=False)
    rng = np.random.default_rng(seed)
    tri = verts[faces]
    a = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    m = int(oversample) * int(target)
    pick = rng.choice(len(faces), size=m, p=a / a.sum())
    r1 = np.sqrt(rng.random(m))
    r2 = rng.random(m)
    t = tri[pick]
    dense = ((1.0 - r1)[:, None] * t[:, 0] + (r1 * (1.0 - r2))[:, None] * t[:, 1]
             + (r1 * r2)[:, None] * t[:, 2])
    dense, res = project(builder, root, dense)
    good = res <= PROBE_TOL
    dense = dense[good]
    if len(dense) < target:
        raise ValueError(f"only {len(dense)} surface samples converged; raise resolution")
    order = farthest_point_order(dense, int(target), rng.integers(len(dense)))
    probes = np.ascontiguousarray(dense[order])
    d, _ = cKDTree(probes).query(probes, k=2)
    nn = d[:, 1]
    stats = {"area": area, "count": int(len(probes)), "median_spacing": float(np.median(nn)),
             "p90_spacing": float(np.percentile(nn, 90)), "mean_spacing": float(nn.mean()),
             "even_spacing": even_spacing(area, int(len(probes))),
             "dropped_unconverged": int((~good).sum()),
             "max_abs_phi": float(np.abs(builder.eval_root(root, probes)).max())}
    return probes, stats
