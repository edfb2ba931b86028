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

#: Probes must satisfy |phi| <= this after projection.
PROBE_TOL = 1e-6


def even_spacing(area, count):
    """Nearest-neighbour spacing of ``count`` points in a hexagonal packing over ``area``."""
    area = float(area)
    if not (math.isfinite(area) and area > 0.0):
        raise ValueError(f"area must be a finite number > 0, got {area!r}")
    if not (isinstance(count, (int, np.integer)) and count >= 1):
        raise ValueError(f"count must be an integer >= 1, got {count!r}")
    return math.sqrt(2.0 * area / (math.sqrt(3.0) * count))


def count_for_spacing(area, spacing):
    """Probe count whose even (hexagonal) spread over ``area`` has NN spacing ``spacing``."""
    area = float(area)
    spacing = float(spacing)
    if not (math.isfinite(area) and area > 0.0):
        raise ValueError(f"area must be a finite number > 0, got {area!r}")
    if not (math.isfinite(spacing) and spacing > 0.0):
        raise ValueError(f"spacing must be a finite number > 0, got {spacing!r}")
    return int(math.ceil(2.0 * area / (math.sqrt(3.0) * spacing * spacing)))


def surface_mesh(builder, root, resolution, lo, hi):
    """(vertices (V, 3), faces (F, 3), area) of the marching-cubes surface of ``root``."""
    from skimage import measure
    lo = np.asarray(lo, dtype=np.float64).reshape(3)
    hi = np.asarray(hi, dtype=np.float64).reshape(3)
    res = int(resolution)
    sp = (hi - lo) / (res - 1)
    # a narrow band one lattice-cell diagonal wide gives the same mesh (see SceneBuilder.bake)
    band = float(np.linalg.norm(sp)) if builder.is_lipschitz(root) else None
    vals = builder.bake(root, origin=lo, spacing=sp, dims=[res] * 3, band=band)
    grid = np.ascontiguousarray(vals.reshape((res, res, res), order="F"))
    if not (grid.min() < 0.0 < grid.max()):
        raise ValueError("no surface inside the box: phi does not change sign on the lattice "
                         f"(resolution {res} may be too coarse, or the solid is empty)")
    verts, faces, _, _ = measure.marching_cubes(grid, level=0.0, spacing=tuple(sp))
    verts = verts + lo
    area = float(measure.mesh_surface_area(verts, faces))
    return verts, faces, area


def project(builder, root, points, iters=8):
    """Newton-project ``points`` onto phi = 0; returns (points, |phi|) after ``iters`` steps."""
    p = np.array(points, dtype=np.float64)
    for _ in range(iters):
        phi, g = builder.eval_root_grad(root, p)
        gg = np.einsum("ij,ij->i", g, g)
        gg[gg == 0.0] = 1.0
        p -= (phi / gg)[:, None] * g
    phi = builder.eval_root(root, p)
    return p, np.abs(phi)


def farthest_point_order(points, count, start):
    """Indices of ``count`` points chosen greedily farthest from those already chosen
    (ties: the lowest index), starting at index ``start``."""
    pts = np.ascontiguousarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3), got {pts.shape}")
    if not 1 <= int(count) <= len(pts):
        raise ValueError(f"count must be in [1, {len(pts)}], got {count!r}")
    if not 0 <= int(start) < len(pts):
        raise ValueError(f"start must be in [0, {len(pts) - 1}], got {start!r}")
    return _farthest_point_order(pts, int(count), int(start))


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

    ``resolution`` (int >= 8) is the marching-cubes lattice size per axis over [lo, hi];
    ``target`` (int >= 4) the probe count. Every probe has |phi| <= 1e-6 (Newton-projected;
    samples that do not converge, e.g. at a sharp crease, are dropped before thinning).
    ``stats``: area (marching-cubes), median / p90 / mean nearest-neighbour spacing, the even-
    spread spacing for this count and area, and the count an even spread needs for a given
    spacing is :func:`count_for_spacing`. Coordinates are those of the root's parent frame.
    """
    from scipy.spatial import cKDTree
    if isinstance(target, bool) or not isinstance(target, (int, np.integer)) or target < 4:
        raise ValueError(f"target (shell points) must be an integer >= 4, got {target!r}")
    if (isinstance(resolution, bool) or not isinstance(resolution, (int, np.integer))
            or not 8 <= resolution <= 1024):
        raise ValueError(f"resolution must be an integer in [8, 1024], got {resolution!r}")
    verts, faces, area = surface_mesh(builder, root, resolution, lo, hi)
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
