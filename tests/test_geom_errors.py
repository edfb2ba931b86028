"""Edge inputs the geometry core accepts (and what it makes of them), and the errors that are not
about one argument. The one-argument errors are in tests/test_bad_input_geom.py."""
import numpy as np
import pytest

from peclet.core import geom
from peclet.core.geom import kernels
from peclet.core.validation import PecletArgumentError


@pytest.fixture
def b():
    return geom.SceneBuilder()


def test_non_unit_quaternion_is_normalised(b):
    r = b.add_leaf("box", [1, 2, 3], rotation=[0, 0, 2, 2])
    q = b.node(r)[5]
    assert np.allclose(q, [0, 0, np.sqrt(0.5), np.sqrt(0.5)], rtol=0, atol=4e-16)


@pytest.mark.parametrize("magnitude", [1e200, 1e-200, 1e-310])
def test_huge_and_tiny_quaternions_are_the_rotation_they_point_at(b, magnitude):
    # [m] * 4 for any finite m > 0 is the 120-degree turn about (1, 1, 1), q = [0.5] * 4; its
    # square overflows (1e200) or underflows (1e-200, subnormal 1e-310) in a naive norm
    ref = b.add_leaf("box", [0.1, 0.2, 0.3], rotation=[0.5] * 4)
    r = b.add_leaf("box", [0.1, 0.2, 0.3], rotation=[magnitude] * 4)
    assert np.array_equal(b.node(r)[5], [0.5] * 4)
    p = np.random.default_rng(0).uniform(-0.4, 0.4, (1000, 3))
    assert np.array_equal(b.eval_root(r, p), b.eval_root(ref, p))
    # and it is that rotation (x -> y -> z -> x): the half-extents (0.1, 0.2, 0.3) now lie
    # along (y, z, x), so (0.25, 0, 0) is inside and (0, 0.15, 0) outside, unlike the unturned box
    assert b.eval_root(r, [[0.25, 0.0, 0.0]])[0] < 0.0 < b.eval_root(r, [[0.0, 0.15, 0.0]])[0]


def test_integer_and_float32_arguments_are_accepted_as_float64(b):
    a = b.add_leaf("sphere", [1], translation=np.array([1, 2, 3], np.int32), scale=2)
    c = b.add_leaf("sphere", [1.0], translation=np.array([1, 2, 3], np.float32), scale=2.0)
    p = [[0.5, 0.25, 0.125]]
    assert b.eval_root(a, p)[0] == b.eval_root(c, p)[0]


def test_tree_deeper_than_the_stack(b):
    # a right-deep chain needs one stack slot per level; a left-deep one needs two
    node = b.add_leaf("sphere", [1.0])
    for k in range(kernels.MAX_STACK - 1):
        node = b.add_union(b.add_leaf("sphere", [1.0]), node)
    n = b.num_nodes()
    with pytest.raises(PecletArgumentError, match="^b must .*tree too deep.*needs 65 stack slots"):
        b.add_union(b.add_leaf("sphere", [1.0]), node)
    assert b.num_nodes() == n + 1      # the leaf, not the union
    left = b.add_leaf("sphere", [1.0])
    for k in range(500):
        left = b.add_union(left, b.add_leaf("sphere", [1.0 + k]))
    assert b.eval_root(left, [[0.0, 0.0, 0.0]])[0] == -500.0


def test_empty_points_give_an_empty_answer(b):
    r = b.add_leaf("sphere", [1.0])
    assert b.eval_root(r, np.zeros((0, 3))).shape == (0,)


def test_a_failed_decode_leaves_the_arrays_usable():
    b = geom.SceneBuilder()
    b.add_union(b.add_leaf("sphere", [1.0]), b.add_leaf("box", [1, 1, 1]))
    ni, nr, _, _ = b.encode()
    bad = ni.copy()
    bad[2, 2] = 7
    with pytest.raises(ValueError):
        geom.decode(bad, nr)
    assert np.array_equal(geom.decode(ni, nr).encode()[0], ni)


def test_a_scene_without_instances_is_an_error(b):
    with pytest.raises(ValueError, match="no instances"):
        b.eval_scene(np.zeros((1, 3)))


def test_unknown_kind_in_a_corrupted_program_is_nan_not_a_sentinel():
    b = geom.SceneBuilder()
    r = b.add_leaf("sphere", [1.0])
    prog = b.program(r)
    kinds = prog.leaf_kind.copy()
    kinds[0] = 31
    phi = np.empty(1)
    kernels.eval_points(prog.ops, kinds, prog.leaf_reals, prog.op_begin, prog.op_end,
                        np.zeros((1, 3)), phi, np.empty((0, 3)), False)
    assert np.isnan(phi[0])
