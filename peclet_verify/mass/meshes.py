"""Grid leaves made from meshes, measured against the mesh's exact mass properties (issue 41).

A :class:`MeshSolid` is a closed triangle mesh drawn at random: a trimesh primitive (box,
cylinder, capsule, icosphere, or an annulus: a ring with a thin wall) turned and moved, or the
marching-cubes surface of a random CSG tree (:func:`peclet.core.geom.surface_mesh`). Its grid
leaf (:func:`peclet.core.geom.grids.grid_from_mesh`, ``cells`` lattice cells across its largest
extent) is measured by peclet's quadrature and compared with the mesh's own volume, centre of
mass and inertia by the divergence theorem (:func:`~peclet.core.geom.grids.mesh_mass_properties`).

Two checks, each on the volume and on the first and second moments about the mesh's centre
of mass c (every component):

- *fidelity*, a bound: the grid samples the mesh's exact signed distance (1-Lipschitz), so the
  grid's sign is the mesh's at every point farther than one cell diagonal d = sqrt(3) h from the
  mesh's surface (a trilinear value is a convex combination of corner values each within d of
  the point's own distance). The two solids differ only inside the band B = {|phi_mesh| <= d},
  so for any integrand g the two integrals differ by at most the integral of |g| over B (g = 1,
  |x - c|, |x - c|^2). The band's integrals are Monte Carlo estimates with the mesh's exact
  distance (libigl), taken at their upper 5-sigma value. This bound is loose (at 20 cells across
  a sphere it allows most of its volume); what it catches is a grid of another solid: wrong
  units, a lattice misplaced by more than the band, the inside out, lost pieces.
- *quadrature*: the quadrature's figure less the mesh's equals an independent Monte Carlo
  estimate of the same difference (the grid's sign against the mesh's at the same points)
  within 5 standard errors plus the quadrature's own error estimate. This one is tight (a few
  tenths of a percent of the volume): it certifies the quadrature of grid leaves (the search
  of phi / L, the lattice-aligned cells) on solids with no closed form.

Both add the quadrature's error estimates; the figure is the largest error / allowed (passes at
<= 1). The rate at which the grid solid converges to the mesh is not certified here; it is
measured in validation/grid_shapes.py.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np
from hypothesis import strategies as st

from peclet.core.validation import PecletArgumentError

from .. import registry as REG
from ..geometry.recipes import LIPSCHITZ_KINDS, TreeRecipe
from ..geometry.strategies import trees
from ..search import NOT_APPLICABLE, PropertyResult, make_result

__all__ = ["PRIMITIVES", "MeshSolid", "mesh_solids", "band_sample", "grid_mass_certificate"]

#: trimesh primitives and the ranges of their parameters (lengths)
PRIMITIVES = {
    "box": dict(a=(0.3, 1.5), b=(0.3, 1.5), c=(0.3, 1.5)),
    "cylinder": dict(radius=(0.2, 0.8), height=(0.3, 1.5)),
    "capsule": dict(radius=(0.2, 0.6), height=(0.2, 1.2)),
    "icosphere": dict(radius=(0.3, 1.0)),
    "annulus": dict(r_min=(0.3, 0.6), wall=(0.12, 0.3), height=(0.3, 1.0)),
}
#: Monte Carlo points of the band estimate, and the sigmas of its upper value
BAND_POINTS, BAND_SIGMAS = 200_000, 5.0


def _primitive(kind, p):
    import trimesh
    if kind == "box":
        return trimesh.creation.box(extents=(p["a"], p["b"], p["c"]))
    if kind == "cylinder":
        return trimesh.creation.cylinder(radius=p["radius"], height=p["height"], sections=48)
    if kind == "capsule":
        return trimesh.creation.capsule(height=p["height"], radius=p["radius"], count=(24, 24))
    if kind == "icosphere":
        return trimesh.creation.icosphere(subdivisions=3, radius=p["radius"])
    return trimesh.creation.annulus(r_min=p["r_min"], r_max=p["r_min"] + p["wall"],
                                    height=p["height"], sections=48)


@dataclass(frozen=True)
class MeshSolid:
    """A closed mesh: ``kind`` a key of :data:`PRIMITIVES` with ``params`` (name, value) pairs,
    or ``"tree"`` with ``tree`` (meshed on a 40^3 lattice over its ball); turned by the unit
    quaternion ``quat`` (x, y, z, w) and moved by ``shift``; its grid has ``cells`` lattice
    cells across the mesh's largest extent."""

    kind: str
    params: tuple
    quat: tuple
    shift: tuple
    cells: int
    tree: Optional[TreeRecipe] = None

    def mesh(self):
        """(vertices (V, 3), faces (F, 3)) of the mesh, or None when a tree's surface is not a
        closed mesh (a property then does not apply)."""
        from scipy.spatial.transform import Rotation
        if self.kind == "tree":
            from peclet.core.geom import surface_mesh
            b, root = self.tree.build()
            c, r, _ = b.node_bound(root)
            try:
                v, f, _ = surface_mesh(b, root, np.asarray(c) - 1.05 * r,
                                       np.asarray(c) + 1.05 * r, 40)
            except ValueError:
                return None
        else:
            m = _primitive(self.kind, dict(self.params))
            v, f = np.asarray(m.vertices, float), np.asarray(m.faces, np.int64)
        v = Rotation.from_quat(self.quat).apply(v) + np.asarray(self.shift)
        return v, f

    def snippet(self) -> str:
        """Runnable Python that rebuilds the mesh as ``v, f``."""
        return (f"from peclet_verify.mass.meshes import MeshSolid\n"
                f"solid = {self!r}\nv, f = solid.mesh()")


def _params(kind):
    return st.tuples(*(st.tuples(st.just(name), st.floats(lo, hi)) for name, (lo, hi)
                       in PRIMITIVES[kind].items()))


def _quats():
    return st.tuples(*[st.floats(-1.0, 1.0)] * 4).filter(
        lambda q: sum(x * x for x in q) > 0.1).map(
        lambda q: tuple(np.asarray(q) / math.sqrt(sum(x * x for x in q))))


def mesh_solids(cells=(14, 24), with_trees=True) -> st.SearchStrategy:
    """:class:`MeshSolid` s: the primitives of :data:`PRIMITIVES` and (``with_trees``) meshes
    of random 1-Lipschitz CSG trees (at most 3 leaves), at ``cells`` (an int range) lattice
    cells across."""
    shift = st.tuples(*[st.floats(-0.5, 0.5)] * 3)
    n = st.integers(int(cells[0]), int(cells[1]))
    kinds = [st.builds(MeshSolid, st.just(k), _params(k), _quats(), shift, n)
             for k in PRIMITIVES]
    if with_trees:
        kinds.append(st.builds(MeshSolid, st.just("tree"), st.just(()), _quats(), shift, n,
                               trees(kinds=LIPSCHITZ_KINDS, max_leaves=3)))
    return st.one_of(*kinds)


def band_sample(v, f, grid_phi, centre, d, seed=0, n=BAND_POINTS):
    """Monte Carlo over the bounding box of the closed mesh (v, f) grown by d (which holds the
    band |phi_mesh| <= d), with the mesh's exact distance (libigl, winding-number sign) and the
    grid's field ``grid_phi(points)``. Returns (band, diff, sigma):

    - ``band``: upper (BAND_SIGMAS-sigma) values of the integrals of 1, |x - centre| and
      |x - centre|^2 over the band;
    - ``diff``: estimates of the integrals of 1, (x - centre) (3,) and (x - c)(x - c)^T (3, 3)
      over the grid solid less those over the mesh solid;
    - ``sigma``: BAND_SIGMAS standard errors of ``diff`` (same shapes)."""
    import igl
    lo, hi = v.min(axis=0) - d, v.max(axis=0) + d
    box = float(np.prod(hi - lo))
    p = np.random.default_rng(seed).uniform(lo, hi, (n, 3))
    phi = np.asarray(igl.signed_distance(
        p, v, f, sign_type=igl.SignedDistanceType.SIGNED_DISTANCE_TYPE_WINDING_NUMBER)[0])
    x = p - centre
    r = np.linalg.norm(x, axis=1)
    inside = np.abs(phi) <= d
    band = []
    for g in (np.ones(n), r, r * r):
        vals = np.where(inside, g, 0.0) * box
        band.append(float(vals.mean() + BAND_SIGMAS * vals.std() / math.sqrt(n)))
    dif = ((np.asarray(grid_phi(p)) < 0.0).astype(float) - (phi < 0.0)) * box
    diff, sigma = [], []
    for g in (dif, dif[:, None] * x, dif[:, None, None] * x[:, :, None] * x[:, None, :]):
        diff.append(g.mean(axis=0))
        sigma.append(BAND_SIGMAS * g.std(axis=0) / math.sqrt(n))
    return tuple(band), tuple(diff), tuple(sigma)


def _second_moment(props, c):
    """The integral of (x - c)(x - c)^T over a measured solid (unit density) from its volume,
    centre of mass and inertia about it."""
    dc = np.asarray(props.com) - c
    s_com = 0.5 * np.trace(props.inertia) * np.eye(3) - props.inertia
    return s_com + props.volume * np.outer(dc, dc)


def grid_mass_certificate(solid: MeshSolid, tol=1e-6, make_grid=None) -> PropertyResult:
    """The grid leaf of ``solid``'s mesh (``make_grid(builder, mesh, spacing)``, default
    :func:`~peclet.core.geom.grids.grid_from_mesh`), measured by peclet's quadrature (``tol``),
    against the mesh's exact volume, first and second moments about its centre of mass c:

    - *fidelity*: each differs by at most the band bound of the module notes;
    - *quadrature*: each difference equals the Monte Carlo estimate of the same difference
      (grid solid less mesh solid, :func:`band_sample`) within its 5-sigma error plus the
      quadrature's own error estimate.

    Figure: the largest error / allowed. Not applicable to a tree whose surface is not a
    closed mesh."""
    from peclet.core import geom
    from peclet.core.geom.grids import grid_from_mesh, mesh_mass_properties, quadrature_layout

    name, fig = "grid_mass", REG.figure("grid_mass")
    mesh = solid.mesh()
    try:
        exact = None if mesh is None else mesh_mass_properties(mesh)
    except PecletArgumentError:
        exact = None
    if exact is None or exact.volume <= 0.0:
        return PropertyResult(name, True, 1, float("nan"), fig, "", NOT_APPLICABLE, "max")
    v, f = mesh
    h = float((v.max(axis=0) - v.min(axis=0)).max()) / solid.cells
    b = geom.SceneBuilder()
    g = (make_grid or grid_from_mesh)(b, mesh, spacing=h)
    lo, hi, nq = quadrature_layout(b, g)
    got = b.body_properties(g, lo, hi, n=nq, tol=tol)
    c = exact.com
    band, diff, sigma = band_sample(v, f, lambda p: b.eval_root(g, p), c, math.sqrt(3.0) * h)
    s_exact = 0.5 * np.trace(exact.inertia) * np.eye(3) - exact.inertia
    errors = (got.volume - exact.volume, got.volume * (np.asarray(got.com) - c),
              _second_moment(got, c) - s_exact)
    quad = (got.volume_error, got.volume_error * float(np.linalg.norm(np.asarray(got.com) - c)),
            got.moment_error)
    checks = []
    for what, err, bound, est, sig, q in zip(
            ("volume", "first moment about the mesh's com", "second moment about it"),
            errors, band, diff, sigma, quad):
        checks.append((f"{what} (fidelity)", float(np.abs(err).max()), bound + q))
        dev = np.abs(np.asarray(err) - est)
        allow = np.asarray(sig) + q + 1e-300
        k = int(np.argmax(dev / allow))
        checks.append((f"{what} (quadrature against Monte Carlo)", float(dev.flat[k]),
                       float(allow.flat[k])))
    ratios = [err / allowed for _, err, allowed in checks]
    k = int(np.argmax(ratios))
    what, err, allowed = checks[k]
    text = (f"{solid.kind} mesh ({len(f)} faces) at h = {h:.4g}: {what} off by {err:.4g}, "
            f"more than its allowance {allowed:.4g} (grid volume {got.volume:.6g}, mesh "
            f"{exact.volume:.6g})")
    return make_result(name, max(ratios) <= 1.0, max(ratios), fig, "max", text,
                       volume_rel_error=float(got.volume / exact.volume - 1.0), spacing=h)
