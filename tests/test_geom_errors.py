"""Bad input: a ValueError naming the argument and what is accepted, never a silent sentinel."""
import numpy as np
import pytest

from peclet.core import geom
from peclet.core.geom import kernels


@pytest.fixture
def b():
    return geom.SceneBuilder()


@pytest.mark.parametrize("kind, params, match", [
    ("blob", [1.0], "kind must be one of"),
    (99, [1.0], "kind must be one of"),
    (True, [1.0], "kind must be one of"),
    ("sphere", [1.0, 2.0], "sphere: params must have 1 values"),
    ("box", [1.0, 1.0], r"box: params must have 3 values \(hx, hy, hz\)"),
    ("sphere", [0.0], "'radius' must be > 0"),
    ("sphere", [-1.0], "'radius' must be > 0"),
    ("box", [1.0, -1.0, 1.0], "'hy' must be > 0"),
    ("sphere", [np.nan], "params must be finite"),
    ("hollow_cylinder", [0.5, 1.0, 0.6], r"'thickness' must be in \(0, rOuter\)"),
    ("hollow_cylinder", [0.5, 1.0, 0.5], r"'thickness' must be in \(0, rOuter\)"),
    ("hollow_cylinder_shell", [0.5, 0.6, 1.0], r"'rInner' must be in \[0, rOuter\)"),
    ("torus", [0.3, 0.4], r"'r' must be in \(0, R\)"),
    ("cone", [0.0, 0.0, 1.0], "at least one of"),
    ("cone", [0.3, 0.2, 0.0], "'halfHeight' must be > 0"),
    ("superquadric", [1, 1, 1, 3.0], r"'e' must be in \[0.1, 1.0\]"),
    ("half_space", [0, 0, 0, 1.0], "normal .* must be non-zero"),
    ("capsule", [0.2, -0.1], "'halfLength' must be >= 0"),
])
def test_bad_leaf_parameters(b, kind, params, match):
    with pytest.raises(ValueError, match=match):
        b.add_leaf(kind, params)
    assert b.num_nodes() == 0          # nothing half-added


@pytest.mark.parametrize("kw, match", [
    (dict(rotation=[0, 0, 0, 0]), "non-zero quaternion"),
    (dict(rotation=[0, 0, 1]), "quaternion of 4 finite"),
    (dict(rotation=[0, np.inf, 0, 1]), "quaternion of 4 finite"),
    (dict(translation=[0, 1]), "translation must be 3 finite"),
    (dict(translation=[0, np.nan, 1]), "translation must be 3 finite"),
    (dict(scale=0.0), "scale must be a finite number > 0"),
    (dict(scale=-2.0), "scale must be a finite number > 0"),
    (dict(scale=np.inf), "scale must be a finite number > 0"),
])
def test_bad_transforms(b, kw, match):
    with pytest.raises(ValueError, match=match):
        b.add_leaf("sphere", [1.0], **kw)


def test_non_unit_quaternion_is_normalised(b):
    r = b.add_leaf("box", [1, 2, 3], rotation=[0, 0, 2, 2])
    q = b.node(r)[5]
    assert np.allclose(q, [0, 0, np.sqrt(0.5), np.sqrt(0.5)], rtol=0, atol=4e-16)


@pytest.mark.parametrize("a, c, match", [
    (0, 5, r"b must be an existing node index in \[0, 2\), got 5"),
    (-1, 0, r"a must be an existing node index in \[0, 2\), got -1"),
    (2, 0, r"a must be an existing node index in \[0, 2\), got 2"),
    (0.0, 1, "a must be a node index"),
])
def test_bad_child_indices(b, a, c, match):
    b.add_leaf("sphere", [1.0])
    b.add_leaf("sphere", [2.0])
    with pytest.raises(ValueError, match=match):
        b.add_union(a, c)


def test_tree_deeper_than_the_stack(b):
    # a right-deep chain needs one stack slot per level; a left-deep one needs two
    node = b.add_leaf("sphere", [1.0])
    for k in range(kernels.MAX_STACK - 1):
        node = b.add_union(b.add_leaf("sphere", [1.0]), node)
    with pytest.raises(ValueError, match="tree too deep.*needs 65 stack slots"):
        b.add_union(b.add_leaf("sphere", [1.0]), node)
    left = b.add_leaf("sphere", [1.0])
    for k in range(500):
        left = b.add_union(left, b.add_leaf("sphere", [1.0 + k]))
    assert b.eval_root(left, [[0.0, 0.0, 0.0]])[0] == -500.0


@pytest.mark.parametrize("points, match", [
    (np.zeros((4, 2)), r"points must have shape \(N, 3\)"),
    (np.zeros(3), r"points must have shape \(N, 3\)"),
    (np.array([[0, 0, 0], [0, np.nan, 0]]), "points must be finite; row 1"),
    (np.array([[np.inf, 0, 0]]), "points must be finite; row 0"),
])
def test_bad_points(b, points, match):
    r = b.add_leaf("sphere", [1.0])
    with pytest.raises(ValueError, match=match):
        b.eval_root(r, points)
    with pytest.raises(ValueError, match=match):
        b.eval_root_grad(r, points)


def test_bad_bake_arguments(b):
    r = b.add_leaf("sphere", [1.0])
    with pytest.raises(ValueError, match="spacing must be 3 finite numbers > 0"):
        b.bake(r, [0, 0, 0], [0.1, 0, 0.1], [2, 2, 2])
    with pytest.raises(ValueError, match="dims must be 3 integers >= 1"):
        b.bake(r, [0, 0, 0], [0.1] * 3, [2, 0, 2])
    with pytest.raises(ValueError, match="origin must be 3 finite"):
        b.bake(r, [0, np.nan, 0], [0.1] * 3, [2, 2, 2])


def test_bad_flat_arrays():
    b = geom.SceneBuilder()
    b.add_union(b.add_leaf("sphere", [1.0]), b.add_leaf("box", [1, 1, 1]))
    ni, nr, _, _ = b.encode()
    bad = ni.copy()
    bad[2, 2] = 7
    with pytest.raises(ValueError, match=r"node 2: right child must be in \[0, 2\), got 7"):
        geom.decode(bad, nr)
    bad = ni.copy()
    bad[0, 0] = 17
    with pytest.raises(ValueError, match="kind must be one of"):
        geom.decode(bad, nr)
    bad = nr.copy()
    bad[0, 0] = -1.0
    with pytest.raises(ValueError, match="'radius' must be > 0"):
        geom.decode(ni, bad)
    bad = ni.copy()
    bad[0, 1] = 1
    with pytest.raises(ValueError, match="a leaf .* must have children -1"):
        geom.decode(bad, nr)
    with pytest.raises(ValueError, match=r"node_reals must have shape \(3, 16\)"):
        geom.decode(ni, nr[:, :15])
    assert np.array_equal(geom.decode(ni, nr).encode()[0], ni)


def test_scene_errors(b):
    with pytest.raises(ValueError, match="no instances"):
        b.eval_scene(np.zeros((1, 3)))
    r = b.add_leaf("sphere", [1.0])
    b.add_instance(r, translation=[9.0, 0, 0])
    with pytest.raises(ValueError, match="periodic axes need box"):
        b.eval_scene(np.zeros((1, 3)), periodic=(True, False, False))
    with pytest.raises(ValueError, match=r"translation\[0\]=9.0 must lie in the periodic box"):
        b.eval_scene(np.zeros((1, 3)), box=([0, 0, 0], [5, 5, 5]), periodic=(True, False, False))
    with pytest.raises(ValueError, match="method must be"):
        b.eval_scene(np.zeros((1, 3)), method="fast")


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
