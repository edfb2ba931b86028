"""A mesh-based signed-distance engine: a foreign engine for peclet certification.

It knows nothing of CSG. For each tree (the flat encoding of docs/architecture.md §2) it bakes phi on a
lattice of ``n`` points per axis over a cube holding the root's ball, extracts a triangle mesh
with marching cubes (:func:`peclet.core.geom.mesh.surface_mesh`), and from then on answers from
the mesh alone:

- distance: the exact Euclidean distance to the nearest triangle (trimesh's
  ``triangles.closest_point`` on the triangles a bounding-sphere test cannot rule out);
- sign: the generalised winding number of the closed mesh (solid angles, Van Oosterom and
  Strackee's formula): inside where |w| > 1/2.

Convention: phi < 0 inside (peclet's), so the answer is ``-d`` inside and ``+d`` outside.
trimesh's own ``proximity.signed_distance`` is positive inside (and needs rtree, which this
environment lacks); it is not used.

Resolution band (h = lattice spacing = ``spacing(...)``): marching cubes places vertices by
linear interpolation, so on smooth parts of the surface the mesh is within ~h^2 * curvature / 8
of the true surface, while sharp edges and corners (box edges, CSG seams, cone tips) are cut off
at the lattice scale, within ~h. Hence |phi_mesh - phi| <~ h everywhere the lattice resolves
the solid (walls thicker than ~2h) and the sign is wrong only within that distance of the
surface. Features thinner than the lattice are lost altogether.
"""
from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["MeshEngine"]

#: Points x triangles per vectorised block (memory bound: a few arrays of this many doubles).
_BLOCK = 1 << 19


class MeshEngine:
    """Backend protocol of :mod:`peclet_verify.geometry.backend`: ``evaluate(node_ints, node_reals,
    root, points) -> phi``. ``n``: lattice points per axis (resolution), an int >= 8."""

    def __init__(self, n: int = 40):
        if isinstance(n, bool) or not isinstance(n, int) or n < 8:
            raise ValueError(f"n must be an int >= 8 (lattice points per axis), got {n!r}")
        self.n = n
        self.name = f"trimesh-marching-cubes(n={n})"
        self._key = None
        self._cached = None

    # -------------------------------------------------------------------- mesh of a tree
    def _ball_and_box(self, builder, root):
        """(centre, radius, lo, hi, h): the root's ball and the lattice's cube around it."""
        c, r, _ = builder.node_bound(root)
        if not np.isfinite(r):
            raise ValueError("root is unbounded: a mesh engine needs a finite solid")
        # margin of 1.5 cells on each side: the lattice's outer faces are strictly outside
        c, half = np.asarray(c, float), r * (self.n - 1) / (self.n - 4)
        return c, float(r), c - half, c + half, 2.0 * half / (self.n - 1)

    def spacing(self, node_ints, node_reals, root) -> float:
        """The lattice spacing h = 2 r / (n - 4) (length unit of the tree, r the root's ball
        radius) this engine meshes ``root`` with."""
        from peclet.core.geom import SceneBuilder
        b = SceneBuilder.decode(np.asarray(node_ints, np.int32), np.asarray(node_reals, float))
        return self._ball_and_box(b, int(root))[4]

    def _mesh(self, ni, nr, root):
        """(triangles or None, (centre, radius, h)) of ``root``, cached for the last tree.

        Triangles: (tri (F, 3, 3), their centroids (F, 3), their bounding radii (F,)); None
        when phi > 0 on the whole lattice (the solid is empty or thinner than the lattice: the
        cube holds the ball, so the solid cannot fill it)."""
        ni = np.ascontiguousarray(ni, dtype=np.int32)
        nr = np.ascontiguousarray(nr, dtype=np.float64)
        key = (ni.tobytes(), nr.tobytes(), int(root))
        if key != self._key:
            import trimesh
            from peclet.core.geom import SceneBuilder
            from peclet.core.geom.mesh import surface_mesh
            b = SceneBuilder.decode(ni, nr)
            c, r, lo, hi, h = self._ball_and_box(b, int(root))
            try:
                verts, faces, _ = surface_mesh(b, int(root), lo, hi, self.n)
            except ValueError:
                triangles = None
            else:
                tri = np.ascontiguousarray(trimesh.Trimesh(verts, faces, process=False)
                                           .triangles, dtype=np.float64)
                centre = tri.mean(axis=1)
                radius = np.linalg.norm(tri - centre[:, None, :], axis=2).max(axis=1)
                triangles = (tri, centre, radius)
            self._key, self._cached = key, (triangles, (c, r, h))
        return self._cached

    # -------------------------------------------------------------------- queries
    def evaluate(self, node_ints, node_reals, root, points):
        """phi (N,) float64 at ``points`` (N, 3), world = root's parent frame; < 0 inside."""
        from trimesh.triangles import closest_point
        mesh, (c, r, h) = self._mesh(node_ints, node_reals, root)
        p = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        if mesh is None:
            # no surface resolved: the solid counts as empty (distance +inf). Any positive
            # value is then a lower bound; answer the distance to the root's ball, floored at
            # h, so that Equation 1 and the sign (outside everywhere) are kept.
            return np.maximum(np.linalg.norm(p - c, axis=1) - r, h)
        tri, centre, radius = mesh
        out = np.empty(len(p))
        step = max(1, _BLOCK // len(tri))
        for s in range(0, len(p), step):
            q = p[s:s + step]
            dc = np.linalg.norm(q[:, None, :] - centre[None, :, :], axis=2)
            # a triangle can hold the nearest point only if its bounding sphere comes closer
            # than the best upper bound (the farthest point of the nearest bounding sphere)
            upper = (dc + radius).min(axis=1)
            ip, it = np.nonzero(dc - radius <= upper[:, None])
            d = np.linalg.norm(closest_point(tri[it], q[ip]) - q[ip], axis=1)
            dist = np.full(len(q), np.inf)
            np.minimum.at(dist, ip, d)
            inside = np.abs(_winding(tri, q)) > 0.5
            out[s:s + step] = np.where(inside, -dist, dist)
        return out


@njit(cache=True)
def _winding(tri, q):
    """Generalised winding number of the triangles ``tri`` (F, 3, 3) at points ``q`` (M, 3):
    the sum of the triangles' signed solid angles over 4 pi (+-1 inside a closed mesh, 0 out;
    the solid angle of each triangle by Van Oosterom and Strackee's formula)."""
    out = np.empty(q.shape[0])
    for m in range(q.shape[0]):
        total = 0.0
        for f in range(tri.shape[0]):
            ax = tri[f, 0, 0] - q[m, 0]
            ay = tri[f, 0, 1] - q[m, 1]
            az = tri[f, 0, 2] - q[m, 2]
            bx = tri[f, 1, 0] - q[m, 0]
            by = tri[f, 1, 1] - q[m, 1]
            bz = tri[f, 1, 2] - q[m, 2]
            cx = tri[f, 2, 0] - q[m, 0]
            cy = tri[f, 2, 1] - q[m, 1]
            cz = tri[f, 2, 2] - q[m, 2]
            la = np.sqrt(ax * ax + ay * ay + az * az)
            lb = np.sqrt(bx * bx + by * by + bz * bz)
            lc = np.sqrt(cx * cx + cy * cy + cz * cz)
            det = ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz) + az * (bx * cy - by * cx)
            den = (la * lb * lc + (ax * bx + ay * by + az * bz) * lc
                   + (ax * cx + ay * cy + az * cz) * lb + (bx * cx + by * cy + bz * cz) * la)
            total += 2.0 * np.arctan2(det, den)
        out[m] = total / (4.0 * np.pi)
    return out
