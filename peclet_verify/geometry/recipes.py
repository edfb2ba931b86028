"""Tree recipes: a CSG tree as the record of the public ``SceneBuilder`` calls that build it
(:class:`TreeRecipe` of :class:`LeafCall` / :class:`OpCall` nodes, each with a
:class:`Transform`), the leaf kinds by property, and the walk of a recipe's nodes.

A recipe is valid by construction, shrinks towards a single leaf with an identity transform,
and ``repr(recipe)`` / ``recipe.snippet()`` is a runnable Python snippet that rebuilds it.
Conventions follow docs/architecture.md §2. The strategies that draw recipes are in
:mod:`peclet_verify.geometry.strategies`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from peclet.core.geom import LEAF_NAMES, LEAVES_BY_NAME, SceneBuilder
from peclet.core.geom.transforms import quat_to_matrix

__all__ = ["Transform", "LeafCall", "OpCall", "TreeRecipe", "IDENTITY", "BOUNDED_KINDS",
           "EXACT_KINDS", "LIPSCHITZ_KINDS", "OPERATORS"]

#: Leaves with a finite enclosing ball (everything but the half-space).
BOUNDED_KINDS = tuple(k for k in LEAF_NAMES if k != "half_space")
#: Leaves whose value is the exact signed distance (their ball is certified).
EXACT_KINDS = tuple(k for k in BOUNDED_KINDS if LEAVES_BY_NAME[k].exact)
#: Leaves that are 1-Lipschitz (may sit on the right of a certified intersection/difference).
LIPSCHITZ_KINDS = tuple(k for k in BOUNDED_KINDS if LEAVES_BY_NAME[k].lipschitz)
OPERATORS = ("union", "intersection", "difference")


# ---------------------------------------------------------------------------- recipe records
@dataclass(frozen=True)
class Transform:
    """A conformal transform: translation (3,), unit quaternion (x, y, z, w), scale > 0."""

    translation: tuple = (0.0, 0.0, 0.0)
    rotation: tuple = (0.0, 0.0, 0.0, 1.0)
    scale: float = 1.0

    def kwargs_source(self) -> str:
        parts = []
        if any(v != 0.0 for v in self.translation):
            parts.append(f"translation={list(self.translation)!r}")
        if tuple(self.rotation) != (0.0, 0.0, 0.0, 1.0):
            parts.append(f"rotation={list(self.rotation)!r}")
        if self.scale != 1.0:
            parts.append(f"scale={self.scale!r}")
        return "".join(", " + p for p in parts)

    def kwargs(self) -> dict:
        return dict(translation=list(self.translation), rotation=list(self.rotation),
                    scale=self.scale)

    def inverse(self) -> "Transform":
        """The transform T^-1 with T^-1(T(p)) = p."""
        x, y, z, w = self.rotation
        qi = (-x, -y, -z, w)
        R = quat_to_matrix(np.array(qi, dtype=np.float64))
        t = -(R @ np.asarray(self.translation)) / self.scale
        return Transform(tuple(float(v) for v in t), tuple(float(v) for v in qi),
                         1.0 / self.scale)


IDENTITY = Transform()


@dataclass(frozen=True)
class LeafCall:
    """``add_leaf(kind, params, **transform)``."""

    kind: str
    params: tuple
    transform: Transform = IDENTITY


@dataclass(frozen=True)
class OpCall:
    """``add_union / add_intersection / add_difference(left, right, **transform)``."""

    op: str
    left: object
    right: object
    transform: Transform = IDENTITY


@dataclass(frozen=True)
class TreeRecipe:
    """A CSG tree as the list of public ``SceneBuilder`` calls that build it.

    ``root`` is a nested :class:`LeafCall` / :class:`OpCall`; ``reframe`` optional transforms
    applied with ``add_reframed`` to the finished root, innermost first.
    """

    root: object
    reframes: tuple = field(default=())

    # -- structure
    @property
    def num_leaves(self) -> int:
        return sum(1 for n in _postorder(self.root) if isinstance(n, LeafCall))

    @property
    def depth(self) -> int:
        return _depth(self.root)

    @property
    def num_nodes(self) -> int:
        return sum(1 for _ in _postorder(self.root)) + len(self.reframes)

    @property
    def kinds(self) -> tuple:
        return tuple(n.kind for n in _postorder(self.root) if isinstance(n, LeafCall))

    def reframed(self, transform: Transform) -> "TreeRecipe":
        """The same tree moved by ``transform`` through ``add_reframed`` (exact, no resample)."""
        return TreeRecipe(self.root, self.reframes + (transform,))

    # -- building
    def calls(self):
        """[(variable, method, args source, kwargs source)] in build order."""
        out = []
        names = {}
        for node in _postorder(self.root):
            var = f"n{len(out)}"
            if isinstance(node, LeafCall):
                args = f"{node.kind!r}, {list(node.params)!r}"
                out.append((var, "add_leaf", args, node.transform.kwargs_source()))
            else:
                args = f"{names[id(node.left)]}, {names[id(node.right)]}"
                out.append((var, "add_" + node.op, args, node.transform.kwargs_source()))
            names[id(node)] = var
        for tr in self.reframes:
            out.append((f"n{len(out)}", "add_reframed", out[-1][0], tr.kwargs_source()))
        return out

    def build(self, builder: Optional[SceneBuilder] = None):
        """Replay the calls on ``builder`` (a new one by default); returns (builder, root)."""
        b = SceneBuilder() if builder is None else builder
        idx = {}
        last = None
        for node in _postorder(self.root):
            kw = node.transform.kwargs()
            if isinstance(node, LeafCall):
                last = b.add_leaf(node.kind, list(node.params), **kw)
            else:
                last = getattr(b, "add_" + node.op)(idx[id(node.left)], idx[id(node.right)], **kw)
            idx[id(node)] = last
        for tr in self.reframes:
            last = b.add_reframed(last, **tr.kwargs())
        return b, last

    def snippet(self) -> str:
        """Runnable Python that rebuilds this tree as ``b`` with its root in ``root``."""
        lines = ["from peclet.core.geom import SceneBuilder", "b = SceneBuilder()"]
        calls = self.calls()
        for var, method, args, kwargs in calls:
            lines.append(f"{var} = b.{method}({args}{kwargs})")
        lines.append(f"root = {calls[-1][0]}")
        return "\n".join(lines)

    def __repr__(self) -> str:
        return self.snippet()


def _postorder(node):
    """Children before parents, left before right; shared subtrees appear once per use."""
    stack = [(node, False)]
    while stack:
        n, expanded = stack.pop()
        if isinstance(n, LeafCall) or expanded:
            yield n
        else:
            stack.append((n, True))
            stack.append((n.right, False))
            stack.append((n.left, False))


def _depth(node) -> int:
    if isinstance(node, LeafCall):
        return 0
    return 1 + max(_depth(node.left), _depth(node.right))
