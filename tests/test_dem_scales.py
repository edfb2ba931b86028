"""Polydisperse bodies: ``set_scales`` / ``set_scales_uniform`` (issue 22, item 3).

A body of shape k and scale s is shape k enlarged by s about its centre of mass, mass and
inertia following (s^3, s^5). Closed forms: a scaled sphere and a scaled composed particle rest
on a floor at their scaled radius; an elastic head-on collision of spheres whose scales differ
by 2 (mass ratio 8) ends at the textbook velocities. Exactness: scales of 1 change no bit, and a
save holds the scales (bitwise resume).
"""
import math

import numpy as np
import pytest

from peclet.core.geom import SceneBuilder
from peclet.core.validation import PecletArgumentError
from peclet.dem import Simulation


def _floor(sim):
    b = SceneBuilder()
    root = b.add_leaf("box", [50.0, 1.0, 50.0], translation=[0.0, -1.0, 0.0])
    ni, nr, _, _ = b.encode()
    return sim.add_analytic_wall(ni, nr, root, False, 0.0, 0.5)


def _ball_tree(r=0.5):
    b = SceneBuilder()
    root = b.add_leaf("sphere", [r])
    ni, nr, _, _ = b.encode()
    rng = np.random.default_rng(0)
    p = rng.normal(size=(400, 3))
    return ni, nr, root, r * p / np.linalg.norm(p, axis=1)[:, None]


def _rest_height(kind, scale):
    sim = Simulation(1)
    sim.set_gravity(0.0, -9.81, 0.0)
    sim.set_material_params(0.0, 0.0, 0.5)
    _floor(sim)
    if kind == "sphere":
        sim.add_sphere_shape(0.5)
    else:
        ni, nr, root, shell = _ball_tree()
        sim.add_scene_shape(ni, nr, root, shell, 0.5)
    sim.set_positions(np.array([[0.0, 0.5 * scale + 0.2, 0.0]]))
    sim.set_shape_ids(np.array([0]))
    sim.set_inv_mass(np.array([1.0]))
    sim.set_scales([scale])
    for _ in range(300):
        sim.step(2e-3)
    return sim.get_positions()[0, 1], sim


@pytest.mark.parametrize("kind", ["sphere", "scene"])
@pytest.mark.parametrize("scale", [0.5, 2.5])
def test_a_scaled_body_rests_at_its_scaled_radius(kind, scale):
    y, sim = _rest_height(kind, scale)
    # a scene sphere touches through its probes (a chord below the true surface, < 1e-2 r)
    tol = 1e-3 * scale if kind == "sphere" else 1.5e-2 * scale
    assert y == pytest.approx(0.5 * scale, abs=tol)
    # at rest vertically (the probe ball keeps rolling from probe to probe, a few cm/s)
    assert abs(sim.get_velocities()[0, 1]) < (1e-9 if kind == "sphere" else 0.05)


def test_mass_and_inertia_follow_the_scale():
    sim = Simulation(2)
    sim.add_sphere_shape(0.5)
    sim.set_positions(np.zeros((2, 3)) + [[0, 0, 0], [5, 0, 0]])
    sim.set_inv_mass(np.array([1.0, 2.0]))
    sim.set_scales([2.0, 1.0])
    # never set: the default, a solid sphere of the SCALED radius, 1 / I = 2.5 inv_mass / r^2
    assert np.array_equal(sim.get_inv_inertia(), [[2.5 / 8.0] * 3, [2.5 * 2.0 / 0.25] * 3])
    sim.set_inv_inertia(np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]))
    sim.set_scales([4.0, 1.0])                               # body 0: 2 -> 4
    assert np.array_equal(sim.get_inv_mass(), [1.0 / 64.0, 2.0])
    assert np.array_equal(sim.get_inv_inertia()[0], np.array([1.0, 2.0, 3.0]) / 32.0)
    assert np.array_equal(sim.get_inv_inertia()[1], [4.0, 5.0, 6.0])
    sim.set_scales_uniform(8.0)                              # 4 -> 8 and 1 -> 8
    assert sim.get_inv_mass() == pytest.approx([1.0 / 512.0, 2.0 / 512.0], rel=1e-15)
    assert np.array_equal(sim.get_scales(), [8.0, 8.0])


def test_an_elastic_collision_of_spheres_scaled_one_to_two():
    sim = Simulation(2)
    sim.set_material_params(1.0, 0.0, 0.0)
    sim.add_sphere_shape(0.5)
    m = 4.0 / 3.0 * math.pi * 0.125
    sim.set_positions(np.array([[-2.0, 0.0, 0.0], [2.0, 0.0, 0.0]]))
    sim.set_shape_ids(np.array([0, 0]))
    sim.set_inv_mass(np.array([1.0 / m, 1.0 / m]))
    sim.set_scales([1.0, 2.0])                               # masses m and 8 m, radii 0.5, 1
    u = 1.0
    sim.set_velocities(np.array([[u, 0.0, 0.0], [0.0, 0.0, 0.0]]))
    for _ in range(400):
        sim.step(1e-2)
    m1, m2 = m, 8.0 * m
    v = sim.get_velocities()[:, 0]
    assert v[0] == pytest.approx((m1 - m2) / (m1 + m2) * u, abs=1e-9)
    assert v[1] == pytest.approx(2.0 * m1 / (m1 + m2) * u, abs=1e-9)
    gap = sim.get_positions()[1, 0] - sim.get_positions()[0, 0]
    assert gap > 1.5                                         # they met at 0.5 + 1.0


def _pile(scales=None):
    sim = Simulation(8)
    sim.set_gravity(0.0, -9.81, 0.0)
    sim.set_material_params(0.3, 0.0, 0.5)
    _floor(sim)
    sim.add_sphere_shape(0.4)
    rng = np.random.default_rng(1)
    n = 30
    sim.set_positions(rng.uniform([-1.5, 0.5, -1.5], [1.5, 6.0, 1.5], size=(n, 3)))
    sim.set_shape_ids(np.zeros(n, np.int64))
    if scales is not None:
        sim.set_scales(scales(n))
    sim.relax(20)
    return sim


def test_scales_of_one_change_no_bit():
    a, b = _pile(), _pile(lambda n: np.ones(n))
    for _ in range(60):
        a.step(2e-3)
        b.step(2e-3)
    assert a.state_hash() == b.state_hash()


def test_a_polydisperse_run_saved_and_resumed_is_bitwise(tmp_path):
    sc = lambda n: np.where(np.arange(n) % 3 == 0, 1.5, np.where(np.arange(n) % 3 == 1, 0.8, 1.0))  # noqa
    ref = _pile(sc)
    res = _pile(sc)
    for _ in range(40):
        ref.step(2e-3)
        res.step(2e-3)
    path = str(tmp_path / "poly.npz")
    res.save(path)
    res = Simulation.load(path)
    assert np.array_equal(res.get_scales(), ref.get_scales())
    for _ in range(40):
        ref.step(2e-3)
        res.step(2e-3)
    assert ref.state_hash() == res.state_hash()
    # the three sizes are there: no two bodies closer than their scaled radii allow
    c = ref.detect_contacts()
    assert c["depth"].max() < 0.01


@pytest.mark.parametrize("value,phrase", [([1.0, -1.0], "(0, 1000]"), ([1.0, 0.0], "(0, 1000]"),
                                          ([1.0, np.nan], "finite"), ([1.0], "shape (2,)"),
                                          ([1.0, 1e4], "(0, 1000]")])
def test_bad_scales_are_refused_naming_the_argument(value, phrase):
    sim = Simulation(2)
    sim.add_sphere_shape(0.5)
    sim.set_positions(np.zeros((2, 3)))
    with pytest.raises(PecletArgumentError, match=r"^scales") as ex:
        sim.set_scales(value)
    assert phrase in str(ex.value)
    assert np.array_equal(sim.get_scales(), [1.0, 1.0])      # nothing changed
    with pytest.raises(PecletArgumentError, match=r"^scale "):
        sim.set_scales_uniform(0.0)


def test_a_version_2_save_without_scales_still_loads(tmp_path):
    sim = _pile()
    path = str(tmp_path / "v3.npz")
    sim.save(path)
    with np.load(path) as z:
        d = {k: z[k] for k in z.files}
    assert int(d["version"]) == 3 and len(d["scales"]) == 0
    old = dict(d, version=np.int64(2))
    del old["scales"]
    np.savez(str(tmp_path / "v2.npz"), **old)
    back = Simulation.load(str(tmp_path / "v2.npz"))
    assert back.state_hash() == sim.state_hash()
    assert np.array_equal(back.get_scales(), np.ones(sim.num_particles()))
    # a version 2 file carrying the version 3 key is not a save
    np.savez(str(tmp_path / "bad.npz"), **dict(d, version=np.int64(2)))
    with pytest.raises(PecletArgumentError, match="keys"):
        Simulation.load(str(tmp_path / "bad.npz"))
