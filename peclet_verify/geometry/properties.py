"""Geometry certificates: Equation 1 (its slack and tolerance are the engine's own,
:mod:`peclet.core.geom.certificate`), sign agreement between every evaluation path, and
distance agreement between two backends.

Conventions: phi < 0 inside (docs/architecture.md §2); the slack of Equation 1 is
``phi(p) - (|p - c| - r)`` (>= 0 for a certified root); distances are in the tree's length
unit.
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np

from peclet.core.geom.certificate import SLACK_TOL, equation1_slack, equation1_violations

from .. import registry as REG
from ..loading import backend_name
from ..search import (NOT_APPLICABLE, PropertyResult, bad_answer, encode_recipe, example_rng,
                      make_result)
from .answers import ask, ask_bound
from .backend import ReferenceBackend, check_backend
from .recipes import TreeRecipe
from .strategies import surface_points

__all__ = ["equation1", "sign_agreement", "distance_agreement"]


def _probe_outside(c, r, n, rng, max_factor=10.0):
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    # half the probes just outside the ball, half spread out to max_factor radii
    u = np.concatenate([rng.uniform(0, 0.05, n // 2), rng.uniform(0, max_factor, n - n // 2)])
    return c + d * (r * (1.0 + u) + 1e-9)[:, None]


def equation1(recipe: TreeRecipe, backend=None, n: int = 256, claimed_by: str = "backend",
              tol: float = SLACK_TOL) -> PropertyResult:
    """Equation 1, ``phi(p) >= |p - c| - r``, at ``n`` points outside the root's ball.

    The ball and the ``certified`` claim come from ``backend.bound`` when the backend has one
    (``claimed_by="backend"``), else from the reference rule (docs/architecture.md §4). Applies
    only to trees claimed certified (status "n/a" otherwise). The slack and what violates it
    (``slack < -tol * (1 + r)``, NaN included; ``tol`` defaults to the engine's own
    :data:`~peclet.core.geom.certificate.SLACK_TOL`) are those of
    :mod:`peclet.core.geom.certificate`. Figure: minimum slack; the violation rate is in
    ``details``. An unusable answer from
    ``evaluate`` or ``bound`` (see :mod:`peclet_verify.geometry.answers`) fails, with the answer in the
    text.
    """
    backend = check_backend(backend or ReferenceBackend())
    b, root, ni, nr = encode_recipe(recipe)
    name, fig = "equation1", REG.figure("equation1")
    if claimed_by == "backend" and callable(getattr(backend, "bound", None)):
        claim, why = ask_bound(backend, ni, nr, root)
        if why:
            return bad_answer(name, fig, "min", why)
        c, r, cert = claim
    else:
        c, r, cert = b.node_bound(root)
    c = np.asarray(c, float)
    if not cert or not math.isfinite(r):
        return PropertyResult(name, True, 1, float("nan"), fig, "", NOT_APPLICABLE, "min")
    p = _probe_outside(c, r, n, example_rng("eq1", ni.tobytes(), nr.tobytes()))
    phi, why = ask(backend, "evaluate", ni, nr, root, p)
    if why:
        return bad_answer(name, fig, "min", why)
    slack = equation1_slack(phi, np.linalg.norm(p - c, axis=1), r)
    bad = equation1_violations(slack, r, tol)
    k = int(np.argmin(slack))
    text = (f"{backend_name(backend)} claims the root certified with ball c={c.tolist()}, "
            f"r={r!r}, but at p={p[k].tolist()} phi={float(phi[k])!r} < |p-c|-r="
            f"{float(phi[k] - slack[k])!r} (slack {slack[k]:.3e}); {int(bad.sum())}/{n} points violate")
    return make_result(name, not bad.any(), slack.min(), fig, "min", text,
                   violation_rate=float(bad.mean()))


# ---------------------------------------------------------------------------- sign agreement
def _sign_points(b, root, n, rng):
    c, r, _ = b.node_bound(root)
    if not math.isfinite(r):
        c, r = np.zeros(3), 2.0
    raw = c + rng.uniform(-1.2, 1.2, (n, 3)) * r
    near = surface_points(b, root, raw[: n // 2], iterations=3)
    near += rng.normal(scale=1e-3 * r, size=near.shape)
    return np.concatenate([near, raw[n // 2:]]), r


def sign_agreement(recipe: TreeRecipe, other: Optional[TreeRecipe] = None, backend=None,
                   n: int = 256, band: float = 1e-9) -> PropertyResult:
    """Every way of evaluating the solid agrees on inside/outside at ``n`` probe points.

    Compared with the reference ``eval_root`` of ``recipe``: ``eval_root_grad``, ``bake`` (one
    lattice through the probes' first point per row is not possible, so a small lattice is
    baked and compared with ``eval_root`` at the lattice nodes), the scene query
    (``eval_scene``, pruned and brute, one instance at identity), ``decode(encode())``, the
    ``backend`` (and its ``evaluate_grad``) and, when given, a second recipe ``other`` for the
    same solid. Points with ``|phi| <= band * (1 + r)`` (on the surface) are skipped; at the
    others an answer of exactly 0 disagrees too. An unusable answer from the backend (see
    :mod:`peclet_verify.geometry.answers`: None, NaN/inf, wrong shape, raised) fails at once.
    Figure: the fraction of points whose sign disagrees.
    """
    backend = check_backend(backend or ReferenceBackend())
    b, root, ni, nr = encode_recipe(recipe)
    rng = example_rng("sign", ni.tobytes(), nr.tobytes())
    p, r = _sign_points(b, root, n, rng)
    ref = b.eval_root(root, p)
    views = {"eval_root_grad": b.eval_root_grad(root, p)[0],
             "decode(encode())": SceneBuilder_decode(ni, nr).eval_root(root, p)}
    methods = ["evaluate"] + (["evaluate_grad"] if callable(getattr(backend, "evaluate_grad",
                                                                     None)) else [])
    for method in methods:
        answer, why = ask(backend, method, ni, nr, root, p)
        if why:
            return bad_answer("sign_agreement", REG.figure("sign_agreement"), "max", why)
        views[backend_name(backend) + ("" if method == "evaluate" else "." + method)] = \
            answer if method == "evaluate" else answer[0]
    if math.isfinite(r):
        sb = SceneBuilder_decode(ni, nr)
        sb.add_instance(root)
        views["eval_scene(pruned)"] = sb.eval_scene(p, method="pruned")
        views["eval_scene(brute)"] = sb.eval_scene(p, method="brute")
    if other is not None:
        ob, oroot = other.build()
        views["other recipe"] = ob.eval_root(oroot, p)
    keep = np.abs(ref) > band * (1.0 + (r if math.isfinite(r) else 1.0))
    worst_rate, text = 0.0, ""
    for label, phi in views.items():
        # a view answering 0 (on the surface) where the reference is clearly off it
        # disagrees too: an engine answering constant zero must not pass
        dis = keep & (np.sign(phi) != np.sign(ref))
        rate = float(dis.sum()) / max(int(keep.sum()), 1)
        if rate > worst_rate:
            k = int(np.argmax(dis))
            worst_rate = rate
            text = (f"{label} disagrees with eval_root on the sign at {int(dis.sum())}/"
                    f"{int(keep.sum())} points, e.g. p={p[k].tolist()}: eval_root={float(ref[k])!r}, "
                    f"{label}={float(phi[k])!r}")
    bake_rate, bake_text = _bake_check(b, root, rng)
    if bake_rate > worst_rate:
        worst_rate, text = bake_rate, bake_text
    return make_result("sign_agreement", worst_rate == 0.0, worst_rate,
                   REG.figure("sign_agreement"), "max", text)


def SceneBuilder_decode(ni, nr):
    from peclet.core.geom import SceneBuilder
    return SceneBuilder.decode(ni, nr)


def _bake_check(b, root, rng, dims=(5, 4, 3)):
    c, r, _ = b.node_bound(root)
    if not math.isfinite(r):
        c, r = np.zeros(3), 2.0
    origin = c - r * rng.uniform(0.5, 1.0, 3)
    spacing = 2 * r * rng.uniform(0.2, 0.4, 3)
    baked = b.bake(root, origin, spacing, dims)
    i, j, k = np.meshgrid(*(np.arange(d) for d in dims), indexing="ij")
    idx = np.stack([i.ravel(order="F"), j.ravel(order="F"), k.ravel(order="F")], axis=1)
    pts = origin + idx * spacing
    ref = b.eval_root(root, pts)
    dis = np.sign(baked) != np.sign(ref)
    if not dis.any():
        return 0.0, ""
    m = int(np.argmax(dis))
    return float(dis.mean()), (f"bake disagrees with eval_root at lattice node {idx[m].tolist()} "
                               f"p={pts[m].tolist()}: bake={float(baked[m])!r} eval_root={float(ref[m])!r}")


# ---------------------------------------------------------------------------- distance
def distance_agreement(recipe: TreeRecipe, backend_a=None, backend_b=None, n: int = 256,
                       rtol: float = 1e-9) -> PropertyResult:
    """Two backends give the same phi within ``rtol * (1 + r)`` at ``n`` points in and around
    the root ball (r its radius). Figure: the largest absolute difference."""
    fig = REG.figure("distance_agreement")
    a = check_backend(backend_a or ReferenceBackend())
    bb = check_backend(backend_b or ReferenceBackend())
    b, root, ni, nr = encode_recipe(recipe)
    p, r = _sign_points(b, root, n, example_rng("dist", ni.tobytes(), nr.tobytes()))
    pa, why_a = ask(a, "evaluate", ni, nr, root, p)
    pb, why_b = ask(bb, "evaluate", ni, nr, root, p)
    if why_a or why_b:
        return bad_answer("distance_agreement", fig, "max", why_a or why_b)
    diff = np.abs(pa - pb)
    k = int(np.argmax(diff))
    tol = rtol * (1.0 + (r if math.isfinite(r) else 1.0))
    text = (f"{backend_name(a)} and {backend_name(bb)} differ by {diff[k]:.3e} (> {tol:.1e}) "
            f"at p={p[k].tolist()}: {float(pa[k])!r} vs {float(pb[k])!r}; {int((diff > tol).sum())}/{n} "
            "points differ")
    return make_result("distance_agreement", diff.max() <= tol, diff.max(), fig,
                   "max", text)
