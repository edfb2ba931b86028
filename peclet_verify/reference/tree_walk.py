"""The tree walk: phi of a flat encoding evaluated node by node, straight from its definition.

docs/architecture.md §2 defines a node's value in its parent frame as
``s * f(R(q)^T (p - t) / s)`` with
``f`` the leaf formula or the operator of the children's values (union = min, intersection =
max, difference(a, b) = max(a, -b)). This module applies that definition recursively, in numpy,
one node at a time; the engine instead composes every leaf's transform down to the root once
(:mod:`peclet.core.geom.program`). Agreement of the two (to rounding: the transforms are
applied in a different order) certifies the engine's program lowering. Leaf formulas are the
engine's own (one home: :mod:`peclet.core.geom.kernels`), evaluated on each leaf alone; a
caller may substitute its own ``leaf`` function, e.g. to plant a bug.
"""
from __future__ import annotations

import numpy as np

from peclet.core.geom.encoding import KIND, LEFT, RIGHT, node_transform
from peclet.core.geom.leaves import DIFFERENCE, INTERSECTION, UNION, leaf_spec
from peclet.core.geom.transforms import quat_to_matrix

__all__ = ["evaluate", "engine_leaf"]


def engine_leaf(kind, params, points):
    """phi (N,) of the leaf ``kind`` with ``params`` at ``points`` (N, 3) of its own frame,
    by the engine's kernel for that leaf alone."""
    from peclet.core.geom import SceneBuilder
    spec = leaf_spec(int(kind))
    b = SceneBuilder()
    return b.eval_root(b.add_leaf(spec.kind, params[:spec.n_params]), points)


def evaluate(node_ints, node_reals, root, points, leaf=engine_leaf):
    """phi (N,) of ``root`` of the flat encoding at ``points`` (N, 3) in the root's parent frame.

    ``node_ints`` (n, 3) rows (kind, left, right); ``node_reals`` (n, 16) rows (params[8], t,
    q as x, y, z, w, s); phi < 0 inside. ``leaf(kind, params (8,), local_points)`` gives a
    leaf's value in its own frame (default :func:`engine_leaf`). Recursion depth is the tree's
    depth (the engine refuses trees deeper than its 64-slot stack long before Python's limit).
    """
    ni = np.asarray(node_ints)
    nr = np.asarray(node_reals, dtype=np.float64)
    return _node(ni, nr, int(root), np.asarray(points, dtype=np.float64), leaf)


def _node(ni, nr, i, p, leaf):
    kind, left, right = int(ni[i, KIND]), int(ni[i, LEFT]), int(ni[i, RIGHT])
    t, q, s = node_transform(nr[i])
    # row vectors: (p - t) R is R^T (p - t) for each point
    local = (p - t) @ quat_to_matrix(q) / s
    if left < 0:
        phi = leaf(kind, nr[i], local)
    else:
        a = _node(ni, nr, left, local, leaf)
        c = _node(ni, nr, right, local, leaf)
        if kind == UNION:
            phi = np.minimum(a, c)
        elif kind == INTERSECTION:
            phi = np.maximum(a, c)
        elif kind == DIFFERENCE:
            phi = np.maximum(a, -c)
        else:
            raise ValueError(f"node {i}: operator kind must be one of {UNION}, {INTERSECTION}, "
                             f"{DIFFERENCE}, got {kind}")
    return s * phi
