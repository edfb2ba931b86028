"""Equation 1's one home (peclet.core.geom.certificate): slack, violations and the page check."""
import math

import numpy as np
import pytest

from peclet.core import geom
from peclet.core.geom.certificate import (check_equation1, equation1_slack,
                                          equation1_violations, exterior_points)
from peclet.core.validation import PecletArgumentError


def test_a_sphere_meets_the_bound_with_equality():
    # phi = |p - c| - r exactly, so the slack is rounding only
    b = geom.SceneBuilder()
    s = b.add_leaf("sphere", [0.7], translation=[0.1, -0.2, 0.3])
    out = check_equation1(b, s, n=20_000, seed=3)
    assert out["certified"] and out["violating"] == 0.0 and out["worst_ratio"] == 1.0
    assert abs(out["min_slack"]) < 1e-14
    assert out["ball_centre"] == [0.1, -0.2, 0.3] and out["ball_radius"] == 0.7


def test_an_underestimating_leaf_violates_and_is_not_claimed():
    # hollow_cylinder_shell is sign-exact only: far off its axis it under-reports the distance
    b = geom.SceneBuilder()
    s = b.add_leaf("hollow_cylinder_shell", [0.5, 0.3, 1.0])
    out = check_equation1(b, s, n=20_000, seed=3)
    assert not out["certified"]
    assert out["violating"] > 0.0 and out["min_slack"] < 0.0 and out["worst_ratio"] < 1.0


def test_exterior_points_lie_at_their_nominal_distance():
    p, d = exterior_points(np.array([1.0, 2.0, 3.0]), 0.5, 1000, 0, 1.4)
    assert np.all((d >= 0.5) & (d < 0.5 * 2.4))
    assert np.allclose(np.linalg.norm(p - [1, 2, 3], axis=1), d, rtol=1e-14, atol=0)


def test_violations_count_nan_and_respect_the_rounding_tolerance():
    slack = equation1_slack([1.0, 0.0, np.nan, -1e-13], [2.0, 1.0, 1.0, 1.0], 1.0)
    assert slack[:2].tolist() == [0.0, 0.0]
    assert equation1_violations(slack, 1.0, tol=1e-12).tolist() == [False, False, True, False]
    assert equation1_violations(slack, 1.0, tol=1e-14).tolist() == [False, False, True, True]


def test_random_certified_trees_keep_their_promise():
    import test_geom_tree as T   # the shared random-tree builder
    g = np.random.default_rng(2)
    exact = [k for k in geom.LEAF_NAMES if geom.LEAVES_BY_NAME[k].exact and k != "half_space"]
    for trial in range(40):
        b = geom.SceneBuilder()
        root = T.random_tree(b, g, g.integers(1, 7), kinds=exact)
        out = check_equation1(b, root, n=5_000, seed=trial, extent=1.5)
        assert out["certified"] and out["violating"] == 0.0, (trial, out)


@pytest.mark.parametrize("kw, name", [
    (dict(n=0), "n"), (dict(n=2.5), "n"), (dict(seed=-1), "seed"), (dict(extent=0.0), "extent"),
    (dict(tol=math.nan), "tol"), (dict(root=5), "root"),
])
def test_bad_arguments(kw, name):
    b = geom.SceneBuilder()
    root = b.add_leaf("sphere", [1.0])
    args = dict(root=root)
    args.update(kw)
    with pytest.raises(PecletArgumentError, match=rf"^{name} must"):
        check_equation1(b, **args)


def test_an_unbounded_ball_is_refused():
    b = geom.SceneBuilder()
    h = b.add_intersection(b.add_leaf("half_space", [0, 1, 0, 0.0]), b.add_leaf("sphere", [1.0]))
    with pytest.raises(PecletArgumentError, match="^root must be a node with a finite"):
        check_equation1(b, h, n=10)
