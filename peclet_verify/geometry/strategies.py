"""Hypothesis strategies of the geometry family: CSG trees (as recipes), leaves, transforms and
probe points.

Every tree strategy produces a :class:`TreeRecipe`: an immutable record of the public
``SceneBuilder`` calls that build it. A recipe is valid by construction (parameters are drawn
inside each leaf's accepted range, quaternions are unit, scales positive), so no example is ever
rejected; it shrinks towards a single leaf with an identity transform; and ``repr(recipe)`` /
``recipe.snippet()`` is a runnable Python snippet that rebuilds the failing tree.

Conventions follow docs/architecture.md §2: phi < 0 inside, quaternions (x, y, z, w) active, a
node's value in its parent frame is ``s * f(R^T (p - t) / s)``. Lengths are in the builder's
unit; the default parameter ranges give solids about one unit across (an example of use:
:mod:`peclet_verify.geometry`).
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from peclet.core.geom import LEAF_NAMES, LEAVES_BY_NAME

from ..checks import check_int, check_range
from .recipes import (BOUNDED_KINDS, EXACT_KINDS, IDENTITY, LIPSCHITZ_KINDS, OPERATORS,
                      LeafCall, OpCall, Transform, TreeRecipe)

__all__ = ["Transform", "LeafCall", "OpCall", "TreeRecipe", "BOUNDED_KINDS", "EXACT_KINDS",
           "LIPSCHITZ_KINDS", "OPERATORS", "leaf_params", "leaves", "transforms", "trees",
           "points_in_box", "points_outside_ball", "points_near_surface", "unit_quaternions",
           "same_solid_pairs", "surface_points"]


# ---------------------------------------------------------------------------- validation
def _check_kinds(kinds, name="kinds", allowed=LEAF_NAMES):
    if isinstance(kinds, str):
        kinds = (kinds,)
    kinds = tuple(kinds)
    if not kinds:
        raise ValueError(f"{name} must name at least one leaf kind from {list(allowed)}")
    bad = [k for k in kinds if k not in allowed]
    if bad:
        raise ValueError(f"{name} must be leaf kinds from {list(allowed)}, got {bad}")
    return kinds


# ---------------------------------------------------------------------------- leaves
def _size(lo=0.1, hi=1.0):
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


def _frac(lo, hi):
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


def leaf_params(kind: str) -> st.SearchStrategy:
    """Parameter tuples for leaf ``kind`` inside its accepted range (about unit size).

    Ranges: radii/extents in [0.1, 1]; hollow_cylinder thickness a fraction 0.05..0.95 of
    rOuter; torus tube a fraction 0.05..0.9 of R; superquadric exponent in [0.1, 1];
    half_space a unit normal and offset in [-1, 1].
    """
    kind = _check_kinds(kind, "kind")[0]
    if kind == "sphere":
        return st.tuples(_size(0.2, 1.0))
    if kind in ("box", "ellipsoid"):
        return st.tuples(_size(), _size(), _size())
    if kind == "hollow_cylinder":
        return st.builds(lambda ro, h, f: (ro, h, ro * f), _size(0.2, 1.0), _size(0.1, 1.5),
                         _frac(0.05, 0.95))
    if kind == "hollow_cylinder_shell":
        return st.builds(lambda ro, f, h: (ro, ro * f, h), _size(0.2, 1.0), _frac(0.0, 0.95),
                         _size(0.1, 1.5))
    if kind == "capsule":
        return st.tuples(_size(0.1, 0.8), _frac(0.0, 1.0))
    if kind == "torus":
        return st.builds(lambda R, f: (R, R * f), _size(0.3, 1.0), _frac(0.05, 0.9))
    if kind == "cone":
        return st.builds(lambda rb, rt, h, flip: (rt, rb, h) if flip else (rb, rt, h),
                         _size(0.05, 1.0), _frac(0.0, 1.0), _size(0.1, 1.0), st.booleans())
    if kind == "superquadric":
        return st.tuples(_size(), _size(), _size(), _frac(0.1, 1.0))
    # half_space
    return st.builds(lambda n, o: (*n, o), _unit_vectors(), _frac(-1.0, 1.0))


def leaves(kinds=BOUNDED_KINDS, certified_only: bool = False, transforms: bool = True,
           scale=(0.5, 2.0)) -> st.SearchStrategy:
    """One-leaf :class:`TreeRecipe` s of the given ``kinds``.

    ``certified_only`` keeps the exact (certified) kinds among ``kinds``; it is an error if none
    remain. ``transforms`` False gives identity transforms.
    """
    return _leaf_calls(kinds, certified_only, transforms, scale).map(TreeRecipe)


def _leaf_calls(kinds, certified_only, with_transforms, scale):
    kinds = _check_kinds(kinds)
    if certified_only:
        kept = tuple(k for k in kinds if LEAVES_BY_NAME[k].exact)
        if not kept:
            raise ValueError(f"certified_only=True but none of kinds {list(kinds)} is exact; "
                             f"exact kinds are {list(EXACT_KINDS)}")
        kinds = kept
    tr = _transform_strategy(scale=scale) if with_transforms else st.just(IDENTITY)
    per_kind = [st.builds(LeafCall, st.just(k), leaf_params(k), tr) for k in kinds]
    return st.one_of(per_kind)


# ---------------------------------------------------------------------------- transforms
def _unit_vectors():
    def norm(v):
        n = math.sqrt(sum(c * c for c in v))
        return (1.0, 0.0, 0.0) if n < 1e-3 else tuple(c / n for c in v)
    return st.tuples(_frac(-1, 1), _frac(-1, 1), _frac(-1, 1)).map(norm)


def unit_quaternions(max_angle: float = math.pi) -> st.SearchStrategy:
    """Unit quaternions (x, y, z, w) as axis-angle, shrinking to the identity."""
    if not (0.0 <= max_angle <= math.pi):
        raise ValueError(f"max_angle must be in [0, pi], got {max_angle!r}")

    def quat(axis, angle):
        s = math.sin(0.5 * angle)
        return (axis[0] * s, axis[1] * s, axis[2] * s, math.cos(0.5 * angle))
    return st.builds(quat, _unit_vectors(), _frac(0.0, max_angle))


def transforms(translation: float = 1.0, rotation: bool = True, scale=(0.5, 2.0),
               identity: bool = True) -> st.SearchStrategy:
    """:class:`Transform` s: translation components in [-translation, translation], a unit
    quaternion (any rotation if ``rotation``), an isotropic scale in ``scale=(lo, hi)``.

    With ``identity`` (default) the identity is one of the choices and what examples shrink to.
    """
    translation = float(translation)
    if not (math.isfinite(translation) and translation >= 0):
        raise ValueError(f"translation must be a finite number >= 0, got {translation!r}")
    lo, hi = check_range(scale, "scale")
    comp = _frac(-translation, translation) if translation > 0 else st.just(0.0)
    rot = unit_quaternions() if rotation else st.just((0.0, 0.0, 0.0, 1.0))
    sc = _frac(lo, hi) if lo < hi else st.just(lo)
    general = st.builds(Transform, st.tuples(comp, comp, comp), rot, sc)
    return st.one_of(st.just(IDENTITY), general) if identity else general


_transform_strategy = transforms


# ---------------------------------------------------------------------------- trees
def trees(kinds=None, max_leaves: int = 8, max_depth: Optional[int] = None,
          certified_only: bool = False, transforms: bool = True, scale=(0.5, 2.0),
          operators=OPERATORS) -> st.SearchStrategy:
    """CSG trees as :class:`TreeRecipe`, built with ``st.recursive`` (valid by construction).

    Parameters
    ----------
    kinds : leaf kinds allowed (default: every bounded kind, i.e. all but ``half_space``).
    max_leaves : at most this many leaves (1..64).
    max_depth : operators deeper than this are cut to their leftmost leaf (default: no cut).
    certified_only : only trees the certificate rule certifies: exact leaves wherever a leaf
        carries the ball (unions, left operands), 1-Lipschitz leaves on the right of an
        intersection/difference.
    transforms : random transforms on every node (else identities).
    scale : range of the isotropic scale of each transform.
    operators : subset of ("union", "intersection", "difference").
    """
    kinds = BOUNDED_KINDS if kinds is None else _check_kinds(kinds)
    max_leaves = check_int(max_leaves, "max_leaves", 1, 64)
    if max_depth is not None:
        max_depth = check_int(max_depth, "max_depth", 0, 63)
    check_range(scale, "scale")
    operators = tuple(operators)
    bad = [o for o in operators if o not in OPERATORS]
    if not operators or bad:
        raise ValueError(f"operators must be a non-empty subset of {list(OPERATORS)}, got "
                         f"{list(operators)}")
    tr = _transform_strategy(scale=scale) if transforms else st.just(IDENTITY)
    if certified_only:
        ball_kinds = tuple(k for k in kinds if LEAVES_BY_NAME[k].exact)
        lip_kinds = tuple(k for k in kinds if LEAVES_BY_NAME[k].lipschitz)
        if not ball_kinds:
            raise ValueError(f"certified_only=True but none of kinds {list(kinds)} is exact; "
                             f"exact kinds are {list(EXACT_KINDS)}")
        certified = _tree_nodes(_leaf_calls(ball_kinds, False, transforms, scale), max_leaves,
                                operators, tr, max_depth,
                                right=_tree_nodes(_leaf_calls(lip_kinds, False, transforms,
                                                              scale), max_leaves, operators,
                                                  tr, max_depth))
        return certified.map(TreeRecipe)
    base = _leaf_calls(kinds, False, transforms, scale)
    return _tree_nodes(base, max_leaves, operators, tr, max_depth).map(TreeRecipe)


def _tree_nodes(base, max_leaves, operators, tr, max_depth, right=None):
    """Nested LeafCall/OpCall nodes. With ``right`` (a strategy of Lipschitz subtrees),
    intersections/differences take their right operand from it, unions from ``children``."""
    if max_leaves == 1:
        return base

    def extend(children):
        rhs = children if right is None else right
        opts = []
        for op in operators:
            r = children if op == "union" else rhs
            opts.append(st.builds(OpCall, st.just(op), children, r, tr))
        return st.one_of(opts)

    nodes = st.recursive(base, extend, max_leaves=max_leaves)
    if max_depth is not None:
        nodes = nodes.map(lambda n: _cut(n, max_depth))
    return nodes


def _cut(node, depth):
    """Replace subtrees deeper than ``depth`` by their leftmost leaf (keeps validity)."""
    if isinstance(node, LeafCall):
        return node
    if depth == 0:
        while not isinstance(node, LeafCall):
            node = node.left
        return node
    return OpCall(node.op, _cut(node.left, depth - 1), _cut(node.right, depth - 1),
                  node.transform)


def same_solid_pairs(**tree_kwargs) -> st.SearchStrategy:
    """Pairs (recipe, other) of different recipes describing the same solid (same sign of
    phi everywhere off the surface):

    - a tree and the tree reframed by T then by T^-1 (``add_reframed`` twice);
    - ``difference(a, half_space(n, o))`` and ``intersection(a, half_space(-n, -o))``
      (cutting by a half-space is intersecting with its complement).
    ``tree_kwargs`` go to :func:`trees`.
    """
    base = trees(**tree_kwargs)
    tr = _transform_strategy(identity=False)
    reframed = st.builds(lambda r, t: (r, r.reframed(t).reframed(t.inverse())), base, tr)

    def cut(r, hs):
        plane = LeafCall("half_space", hs)
        flipped = LeafCall("half_space", (-hs[0], -hs[1], -hs[2], -hs[3]))
        return (TreeRecipe(OpCall("difference", r.root, plane)),
                TreeRecipe(OpCall("intersection", r.root, flipped)))
    cuts = st.builds(cut, base, leaf_params("half_space"))
    return st.one_of(reframed, cuts)


# ---------------------------------------------------------------------------- points
def _ball_of(source):
    if isinstance(source, TreeRecipe):
        b, root = source.build()
        c, r, _ = b.node_bound(root)
        return np.asarray(c, float), float(r)
    try:
        c, r = source
        c = np.asarray(c, dtype=np.float64).reshape(3)
        r = float(r)
    except (TypeError, ValueError):
        raise ValueError(f"expected a TreeRecipe or (centre (3,), radius), got {source!r}") \
            from None
    if not (np.all(np.isfinite(c)) and math.isfinite(r) and r >= 0):
        raise ValueError(f"ball must have a finite centre and a finite radius >= 0, got "
                         f"({c.tolist()}, {r})")
    return c, r


def points_in_box(lo, hi, n: int = 64) -> st.SearchStrategy:
    """(n, 3) float64 arrays uniform-ish in the box [lo, hi] (shrinking towards ``lo``)."""
    lo = np.asarray(lo, dtype=np.float64).reshape(3)
    hi = np.asarray(hi, dtype=np.float64).reshape(3)
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo <= hi)):
        raise ValueError(f"box must satisfy lo <= hi componentwise (finite), got {lo}, {hi}")
    n = check_int(n, "n", 1)
    unit = hnp.arrays(np.float64, (n, 3), elements=st.floats(0.0, 1.0))
    return unit.map(lambda u: lo + u * (hi - lo))


def points_outside_ball(source, n: int = 64, max_factor: float = 10.0) -> st.SearchStrategy:
    """(n, 3) points strictly outside a ball, at distances up to ``max_factor`` radii from its
    surface. ``source`` is a :class:`TreeRecipe` (its root's ball) or ``(centre, radius)``."""
    c, r = _ball_of(source)
    n = check_int(n, "n", 1)
    if not (math.isfinite(max_factor) and max_factor > 0):
        raise ValueError(f"max_factor must be finite and > 0, got {max_factor!r}")
    span = max(r, 1e-3) * max_factor

    def place(d, u):
        nrm = np.linalg.norm(d, axis=1)
        d = np.where(nrm[:, None] < 1e-6, np.array([1.0, 0.0, 0.0]), d)
        d = d / np.linalg.norm(d, axis=1)[:, None]
        dist = r * (1 + 1e-12) + 1e-12 + u * span
        return c + d * dist[:, None]
    dirs = hnp.arrays(np.float64, (n, 3), elements=st.floats(-1.0, 1.0))
    dist = hnp.arrays(np.float64, (n,), elements=st.floats(0.0, 1.0))
    return st.builds(place, dirs, dist)


def surface_points(builder, root, raw, iterations: int = 8):
    """Project the (N, 3) points ``raw`` towards the zero set of ``root`` with Newton steps
    ``p <- p - phi grad / |grad|^2`` (exact for exact distances, a few steps otherwise)."""
    p = np.array(raw, dtype=np.float64)
    for _ in range(iterations):
        phi, g = builder.eval_root_grad(root, p)
        g2 = np.maximum(np.einsum("ij,ij->i", g, g), 1e-12)
        p = p - (phi / g2)[:, None] * g
    return p


def points_near_surface(recipe: TreeRecipe, n: int = 64, band: float = 0.05) -> st.SearchStrategy:
    """(n, 3) points within about ``band`` of the surface of ``recipe``'s solid.

    Raw points in the root ball are projected onto the zero set (:func:`surface_points`) and
    offset along the normal by a drawn amount in [-band, band].
    """
    if not isinstance(recipe, TreeRecipe):
        raise ValueError(f"recipe must be a TreeRecipe, got {type(recipe).__name__}")
    n = check_int(n, "n", 1)
    if not (math.isfinite(band) and band >= 0):
        raise ValueError(f"band must be finite and >= 0, got {band!r}")
    b, root = recipe.build()
    c, r, _ = b.node_bound(root)
    if not math.isfinite(r):
        raise ValueError("points_near_surface needs a bounded root (no half-space on the left)")

    def place(u, off):
        p = surface_points(b, root, c + (2 * u - 1) * r)
        _, g = b.eval_root_grad(root, p)
        g = g / np.maximum(np.linalg.norm(g, axis=1), 1e-12)[:, None]
        return p + (off * band)[:, None] * g
    return st.builds(place, hnp.arrays(np.float64, (n, 3), elements=st.floats(0.0, 1.0)),
                     hnp.arrays(np.float64, (n,), elements=st.floats(-1.0, 1.0)))


st.register_type_strategy(TreeRecipe, trees())
