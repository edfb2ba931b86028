"""peclet.dem.Simulation: the API contract, argument checking, buffers, guards, save/load."""
import numpy as np
import pytest

from peclet.core import geom
from peclet.dem import Simulation
from peclet.dem.simulation import StepError


def sphere_sim(n=4, radius=0.5, spacing=1.2, capacity=1):
    sim = Simulation(capacity)
    sid = sim.add_sphere_shape(radius)
    sim.set_positions(np.column_stack([np.arange(n) * spacing, np.zeros(n), np.zeros(n)]))
    sim.set_shape_ids(np.full(n, sid))
    return sim


def box_wall(sim, half, centre, invert=False, e=0.5, mu=0.5):
    b = geom.SceneBuilder()
    r = b.add_leaf("box", list(half), translation=list(centre))
    ni, nr, _, _ = b.encode()
    return sim.add_analytic_wall(ni, nr, r, invert, e, mu)


def test_step_needs_a_dt_and_never_advances_nothing():
    sim = sphere_sim()
    with pytest.raises(ValueError, match="dt"):
        sim.step()
    for bad in (0.0, -1e-3, np.nan, np.inf):
        with pytest.raises(ValueError, match="dt"):
            sim.step(bad)
    with pytest.raises(ValueError, match="dt"):
        sim.set_dt(0.0)
    sim.set_gravity(0.0, -10.0, 0.0)
    sim.set_dt(1e-2)
    sim.step()
    assert sim.step_count == 1
    np.testing.assert_allclose(sim.get_velocities()[:, 1], -0.1, rtol=0, atol=1e-15)
    sim.step(2e-2)                                  # an explicit dt wins over set_dt
    np.testing.assert_allclose(sim.get_velocities()[:, 1], -0.3, rtol=0, atol=1e-15)
    assert sim.time == pytest.approx(0.03, abs=1e-15)


def test_set_positions_keeps_attributes_in_either_order():
    sim = Simulation(1)
    a = sim.add_sphere_shape(0.5)
    b = sim.add_sphere_shape(0.25)
    ids = np.array([b, a, b], np.int32)
    pos = np.array([[0, 0, 0], [2, 0, 0], [4, 0, 0]], np.float32)
    sim.set_positions(pos)
    sim.set_shape_ids(ids)
    sim.set_inv_mass([1.0, 2.0, 3.0])
    sim.set_positions(pos + 1.0)                    # same N: everything else is kept
    assert np.array_equal(sim.get_shape_ids(), ids)
    assert np.array_equal(sim.get_inv_mass(), [1.0, 2.0, 3.0])
    other = Simulation(1)
    other.add_sphere_shape(0.5)
    other.add_sphere_shape(0.25)
    other.set_shape_ids(ids)                        # the other order
    other.set_positions(pos)
    assert np.array_equal(other.get_shape_ids(), ids)
    assert other.num_particles() == 3
    # a change of N keeps the first min(N_old, N) particles' attributes, defaults the rest
    sim.set_positions(np.zeros((5, 3)))
    assert sim.num_particles() == 5
    assert np.array_equal(sim.get_shape_ids(), [b, a, b, 0, 0])
    assert np.array_equal(sim.get_inv_mass(), [1, 2, 3, 1, 1])
    np.testing.assert_array_equal(sim.get_quaternions()[3:], [[0, 0, 0, 1]] * 2)


def test_float32_input_is_stored_as_float64():
    sim = sphere_sim(2)
    p = np.array([[0.1, 0.2, 0.3], [1.7, 0.0, 0.0]], np.float32)
    sim.set_positions(p)
    out = sim.get_positions()
    assert out.dtype == np.float64
    assert np.array_equal(out, p.astype(np.float64))


def test_quaternions_are_normalised_and_zero_is_refused():
    sim = sphere_sim(2)
    sim.set_quaternions([[0, 0, 0, 2.0], [1.0, 1.0, 0, 0]])
    np.testing.assert_allclose(sim.get_quaternions(),
                               [[0, 0, 0, 1], [2 ** -0.5, 2 ** -0.5, 0, 0]], atol=1e-16)
    with pytest.raises(ValueError, match="quats"):
        sim.set_quaternions([[0, 0, 0, 1.0], [0, 0, 0, 0]])


@pytest.mark.parametrize("call, arg, word", [
    ("set_positions", np.full((2, 3), np.nan), "positions"),
    ("set_positions", np.zeros((2, 2)), "positions"),
    ("set_inv_mass", [1.0, -1.0], "inv_mass"),
    ("set_inv_mass", [1.0, 1.0, 1.0], "inv_mass"),
    ("set_inv_inertia", [[1, 1, -1.0], [1, 1, 1]], "inv_inertia"),
    ("set_velocities", [[np.inf, 0, 0], [0, 0, 0]], "velocities"),
    ("set_angular_velocities", np.zeros((3, 3)), "angular_velocities"),
    ("set_shape_ids", [0, 7], "ids"),
    ("set_shape_ids", [0, -1], "ids"),
])
def test_bad_particle_arguments_raise_value_error_naming_them(call, arg, word):
    sim = sphere_sim(2)
    with pytest.raises(ValueError, match=word):
        getattr(sim, call)(arg)


def test_bad_configuration_arguments():
    sim = Simulation()
    with pytest.raises(ValueError, match="e_n"):
        sim.set_material_params(1.5, 0.0, 0.5)
    with pytest.raises(ValueError, match="e_t"):
        sim.set_material_params(0.5, 2.0, 0.5)
    with pytest.raises(ValueError, match="mu"):
        sim.set_material_params(0.5, 0.0, -0.1)
    with pytest.raises(ValueError, match="velocity"):
        sim.set_solver_iterations(3, -1)
    with pytest.raises(ValueError, match="radius"):
        sim.add_sphere_shape(0.0)
    with pytest.raises(ValueError, match="domain"):
        sim.set_domain((0, 0, 0), (1, 0, 1))
    with pytest.raises(ValueError, match="n must"):
        sim.set_contact_capacity(0)
    b = geom.SceneBuilder()
    r = b.add_leaf("sphere", [1.0])
    ni, nr, _, _ = b.encode()
    with pytest.raises(ValueError, match="root"):
        sim.add_analytic_wall(ni, nr, 5, False, 0.5, 0.5)
    with pytest.raises(ValueError, match="shell_points"):
        sim.add_scene_shape(ni, nr, r, np.zeros((0, 3)), 1.0)
    bad = ni.copy()
    bad[0, 0] = 99                                  # an unknown leaf kind is refused up front
    with pytest.raises(ValueError):
        sim.add_scene_shape(bad, nr, r, np.array([[1.0, 0, 0]]), 1.0)


def test_periodic_axis_without_domain_and_step_without_shape_raise():
    sim = Simulation()
    sim.set_positions(np.zeros((1, 3)))
    with pytest.raises(ValueError, match="shape"):
        sim.step(1e-3)
    sim.add_sphere_shape(0.5)
    sim.enable_periodicity(True, False, False)
    with pytest.raises(ValueError, match="set_domain"):
        sim.step(1e-3)


def test_speed_guard_names_step_and_particle_and_keeps_the_state():
    sim = sphere_sim(5, spacing=3.0)
    sim.set_domain((-1, -1, -1), (15, 1, 1))
    sim.set_dt(1e-3)
    sim.step()
    before = sim.get_positions()
    v = np.zeros((5, 3))
    v[3, 1] = 2e4                                   # > 1e3 * 16 per unit time, no partner
    sim.set_velocities(v)
    with pytest.raises(StepError, match="step 2: particle 3") as err:
        sim.step()
    assert err.value.step == 2 and err.value.particle == 3
    assert np.array_equal(sim.get_positions(), before)
    assert sim.step_count == 1


def test_kinetic_energy_closed_form():
    sim = sphere_sim(2)
    sim.set_inv_mass([0.5, 0.25])
    sim.set_inv_inertia([[1.0, 2.0, 4.0], [1.0, 1.0, 1.0]])
    q = np.array([[0, 0, np.sin(0.3), np.cos(0.3)], [0, 0, 0, 1.0]])
    sim.set_quaternions(q)
    sim.set_velocities([[1.0, 2.0, 0.0], [0.0, 0.0, 3.0]])
    wb = np.array([0.5, -1.0, 2.0])                 # body-frame omega of particle 0
    c, s = np.cos(0.6), np.sin(0.6)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    sim.set_angular_velocities([R @ wb, [0.0, 1.0, 0.0]])
    expect = (0.5 * 2 * 5 + 0.5 * 4 * 9
              + 0.5 * (0.25 / 1 + 1.0 / 2 + 4.0 / 4) + 0.5 * 1.0)
    assert sim.kinetic_energy() == pytest.approx(expect, rel=1e-14)


def test_sphere_sphere_contact_detail_is_exact_and_walls_are_negative():
    sim = sphere_sim(2, spacing=0.9)                # overlap 0.1
    box_wall(sim, (5, 1, 5), (0, -1.45, 0))         # floor top at y = -0.45: overlap 0.05
    c = sim.detect_contacts()
    pair = (c["body_a"] == 0) & (c["body_b"] == 1)
    assert pair.sum() == 1
    assert c["depth"][pair][0] == pytest.approx(0.1, abs=1e-15)
    np.testing.assert_allclose(c["normal"][pair][0], [-1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(c["point"][pair][0], [0.45, 0, 0], atol=1e-15)
    walls = c["body_b"] < 0
    assert np.array_equal(c["body_b"][walls], [-1, -1])
    np.testing.assert_allclose(c["depth"][walls], 0.05, atol=1e-15)
    np.testing.assert_allclose(c["normal"][walls], [[0, 1, 0]] * 2, atol=1e-15)
    assert sim.compute_overlaps() == pytest.approx(0.1, abs=1e-15)
    ov = sim.overlap_pairs()
    assert list(zip(ov["body_a"], ov["body_b"])) == [(0, -1), (0, 1), (1, -1)]


def test_contacts_do_not_depend_on_capacity_and_buffers_grow():
    rng = np.random.default_rng(1)
    n = 60
    sim = Simulation(1)
    sim.add_sphere_shape(0.5)
    sim.set_positions(rng.uniform(0, 4, size=(n, 3)))
    sim.set_shape_ids(np.zeros(n, int))
    box_wall(sim, (3, 3, 3), (2, 2, 2), invert=True)   # a container
    ref = None
    for cap in (1, 7, 10 ** 5):
        sim.set_contact_capacity(cap)
        c = sim.detect_contacts()
        assert sim.contact_capacity >= min(cap, 1)
        if ref is None:
            ref = c
            assert len(c["depth"]) > n              # crowded: many pairs and wall contacts
        else:
            for k in ref:
                assert np.array_equal(ref[k], c[k])
    sim.set_contact_capacity(1)
    sim.set_gravity(0, -9.81, 0)
    for _ in range(5):
        sim.step(1e-3)
    assert sim.contact_capacity >= sim.num_contacts()


def test_periodic_pair_is_found_across_the_boundary():
    sim = Simulation()
    sim.add_sphere_shape(0.5)
    sim.set_domain((0, 0, 0), (5, 5, 5))
    sim.enable_periodicity(True, False, False)
    sim.set_positions([[0.2, 2, 2], [4.7, 2, 2]])   # 0.5 apart through x = 0
    sim.set_shape_ids([0, 0])
    c = sim.detect_contacts()
    assert len(c["depth"]) == 1
    assert c["depth"][0] == pytest.approx(0.5, abs=1e-12)
    np.testing.assert_allclose(c["normal"][0], [1, 0, 0], atol=1e-15)
    sim.set_velocities([[-1.0, 0, 0], [0, 0, 0]])
    sim.step(0.5)
    assert 0.0 <= sim.get_positions()[0, 0] < 5.0   # wrapped


def _pile(seed=3, n=40):
    rng = np.random.default_rng(seed)
    sim = Simulation(1)
    sim.add_sphere_shape(0.3)
    sim.add_sphere_shape(0.2)
    sim.set_positions(rng.uniform([0, 0.5, 0], [3, 6, 3], size=(n, 3)))
    sim.set_shape_ids(rng.integers(0, 2, n))
    sim.set_gravity(0, -9.81, 0)
    sim.set_domain((0, -1, 0), (3, 10, 3))
    sim.enable_periodicity(True, False, True)
    box_wall(sim, (10, 1, 10), (1.5, -1, 1.5), e=0.3, mu=0.4)
    sim.set_dt(2e-3)
    return sim


def _stepped_and_reloaded(tmp_path, steps):
    # a pile after ``steps`` steps, and its copy through save + load
    a = _pile()
    for _ in range(steps):
        a.step()
    path = tmp_path / "state.npz"
    a.save(path)
    return a, Simulation.load(path)


def test_save_load_resumes_bitwise(tmp_path):
    a, b = _stepped_and_reloaded(tmp_path, 60)
    for _ in range(60):
        a.step()
        b.step()
    for get in ("get_positions", "get_quaternions", "get_velocities",
                "get_angular_velocities"):
        assert np.array_equal(getattr(a, get)(), getattr(b, get)())
    assert a.num_contacts() > 0
    assert not list(tmp_path.glob(".peclet-*"))     # the temp file was renamed away


def test_non_finite_state_stops_the_step_naming_the_particle():
    sim = sphere_sim(3, spacing=3.0)
    sim.set_inv_mass([0.0, 1.0, 1.0])              # particle 0 ignores gravity
    sim.set_gravity(0.0, -1e308, 0.0)
    with pytest.raises(StepError, match="step 1: particle 1 has a non-finite state"):
        sim.step(1e10)                              # v = g dt overflows to -inf
    assert sim.step_count == 0
    assert np.all(np.isfinite(sim.get_velocities()))


def test_state_hash_sees_one_bit_of_any_field(tmp_path):
    a, b = _stepped_and_reloaded(tmp_path, 20)
    assert b.state_hash() == a.state_hash()
    for getter, setter in ((b.get_positions, b.set_positions),
                           (b.get_quaternions, b.set_quaternions),
                           (b.get_velocities, b.set_velocities),
                           (b.get_angular_velocities, b.set_angular_velocities)):
        x = np.array(getter(), dtype=np.float64)
        flipped = x.copy()
        flipped[5, 1] = np.nextafter(flipped[5, 1], np.inf)
        setter(flipped)
        assert b.state_hash() != a.state_hash()
        setter(x)
        assert b.state_hash() == a.state_hash()
