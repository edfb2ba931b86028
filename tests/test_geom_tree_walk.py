"""The engine's lowered programs against the node-by-node tree walk (peclet_verify.reference)."""
import numpy as np

from peclet.core import geom
from peclet_verify.reference import tree_walk


def test_engine_equals_the_tree_walk_on_random_trees():
    import test_geom_tree as T   # the shared random-tree builder (every kind, every operator)
    g = np.random.default_rng(7)
    p = g.uniform(-1, 1, (2000, 3))
    worst = 0.0
    for trial in range(25):
        b = geom.SceneBuilder()
        root = T.random_tree(b, g, g.integers(1, 8))
        ni, nr, _, _ = b.encode()
        ref = tree_walk.evaluate(ni, nr, root, p)
        got = b.eval_root(root, p)
        # same formulas, transforms composed in another order: rounding-level differences
        worst = max(worst, float(np.max(np.abs(got - ref) / (1.0 + np.abs(ref)))))
    assert worst < 1e-12


def test_a_single_untransformed_leaf_is_bitwise_the_engine():
    b = geom.SceneBuilder()
    r = b.add_leaf("torus", [0.4, 0.1])
    p = np.random.default_rng(1).uniform(-0.6, 0.6, (500, 3))
    ni, nr, _, _ = b.encode()
    assert np.array_equal(tree_walk.evaluate(ni, nr, r, p), b.eval_root(r, p))


def test_a_planted_leaf_shows_where_it_matters():
    # a leaf function that flips the sphere's sign: the walk follows it through the operators
    b = geom.SceneBuilder()
    box = b.add_leaf("box", [0.5, 0.5, 0.5])
    hole = b.add_leaf("sphere", [0.2], translation=[0.3, 0, 0])
    root = b.add_difference(box, hole)
    ni, nr, _, _ = b.encode()

    def flipped(kind, params, pts):
        phi = tree_walk.engine_leaf(kind, params, pts)
        return -phi if kind == 1 else phi

    centre = np.array([[0.3, 0.0, 0.0]])   # in the hole: outside the difference (phi 0.2)
    assert tree_walk.evaluate(ni, nr, root, centre)[0] > 0
    assert tree_walk.evaluate(ni, nr, root, centre, leaf=flipped)[0] < 0
