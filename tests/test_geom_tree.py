"""Trees: encoding round trip, bake, scene query, certificate rule, compilation and threads."""
import numba
import numpy as np
import pytest

import page_steps
from tiers import heavy_params
from peclet.core import geom
from peclet.core.geom import encoding, kernels, scene

LEAF_PARAMS = {
    "sphere": lambda g: [g.uniform(0.1, 0.5)],
    "hollow_cylinder": lambda g: [0.4, g.uniform(0.2, 0.8), g.uniform(0.05, 0.3)],
    "box": lambda g: list(g.uniform(0.05, 0.4, 3)),
    "hollow_cylinder_shell": lambda g: [0.4, g.uniform(0.0, 0.35), g.uniform(0.2, 0.8)],
    "capsule": lambda g: [g.uniform(0.05, 0.3), g.uniform(0.0, 0.3)],
    "torus": lambda g: [0.35, g.uniform(0.05, 0.3)],
    "cone": lambda g: [g.uniform(0.0, 0.4), g.uniform(0.05, 0.4), g.uniform(0.1, 0.4)],
    "ellipsoid": lambda g: list(g.uniform(0.1, 0.5, 3)),
    "superquadric": lambda g: list(g.uniform(0.1, 0.5, 3)) + [g.uniform(0.1, 1.0)],
    "half_space": lambda g: list(g.normal(size=3)) + [g.uniform(-0.2, 0.2)],
}


def random_tree(b, g, n_leaves, kinds=geom.LEAF_NAMES):
    """A random tree over all kinds and operators, every node with a random transform."""
    def xf():
        q = g.normal(size=4)
        return dict(translation=g.uniform(-0.3, 0.3, 3), rotation=q, scale=g.uniform(0.6, 1.5))

    nodes = []
    for _ in range(n_leaves):
        k = kinds[g.integers(len(kinds))]
        nodes.append(b.add_leaf(k, LEAF_PARAMS[k](g), **xf()))
    while len(nodes) > 1:
        i, j = sorted(g.choice(len(nodes), 2, replace=False))
        a, c = nodes.pop(j), nodes.pop(i)
        op = (b.add_union, b.add_intersection, b.add_difference)[g.integers(3)]
        nodes.append(op(c, a, **xf()))
    return nodes[0]


def test_encode_decode_eval_is_bitwise_equal():
    g = np.random.default_rng(0)
    p = g.uniform(-1, 1, (20_000, 3))
    for trial in range(30):
        b = geom.SceneBuilder()
        root = random_tree(b, g, g.integers(1, 9))
        b.add_instance(root, translation=[1, 2, 3], rotation=[0, 0, 1, 1])
        enc = b.encode()
        b2 = geom.decode(*enc)
        enc2 = b2.encode()
        for x, y in zip(enc, enc2):
            assert x.dtype == y.dtype and np.array_equal(x, y)
        assert np.array_equal(b.eval_root(root, p), b2.eval_root(root, p))
        assert np.array_equal(b.eval_root_grad(root, p)[1], b2.eval_root_grad(root, p)[1])
        assert b.node_bound(root)[1] == b2.node_bound(root)[1]


def test_encoding_layout():
    ni, nr, ii, ir = page_steps.b.encode()
    assert ni.shape == (21, 3) and ni.dtype == np.int32
    assert nr.shape == (21, 16) and nr.dtype == np.float64
    assert ni[0].tolist() == [2, -1, -1]                  # the tube, a leaf
    assert nr[0, :3].tolist() == [0.5, 1.0, 0.12]
    assert nr[0, encoding.ROTATION].tolist() == [0, 0, 0, 1]  # identity quaternion (x,y,z,w)
    assert nr[0, encoding.SCALE] == 1.0
    assert nr[0, encoding.TRANSLATION].tolist() == [0, 0, 0]
    assert ni[20, encoding.KIND] in (32, 33, 34) and ni[0, encoding.LEFT] == -1
    assert set(ni[:, 0].tolist()) == {2, 3, 32, 34}
    assert ii.shape == (0, 2) and ir.shape == (0, 8)


def test_float32_arrays_decode_like_the_page_floor():
    fb = geom.SceneBuilder()
    floor = fb.add_leaf("box", [40.0, 1.0, 40.0], translation=[1.75, -1.0, 1.75])
    fi, fr, _, _ = fb.encode()
    b2 = geom.decode(np.asarray(fi, np.int32), np.asarray(fr, np.float32))
    p = np.array([[1.0, 0.25, 1.0], [0.0, -0.5, 0.0]])
    assert np.array_equal(b2.eval_root(floor, p), [0.25, -0.5])


def test_bake_equals_eval_at_lattice_points_bitwise():
    b, ring = page_steps.b, page_steps.ring
    origin, spacing, dims = np.array([-0.62, -0.61, -0.6]), np.array([0.011, 0.013, 0.017]), (37, 29, 23)
    baked = b.bake(ring, origin, spacing, dims)
    i, j, k = np.meshgrid(*[np.arange(n) for n in dims], indexing="ij")
    pts = np.column_stack([origin[0] + i.ravel(order="F") * spacing[0],
                           origin[1] + j.ravel(order="F") * spacing[1],
                           origin[2] + k.ravel(order="F") * spacing[2]])
    assert np.array_equal(baked, b.eval_root(ring, pts))
    grid = baked.reshape(dims, order="F")
    assert grid[3, 5, 7] == b.eval_root(ring, [origin + spacing * [3, 5, 7]])[0]


def test_ties_go_left_with_their_gradient():
    b = geom.SceneBuilder()
    a = b.add_leaf("box", [1, 1, 1])
    c = b.add_leaf("box", [1, 1, 1], rotation=[0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)])
    u, i, d = b.add_union(a, c), b.add_intersection(a, c), b.add_difference(a, c)
    p = np.array([[2.0, 0.0, 0.0]])                       # both leaves give exactly 1
    ga = b.eval_root_grad(a, p)[1]
    assert np.array_equal(b.eval_root_grad(u, p)[1], ga)
    assert np.array_equal(b.eval_root_grad(i, p)[1], ga)
    v, gd = b.eval_root_grad(d, np.array([[0.0, 0.0, 0.0]]))  # max(-1, 1): right side wins
    assert v[0] == 1.0


def test_reframed_copy_is_exact():
    b, ring = page_steps.b, page_steps.ring
    bb = geom.decode(*b.encode())
    q = np.array([0.1, 0.7, -0.2, 0.6])
    q /= np.linalg.norm(q)
    t = np.array([0.3, -0.1, 0.2])
    moved = bb.add_reframed(ring, translation=t, rotation=q, scale=1.3)
    p = np.random.default_rng(1).uniform(-1.5, 1.5, (50_000, 3))
    R = geom.quat_to_matrix(q)
    expect = 1.3 * bb.eval_root(ring, (p - t) @ R / 1.3)
    assert np.max(np.abs(bb.eval_root(moved, p) - expect)) < 1e-14
    assert bb.node_bound(moved)[2]
    assert np.allclose(bb.node_bound(moved)[0], t)


def test_certificate_rule():
    b = geom.SceneBuilder()
    box = b.add_leaf("box", [1, 1, 1])
    ell = b.add_leaf("ellipsoid", [0.5, 0.4, 0.3])
    shell = b.add_leaf("hollow_cylinder_shell", [0.5, 0.3, 1.0])
    sph = b.add_leaf("sphere", [0.3])
    assert b.node_bound(box)[2] and not b.node_bound(ell)[2] and not b.node_bound(shell)[2]
    # left certified, right 1-Lipschitz: kept; right not 1-Lipschitz (ellipsoid): lost
    assert b.node_bound(b.add_difference(box, sph))[2]
    assert b.node_bound(b.add_difference(box, shell))[2]       # shell is 1-Lipschitz
    assert not b.node_bound(b.add_difference(box, ell))[2]     # the upstream rule kept this
    assert not b.node_bound(b.add_intersection(box, ell))[2]
    assert not b.node_bound(b.add_difference(ell, box))[2]
    assert not b.node_bound(b.add_union(box, ell))[2]
    deep = b.add_union(b.add_difference(box, sph), b.add_intersection(sph, shell))
    assert b.node_bound(deep)[2] is True
    # the union ball encloses both children's balls
    u = b.add_union(b.add_leaf("sphere", [0.2], translation=[3, 0, 0]), box)
    c, r, _ = b.node_bound(u)
    assert r >= np.linalg.norm(c - [3, 0, 0]) + 0.2 - 1e-15 and r >= np.linalg.norm(c) + np.sqrt(3) - 1e-15


def _scene(n, certified_share, seed, box=None):
    g = np.random.default_rng(seed)
    b = geom.SceneBuilder()
    roots = [page_steps.pall_ring(b, certified=True), page_steps.pall_ring(b, certified=False),
             b.add_leaf("ellipsoid", [0.3, 0.2, 0.25]), b.add_leaf("sphere", [0.25])]
    lo, hi = (np.zeros(3), np.full(3, 8.0)) if box is None else box
    for k in range(n):
        root = roots[0] if g.random() < certified_share else roots[1 + g.integers(3)]
        b.add_instance(root, translation=g.uniform(lo, hi), rotation=g.normal(size=4),
                       scale=g.uniform(0.5, 1.2))
    return b, g


@pytest.mark.parametrize("periodic", heavy_params([(False, False, False), (True, False, True)],
                                                  (True, False, True)))
def test_scene_query_equals_brute_force_bitwise(periodic):
    box = (np.zeros(3), np.full(3, 8.0))
    b, g = _scene(1000, 0.9, 3, box)
    p = g.uniform(-1, 9, (3_000, 3))
    kw = dict(box=box, periodic=periodic) if any(periodic) else {}
    pruned = b.eval_scene(p, method="pruned", **kw)
    brute = b.eval_scene(p, method="brute", **kw)
    assert np.array_equal(pruned, brute)
    assert (pruned < 0).mean() > 0.01                      # the points do meet solids
    if any(periodic):   # and the field is periodic (wrapping x + 8 rounds: not bitwise)
        shifted = p + np.array([8.0, 0.0, -16.0])
        assert np.allclose(b.eval_scene(shifted, box=box, periodic=periodic), pruned,
                           rtol=0, atol=1e-12)


def test_scene_matches_instance_definition():
    b = geom.SceneBuilder()
    ring = page_steps.pall_ring(b)
    q = np.array([0.2, 0.3, 0.1, 0.9])
    q /= np.linalg.norm(q)
    b.add_instance(ring, translation=[1, 2, 3], rotation=q, scale=2.0)
    p = np.random.default_rng(4).uniform(-1, 5, (5000, 3))
    local = (p - [1, 2, 3]) @ geom.quat_to_matrix(q) / 2.0
    assert np.max(np.abs(b.eval_scene(p) - 2.0 * b.eval_root(ring, local))) < 1e-14


def _signature_counts():
    fns = [kernels.eval_points, kernels.bake_lattice, kernels.eval_point, kernels.leaf_eval,
           scene._scene_pruned, scene._scene_brute]
    return [len(f.signatures) for f in fns]


def test_new_trees_never_compile():
    g = np.random.default_rng(5)
    p = g.uniform(-1, 1, (64, 3))
    warm = geom.SceneBuilder()
    r = random_tree(warm, g, 3)
    warm.eval_root(r, p), warm.eval_root_grad(r, p), warm.bake(r, [0, 0, 0], [0.1] * 3, [2] * 3)
    warm.add_instance(r)
    warm.eval_scene(p), warm.eval_scene(p, method="brute")
    before = _signature_counts()
    for trial in range(1000):
        b = geom.SceneBuilder()
        root = random_tree(b, g, g.integers(1, 12))
        b.eval_root(root, p)
        if trial % 50 == 0:
            b.eval_root_grad(root, p)
            b.bake(root, [-1, -1, -1], [0.5, 0.5, 0.5], [4, 4, 4])
            b.add_instance(root)
            b.eval_scene(p)
    assert _signature_counts() == before


def test_results_are_bitwise_identical_at_any_thread_count():
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("needs NUMBA_NUM_THREADS >= 2")
    b, g = _scene(300, 0.8, 6)
    ring = page_steps.ring
    bb = page_steps.b
    p = g.uniform(-0.8, 8.8, (100_003, 3))
    out = {}
    old = numba.get_num_threads()
    try:
        for t in (1, 2):
            numba.set_num_threads(t)
            v, gr = bb.eval_root_grad(ring, p)
            out[t] = (bb.eval_root(ring, p), v, gr, bb.bake(ring, [-0.6] * 3, [0.02] * 3, [61] * 3),
                      b.eval_scene(p))
    finally:
        numba.set_num_threads(old)
    for x, y in zip(out[1], out[2]):
        assert np.array_equal(x, y)
