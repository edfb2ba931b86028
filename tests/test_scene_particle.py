"""scene_particle.build on a small composed solid: frames, shell probes, radius, register."""
import numpy as np
import pytest

from peclet.core import geom
from peclet.core.geom.shell import count_for_spacing, even_spacing
from peclet.dem import Simulation, scene_particle


def _solid(b):
    s = b.add_leaf("sphere", [0.3], translation=[0.1, 0.0, 0.0])
    return b.add_union(s, b.add_leaf("box", [0.25, 0.05, 0.15], translation=[-0.1, 0.1, 0.0]))


def test_build_small_particle():
    b = geom.SceneBuilder()
    root = _solid(b)
    sp = scene_particle.build(b, root, bounds=([-0.5] * 3, [0.5] * 3), n=32,
                              shell_resolution=48, target_shell_points=300)
    assert abs(len(sp.shell) - 300) <= 30
    assert np.abs(b.eval_root(sp.home_root, sp.shell)).max() <= 1e-6
    # home frame: com at the origin, inertia diagonal and ascending
    q = b.body_properties(sp.home_root, [-0.7] * 3, [0.7] * 3, n=32, tol=1e-6)
    # the body has creases (box edges, box-sphere seam): quadrature reaches ~1e-5 there
    assert np.abs(q.com).max() <= 1e-5
    off = q.inertia - np.diag(np.diag(q.inertia))
    assert np.abs(off).max() <= 1e-5 * np.abs(q.inertia).max()
    assert np.all(np.diff(sp.principal) >= 0)
    assert np.allclose(sp.inv_inertia_unit, 1 / sp.principal)
    # quat maps home to authoring coordinates: p_author = R p_home + com
    Rm = geom.quat_to_matrix(sp.quat)
    back = sp.shell @ Rm.T + sp.com
    assert np.abs(b.eval_root(root, back)).max() <= 1e-6
    # guaranteed radius contains every probe and random interior points
    assert np.linalg.norm(sp.shell, axis=1).max() <= sp.bounding_radius
    pts = np.random.default_rng(1).uniform(-0.7, 0.7, (20000, 3))
    inside = pts[b.eval_root(sp.home_root, pts) < 0]
    assert np.linalg.norm(inside, axis=1).max() <= sp.bounding_radius
    # even spread: median NN spacing close to the hexagonal expectation
    exp = even_spacing(sp.spacing["area"], len(sp.shell))
    assert 0.6 * exp <= sp.spacing["median_spacing"] <= 1.2 * exp
    # registered in a real Simulation (after a sphere, so the id is not trivially 0)
    sim = Simulation(2)
    sim.add_sphere_shape(0.1)
    sid = sp.register(sim)
    assert sid == 1
    shape = sim.world.shapes[sid]
    assert shape.root == sp.home_root and shape.radius == sp.bounding_radius
    assert np.array_equal(shape.shell, sp.shell)
    assert shape.node_ints.tobytes() == sp.node_ints.tobytes()
    assert shape.node_reals.tobytes() == sp.node_reals.tobytes()


def test_a_shared_cache_measures_once_and_changes_no_bit():
    # the thin-wall rule of peclet.packing builds twice (more probes the second time): with a
    # shared cache the second build integrates no cell, and both equal cache-free builds
    box = ([-0.5] * 3, [0.5] * 3)
    cache = {}
    got = []
    for count in (300, 500):
        b1, b2 = geom.SceneBuilder(), geom.SceneBuilder()
        plain = scene_particle.build(b1, _solid(b1), bounds=box, shell_resolution=48,
                                     target_shell_points=count, tol=1e-5)
        rows = sum(len(v) for v in cache.values() if isinstance(v, dict))
        shared = scene_particle.build(b2, _solid(b2), bounds=box, shell_resolution=48,
                                      target_shell_points=count, tol=1e-5, cache=cache)
        got.append(sum(len(v) for v in cache.values() if isinstance(v, dict)) - rows)
        for f in ("shell", "node_ints", "node_reals", "com", "quat", "principal"):
            assert np.asarray(getattr(shared, f)).tobytes() == \
                np.asarray(getattr(plain, f)).tobytes(), f
        assert shared.volume == plain.volume and shared.volume_error == plain.volume_error
    assert got[0] > 0 and got[1] == 0          # cells integrated by the first build only


def test_count_for_spacing_inverts_even_spacing():
    n = count_for_spacing(6.56, 0.040)
    assert even_spacing(6.56, n) <= 0.040 < even_spacing(6.56, n - 1)


def test_bad_arguments():
    b = geom.SceneBuilder()
    root = _solid(b)
    with pytest.raises(ValueError, match="bounds"):
        scene_particle.build(b, root, bounds=[0.5])
    with pytest.raises(ValueError, match="target"):
        scene_particle.build(b, root, bounds=([-0.5] * 3, [0.5] * 3), n=4,
                             target_shell_points=0)



_SIGNATURES = """
import json, sys
from numba.core.registry import CPUDispatcher
from peclet.core import geom
from peclet.dem import scene_particle


def signatures():
    out = {}
    for name, mod in list(sys.modules.items()):
        if name.startswith(("peclet.core.geom", "peclet.dem.scene_particle")) and mod:
            for attr, f in vars(mod).items():
                if isinstance(f, CPUDispatcher):
                    out[name + "." + attr] = len(f.signatures)
    return out


scene_particle.compile_kernels()
before = signatures()
b = geom.SceneBuilder()
root = b.add_difference(b.add_leaf("torus", [0.3, 0.1]),
                        b.add_leaf("box", [0.1, 0.2, 0.5], translation=[0.3, 0.0, 0.0]))
sp = scene_particle.build(b, root, bounds=([-0.45] * 3, [0.45] * 3), n=16,
                          shell_resolution=48, target_shell_points=400, tol=1e-6)
after = signatures()
print(json.dumps(dict(added={k: v for k, v in after.items() if before.get(k, 0) != v},
                      quadrature=before["peclet.core.geom.quadrature.refine._integrate_share"],
                      probes=len(sp.shell))))
"""


@pytest.mark.heavy
def test_compile_kernels_serves_a_build_of_any_tree():
    # peclet warm and the suite's cold start compile on a small solid at n 8, tol 1e-4; in a
    # fresh process (each kernel's signatures are those loaded or compiled there) a build of
    # another tree at n 16, tol 1e-6 must then add no signature to any kernel of the geometry
    # layer
    import json
    import subprocess
    import sys

    p = subprocess.run([sys.executable, "-c", _SIGNATURES], capture_output=True, text=True,
                       timeout=600)
    assert p.returncode == 0, p.stderr
    got = json.loads(p.stdout)
    assert got["quadrature"] == 1 and got["probes"] == 400
    assert got["added"] == {}
