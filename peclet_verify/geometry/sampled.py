"""Grid leaves drawn from random CSG trees, and what a grid leaf must keep of its source.

A :class:`SampledTree` is a random tree (a :class:`~.recipes.TreeRecipe`) sampled onto a grid
leaf of ``cells`` cells across its ball (:func:`peclet.core.geom.grids.grid_from_callable` over
the ball's box plus its margin), so every grid drawn has an exact source to be judged against
and shrinks with it. The properties (docs/architecture.md §3, §4):

- :func:`sign_violations`: the grid's sign is the source's at every point farther than one
  cell diagonal sqrt(3) h from the source's surface. For a 1-Lipschitz source this is a
  theorem, not a tolerance: a trilinear value is a convex combination of corner values each
  within sqrt(3) h of the source's value at the point, and outside the lattice both are > 0.
- :func:`equation1_report`: Equation 1 holds on exterior points for the ball the builder
  measured from the samples (no tolerance beyond the certificate's rounding).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from hypothesis import strategies as st

from peclet.core.geom import check_equation1
from peclet.core.geom.grids import grid_from_callable
from peclet.core.validation import PecletArgumentError

from .. import registry as REG
from ..checks import check_range
from ..search import NOT_APPLICABLE, PropertyResult, make_result
from .recipes import LIPSCHITZ_KINDS, TreeRecipe
from .strategies import trees

__all__ = ["SampledTree", "sampled_trees", "sign_violations", "equation1_report", "grid_sign",
           "grid_equation1"]


@dataclass(frozen=True)
class SampledTree:
    """A source tree and the resolution of its grid: ``cells`` across the source's ball."""

    source: TreeRecipe
    cells: int

    def build(self):
        """(builder, source root, grid root or None, spacing h): None when the source has no
        solid the grid resolves (every sample > 0), which a property skips."""
        b, src = self.source.build()
        c, r, _ = b.node_bound(src)
        c = np.asarray(c, float)
        h = 2.0 * r / self.cells
        try:
            g = grid_from_callable(b, lambda p: b.eval_root(src, p), c - r, c + r, h)
        except PecletArgumentError as e:
            if "< 0" in str(e):
                return b, src, None, h
            raise
        return b, src, g, h

    def snippet(self) -> str:
        """Runnable Python that rebuilds the source as ``b``/``root`` and its grid as ``g``."""
        return (self.source.snippet() + "\nimport numpy as np\n"
                "from peclet.core.geom.grids import grid_from_callable\n"
                "c, r, _ = b.node_bound(root)\n"
                f"g = grid_from_callable(b, lambda p: b.eval_root(root, p), c - r, c + r, "
                f"2 * r / {self.cells})")


def sampled_trees(cells=(6, 24), **tree_kwargs) -> st.SearchStrategy:
    """:class:`SampledTree` of random trees (:func:`.strategies.trees` with ``tree_kwargs``;
    default 1-Lipschitz leaves, at most 4) at ``cells`` (an int range) across their ball."""
    lo, hi = check_range(cells, "cells")
    tree_kwargs.setdefault("kinds", LIPSCHITZ_KINDS)
    tree_kwargs.setdefault("max_leaves", 4)
    return st.builds(SampledTree, trees(**tree_kwargs), st.integers(int(lo), int(hi)))


def sign_violations(sample: SampledTree, n=4000, seed=0):
    """(points where the grid's sign differs from the source's at |phi_source| > sqrt(3) h,
    number of points judged). Points: uniform in the source ball's box enlarged by a quarter."""
    b, src, g, h = sample.build()
    if g is None:
        return np.zeros((0, 3)), 0
    c, r, _ = b.node_bound(src)
    p = np.random.default_rng(seed).uniform(np.asarray(c) - 1.25 * r, np.asarray(c) + 1.25 * r,
                                            (n, 3))
    f = b.eval_root(src, p)
    F = b.eval_root(g, p)
    far = np.abs(f) > math.sqrt(3.0) * h
    bad = far & ((f < 0.0) != (F < 0.0))
    return p[bad], int(far.sum())


def equation1_report(sample: SampledTree, n=20_000, seed=3):
    """:func:`peclet.core.geom.check_equation1` of the grid leaf's measured ball, or None when
    the source has no solid on the grid."""
    b, _, g, _ = sample.build()
    return None if g is None else check_equation1(b, g, n=n, seed=seed, extent=2.0)


def grid_sign(sample: SampledTree) -> PropertyResult:
    """Certificate: :func:`sign_violations` finds none. Figure: the rate of points farther than
    a cell diagonal from the source's surface where the grid's sign is not the source's."""
    name, fig = "grid_sign", REG.figure("grid_sign")
    bad, judged = sign_violations(sample)
    if judged == 0:
        return PropertyResult(name, True, 1, float("nan"), fig, "", NOT_APPLICABLE, "max")
    text = (f"{len(bad)}/{judged} points beyond a cell diagonal of the source's surface have "
            f"the other sign on the grid, e.g. {bad[:1].tolist()}")
    return make_result(name, len(bad) == 0, len(bad) / judged, fig, "max", text)


def grid_equation1(sample: SampledTree) -> PropertyResult:
    """Certificate: Equation 1 holds for the grid leaf's measured ball (:func:`equation1_report`).
    Figure: the minimum slack."""
    name, fig = "grid_equation1", REG.figure("grid_equation1")
    rep = equation1_report(sample)
    if rep is None:
        return PropertyResult(name, True, 1, float("nan"), fig, "", NOT_APPLICABLE, "min")
    text = (f"{rep['violating']:.3g} of the exterior points violate Equation 1 for the grid's "
            f"measured ball (min slack {rep['min_slack']:.3e})")
    return make_result(name, rep["violating"] == 0.0, rep["min_slack"], fig, "min", text)
