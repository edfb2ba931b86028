"""The geometry front door: every bad argument is a PecletArgumentError naming it, raised before
any work and leaving the builder unchanged (issue 18)."""
import math

import numpy as np
import pytest

from peclet.core import geom
from peclet.core.geom import shell
from peclet.core.geom.mesh import surface_mesh
from peclet.core.validation import PecletArgumentError

NAN, INF = math.nan, math.inf


def _builder():
    """Nodes 0, 1: spheres (1-Lipschitz); node 2: an ellipsoid (not 1-Lipschitz)."""
    b = geom.SceneBuilder()
    b.add_leaf("sphere", [1.0])
    b.add_leaf("sphere", [2.0])
    b.add_leaf("ellipsoid", [0.5, 0.4, 0.3])
    return b


def _encoded():
    b = geom.SceneBuilder()
    b.add_union(b.add_leaf("sphere", [1.0]), b.add_leaf("box", [1, 1, 1]))
    ni, nr, _, _ = b.encode()
    return ni, nr


def _with(arr, index, value):
    out = np.array(arr, copy=True)
    out[index] = value
    return out


# (call on a builder b, the argument the message must name)
AUTHORING = [
    # kind
    (lambda b: b.add_leaf("blob", [1.0]), "kind"),
    (lambda b: b.add_leaf(99, [1.0]), "kind"),
    (lambda b: b.add_leaf(True, [1.0]), "kind"),
    (lambda b: b.add_leaf(None, [1.0]), "kind"),
    (lambda b: b.add_leaf(1.0, [1.0]), "kind"),
    # parameter count, type, finiteness
    (lambda b: b.add_leaf("sphere", [1.0, 2.0]), "params"),
    (lambda b: b.add_leaf("box", [1.0, 1.0]), "params"),
    (lambda b: b.add_leaf("sphere", []), "params"),
    (lambda b: b.add_leaf("sphere", [NAN]), "params"),
    (lambda b: b.add_leaf("sphere", [INF]), "params"),
    (lambda b: b.add_leaf("sphere", "1.0"), "params"),
    (lambda b: b.add_leaf("sphere", ["a"]), "params"),
    (lambda b: b.add_leaf("sphere", [[1.0]]), "params"),
    (lambda b: b.add_leaf("sphere", None), "params"),
    (lambda b: b.add_leaf("sphere", [True]), "params"),
    (lambda b: b.add_leaf("sphere", [1j]), "params"),
    (lambda b: b.add_leaf("sphere", {"radius": 1.0}), "params"),
    (lambda b: b.add_leaf("box", [1.0, [1.0], 1.0]), "params"),
    # parameter ranges (the leaf table's rules)
    (lambda b: b.add_leaf("sphere", [0.0]), "params"),
    (lambda b: b.add_leaf("sphere", [-1.0]), "params"),
    (lambda b: b.add_leaf("box", [1.0, -1.0, 1.0]), "params"),
    (lambda b: b.add_leaf("hollow_cylinder", [0.5, 1.0, 0.6]), "params"),
    (lambda b: b.add_leaf("hollow_cylinder", [0.5, 1.0, 0.5]), "params"),
    (lambda b: b.add_leaf("hollow_cylinder_shell", [0.5, 0.6, 1.0]), "params"),
    (lambda b: b.add_leaf("torus", [0.3, 0.4]), "params"),
    (lambda b: b.add_leaf("cone", [0.0, 0.0, 1.0]), "params"),
    (lambda b: b.add_leaf("cone", [0.3, 0.2, 0.0]), "params"),
    (lambda b: b.add_leaf("superquadric", [1, 1, 1, 3.0]), "params"),
    (lambda b: b.add_leaf("half_space", [0, 0, 0, 1.0]), "params"),
    (lambda b: b.add_leaf("capsule", [0.2, -0.1]), "params"),
    # transforms
    (lambda b: b.add_leaf("sphere", [1.0], translation=[0, 1]), "translation"),
    (lambda b: b.add_leaf("sphere", [1.0], translation=[0, NAN, 1]), "translation"),
    (lambda b: b.add_leaf("sphere", [1.0], translation=[INF, 0, 0]), "translation"),
    (lambda b: b.add_leaf("sphere", [1.0], translation=[[0, 0, 0]]), "translation"),
    (lambda b: b.add_leaf("sphere", [1.0], translation="abc"), "translation"),
    (lambda b: b.add_leaf("sphere", [1.0], translation=[0, 0, "x"]), "translation"),
    (lambda b: b.add_leaf("sphere", [1.0], rotation=[0, 0, 0, 0]), "rotation"),
    (lambda b: b.add_leaf("sphere", [1.0], rotation=[0.0, -0.0, 0.0, 0.0]), "rotation"),
    (lambda b: b.add_leaf("sphere", [1.0], rotation=[0, 0, 1]), "rotation"),
    (lambda b: b.add_leaf("sphere", [1.0], rotation=[0, INF, 0, 1]), "rotation"),
    (lambda b: b.add_leaf("sphere", [1.0], rotation=[NAN] * 4), "rotation"),
    (lambda b: b.add_leaf("sphere", [1.0], rotation="quat"), "rotation"),
    (lambda b: b.add_leaf("sphere", [1.0], rotation=[[0, 0, 0, 1]]), "rotation"),
    (lambda b: b.add_leaf("sphere", [1.0], scale=0.0), "scale"),
    (lambda b: b.add_leaf("sphere", [1.0], scale=-2.0), "scale"),
    (lambda b: b.add_leaf("sphere", [1.0], scale=INF), "scale"),
    (lambda b: b.add_leaf("sphere", [1.0], scale=NAN), "scale"),
    (lambda b: b.add_leaf("sphere", [1.0], scale="1"), "scale"),
    (lambda b: b.add_leaf("sphere", [1.0], scale=True), "scale"),
    (lambda b: b.add_leaf("sphere", [1.0], scale=[1.0]), "scale"),
    (lambda b: b.add_union(0, 1, scale=0.0), "scale"),
    (lambda b: b.add_instance(0, rotation=[0, 0, 0, 0]), "rotation"),
    (lambda b: b.add_reframed(0, translation=[1, 2]), "translation"),
    # child / node indices
    (lambda b: b.add_union(0, 5), "b"),
    (lambda b: b.add_union(-1, 0), "a"),
    (lambda b: b.add_union(3, 0), "a"),
    (lambda b: b.add_union(0.0, 1), "a"),
    (lambda b: b.add_intersection(True, 0), "a"),
    (lambda b: b.add_difference("0", 1), "a"),
    (lambda b: b.add_difference(np.int64(0), np.int64(7)), "b"),
    (lambda b: b.add_reframed(9), "node"),
    (lambda b: b.add_instance(None), "root"),
]


@pytest.mark.parametrize("call, name", AUTHORING)
def test_authoring_names_the_bad_argument_and_adds_nothing(call, name):
    b = _builder()
    n, m = b.num_nodes(), b.num_instances()
    with pytest.raises(PecletArgumentError, match=rf"^{name} must "):
        call(b)
    assert (b.num_nodes(), b.num_instances()) == (n, m)


QUERIES = [
    (lambda b: b.eval_root(0, np.zeros((4, 2))), "points"),
    (lambda b: b.eval_root(0, np.zeros(3)), "points"),
    (lambda b: b.eval_root(0, [[0, 0, 0], [0, NAN, 0]]), "points"),
    (lambda b: b.eval_root_grad(0, [[INF, 0, 0]]), "points"),
    (lambda b: b.eval_root(0, "points"), "points"),
    (lambda b: b.eval_root(0, [[0, 0, 0], [0, 0]]), "points"),
    (lambda b: b.eval_root(0, None), "points"),
    (lambda b: b.eval_root(0, np.zeros((2, 3), complex)), "points"),
    (lambda b: b.eval_root_grad(0, np.zeros((2, 3, 1))), "points"),
    (lambda b: b.eval_root(7, np.zeros((1, 3))), "root"),
    (lambda b: b.eval_root(1.0, np.zeros((1, 3))), "root"),
    (lambda b: b.node_bound("0"), "root"),
    (lambda b: b.program(-1), "root"),
    (lambda b: b.node(3), "index"),
    (lambda b: b.is_lipschitz(None), "root"),
    (lambda b: b.bake(0, [0, 0, 0], [0.1, 0, 0.1], [2, 2, 2]), "spacing"),
    (lambda b: b.bake(0, [0, 0, 0], [0.1, NAN, 0.1], [2, 2, 2]), "spacing"),
    (lambda b: b.bake(0, [0, 0, 0], [0.1, 0.1], [2, 2, 2]), "spacing"),
    (lambda b: b.bake(0, [0, 0, 0], [0.1] * 3, [2, 0, 2]), "dims"),
    (lambda b: b.bake(0, [0, 0, 0], [0.1] * 3, [2, 2.5, 2]), "dims"),
    (lambda b: b.bake(0, [0, 0, 0], [0.1] * 3, [4096, 4096, 4096]), "dims"),
    (lambda b: b.bake(0, [0, NAN, 0], [0.1] * 3, [2, 2, 2]), "origin"),
    (lambda b: b.bake(0, [0, 0, 0], [0.1] * 3, [2, 2, 2], band=-1.0), "band"),
    (lambda b: b.bake(0, [0, 0, 0], [0.1] * 3, [2, 2, 2], band="wide"), "band"),
    (lambda b: b.bake(2, [0, 0, 0], [0.1] * 3, [2, 2, 2], band=0.2), "band"),
    (lambda b: geom.evaluate(*b.encode()[:2], 1.5, np.zeros((1, 3))), "root"),
]


@pytest.mark.parametrize("call, name", QUERIES)
def test_queries_name_the_bad_argument(call, name):
    with pytest.raises(PecletArgumentError, match=rf"^{name} must "):
        call(_builder())


def _placed(translation=(0.5, 0.5, 0.5)):
    b = _builder()
    b.add_instance(0, translation=list(translation))
    return b


BOX = ([0, 0, 0], [4, 4, 4])
SCENE = [
    (lambda b: b.eval_scene(np.zeros((1, 3)), box=BOX, periodic=("False",) * 3), r"periodic\[0\]"),
    (lambda b: b.eval_scene(np.zeros((1, 3)), box=BOX, periodic=(0, 1, 0)), r"periodic\[0\]"),
    (lambda b: b.eval_scene(np.zeros((1, 3)), box=BOX, periodic=(True, False)), "periodic"),
    (lambda b: b.eval_scene(np.zeros((1, 3)), box=BOX, periodic="TTT"), "periodic"),
    (lambda b: b.eval_scene(np.zeros((1, 3)), periodic=(True, False, False)), "box"),
    (lambda b: b.eval_scene(np.zeros((1, 3)), box=([0, 0, 0], [4, -1, 4])), "box"),
    (lambda b: b.eval_scene(np.zeros((1, 3)), box=([0, 0, 0], [4, NAN, 4])), "box hi"),
    (lambda b: b.eval_scene(np.zeros((1, 3)), box=[0, 0, 0]), "box"),
    (lambda b: b.eval_scene(np.zeros((1, 3)), method="fast"), "method"),
    (lambda b: b.eval_scene(np.zeros((1, 2))), "points"),
]


@pytest.mark.parametrize("call, name", SCENE)
def test_scene_queries_name_the_bad_argument(call, name):
    with pytest.raises(PecletArgumentError, match=rf"^{name} must "):
        call(_placed())


def test_instance_outside_its_periodic_box_is_refused():
    b = _placed(translation=(9.0, 0.5, 0.5))
    with pytest.raises(PecletArgumentError, match=r"^box must .*translation\[0\]=9.0"):
        b.eval_scene(np.zeros((1, 3)), box=BOX, periodic=(True, False, False))


NI, NR = _encoded()
DECODE = [
    (lambda: geom.decode(_with(NI, (2, 2), 7), NR), r"node_ints\[2\]", "right must be"),
    (lambda: geom.decode(_with(NI, (0, 0), 17), NR), r"node_ints\[0\]", "kind must be"),
    (lambda: geom.decode(_with(NI, (0, 1), 1), NR), r"node_ints\[0\]", "left must be -1"),
    (lambda: geom.decode(NI, _with(NR, (0, 0), -1.0)), r"node_reals\[0\]", "'radius' must be > 0"),
    (lambda: geom.decode(NI, _with(NR, (1, slice(11, 15)), 0.0)), r"node_reals\[1\]", "rotation"),
    (lambda: geom.decode(NI, _with(NR, (2, 15), -1.0)), r"node_reals\[2\]", "scale"),
    (lambda: geom.decode(NI, NR[:, :15]), "node_reals", r"shape \(3, 16\)"),
    (lambda: geom.decode(NI, _with(NR, (1, 9), NAN)), "node_reals", "finite"),
    (lambda: geom.decode(NI.astype(float) + 0.5, NR), "node_ints", "integers"),
    (lambda: geom.decode(NI[:, :2], NR), "node_ints", r"shape \(N, 3\)"),
    (lambda: geom.decode("nodes", NR), "node_ints", "shape"),
    (lambda: geom.decode(NI, NR, inst_ints=[[0, 0]]), "inst_reals", "together"),
    (lambda: geom.decode(NI, NR, [[5, 0]], [[0, 0, 0, 0, 0, 0, 1, 1]]), r"inst_ints\[0\]", "root"),
    (lambda: geom.decode(NI, NR, [[0, 0]], [[0, 0, 0, 0, 0, 0, 1, 0]]), r"inst_reals\[0\]",
     "scale"),
    (lambda: geom.decode(NI, NR, [[0, 0]], [[0, 0, 0, 0, 0, 0, 1]]), "inst_reals", "shape"),
]


@pytest.mark.parametrize("call, name, why", DECODE)
def test_decode_names_the_bad_table_and_row(call, name, why):
    with pytest.raises(PecletArgumentError, match=rf"^{name} must .*{why}"):
        call()


SURFACE = [
    (lambda b: shell.shell_probes(b, 0, 3, 16, [-1.2] * 3, [1.2] * 3), "target"),
    (lambda b: shell.shell_probes(b, 0, True, 16, [-1.2] * 3, [1.2] * 3), "target"),
    (lambda b: shell.shell_probes(b, 0, 10 ** 9, 16, [-1.2] * 3, [1.2] * 3), "target"),
    (lambda b: shell.shell_probes(b, 0, 64, 4, [-1.2] * 3, [1.2] * 3), "resolution"),
    (lambda b: shell.shell_probes(b, 0, 64, "16", [-1.2] * 3, [1.2] * 3), "resolution"),
    (lambda b: shell.shell_probes(b, 0, 64, 16, [-1.2] * 3, [1.2] * 3, seed=-1), "seed"),
    (lambda b: shell.shell_probes(b, 0, 64, 16, [-1.2] * 3, [1.2] * 3, oversample=0),
     "oversample"),
    (lambda b: shell.shell_probes(b, 0, 64, 16, [-1.2] * 2, [1.2] * 3), "lo"),
    (lambda b: shell.even_spacing(0.0, 10), "area"),
    (lambda b: shell.even_spacing(1.0, 0), "count"),
    (lambda b: shell.count_for_spacing(1.0, -0.1), "spacing"),
    (lambda b: shell.farthest_point_order(np.zeros((5, 3)), 6, 0), "count"),
    (lambda b: shell.farthest_point_order(np.zeros((5, 3)), 2, 5), "start"),
    (lambda b: shell.project(b, 0, np.zeros((2, 2))), "points"),
    (lambda b: surface_mesh(b, 0, [-1.2] * 3, [1.2] * 3, 2), "n"),
    (lambda b: surface_mesh(b, 0, [1.2] * 3, [-1.2] * 3, 9), "hi"),
]


@pytest.mark.parametrize("call, name", SURFACE)
def test_surface_tools_name_the_bad_argument(call, name):
    with pytest.raises(PecletArgumentError, match=rf"^{name} must "):
        call(_builder())


def test_every_error_is_still_a_value_error():
    with pytest.raises(ValueError):
        _builder().add_leaf("sphere", [-1.0])

