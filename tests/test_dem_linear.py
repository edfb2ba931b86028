"""The linear spring-dashpot law (peclet.dem.linear) through the contact-law seam.

Closed forms of the damped linear oscillator (written out in validation/linear_law.py and
peclet.dem.linear): restitution exactly e, contact time pi / (omega_0 sqrt(1 - zeta^2)), largest
overlap; a sliding sphere ends rolling at 5/7 of its speed; any thread count gives the same
bits; a save resumes bit for bit; bad parameters are refused naming them."""
import math
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from peclet.core import geom
from peclet.core.validation import PecletArgumentError
from peclet.dem import Simulation, scene_particle
from peclet.dem.linear import contact_time, damping_ratio, max_overlap
from validation import linear_law

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.parametrize("wall", [True, False], ids=["sphere-wall", "sphere-sphere"])
@pytest.mark.parametrize("e", [0.0, 0.1, 0.5, 0.9, 1.0])
def test_normal_impact_matches_the_closed_forms(e, wall):
    # Chung & Ooi tests 1 (wall) and 2 (two spheres) for the linear law, starting in touch,
    # at 400 steps a contact: e to 1e-3 absolute, contact time and largest overlap to 0.2%
    # (measured at most 4.5e-4, 0.11% and 0.13%: kick-drift's first-order error)
    r = linear_law.impact(e, wall)
    assert r["e"] == pytest.approx(e, abs=1e-3)
    if e > 0:
        assert r["t_contact"] == pytest.approx(r["t_contact_ref"], rel=2e-3)
    else:
        assert math.isinf(r["t_contact"])       # critically damped: never separates
    assert r["max_overlap"] == pytest.approx(r["max_overlap_ref"], rel=2e-3)


def test_restitution_error_shrinks_with_the_step():
    # the measured e and overlap converge on the closed forms (first order in dt: kick-drift
    # and the contact's start and end falling between steps; measured at 100 and 1600 steps)
    coarse, fine = (linear_law.impact(0.0, False, steps) for steps in (100, 1600))
    # (measured at e = 0: 5.3e-3 at 100 steps, 1.3e-3 at 400, 3.3e-4 at 1600)
    assert abs(fine["max_overlap"] / fine["max_overlap_ref"] - 1) < 5e-4
    assert abs(fine["max_overlap"] / fine["max_overlap_ref"] - 1) < \
        abs(coarse["max_overlap"] / coarse["max_overlap_ref"] - 1) / 8
    coarse, fine = (linear_law.impact(0.5, True, steps) for steps in (100, 1600))
    assert abs(fine["e"] - 0.5) < 1e-4 < abs(coarse["e"] - 0.5)


def test_closed_forms():
    assert damping_ratio(1.0) == 0.0 and damping_ratio(0.0) == 1.0
    z = damping_ratio(0.5)
    assert math.exp(-z * math.pi / math.sqrt(1 - z * z)) == pytest.approx(0.5, rel=1e-14)
    assert contact_time(4.0, 1.0) == pytest.approx(math.pi / 2)
    assert max_overlap(2.0, 4.0, 1.0) == pytest.approx(1.0)
    assert math.isinf(contact_time(4.0, 1.0, 0.0))


def _floor(sim, mu=0.5):
    b = geom.SceneBuilder()
    root = b.add_leaf("box", [5.0, 5.0, 5.0], translation=[0.0, -5.0, 0.0])
    ni, nr, _, _ = b.encode()
    return sim.add_analytic_wall(ni, nr, root, False, 0.5, mu)


def test_sliding_sphere_ends_rolling_at_five_sevenths():
    # Coulomb friction and the tangential spring: a solid sphere launched sliding without spin
    # on a floor ends rolling at 5/7 of its speed (rigid-body mechanics, any mu)
    sim = Simulation(1)
    sim.add_sphere_shape(0.1)
    m = 1.0
    sim.set_positions([[0.0, 0.1 - m * 9.81 / 1e5, 0.0]])    # at rest on its spring
    sim.set_inv_mass([1 / m])
    sim.set_inv_inertia([[1 / (0.4 * m * 0.01)] * 3])
    sim.set_velocities([[1.0, 0.0, 0.0]])
    sim.set_gravity(0.0, -9.81, 0.0)
    _floor(sim, mu=0.3)
    sim.set_contact_law("linear", kn=1e5)
    sim.advance(3000, 1e-4)            # friction decelerates at mu g: rolling after ~0.1 s
    # once it sticks, the undamped tangential spring rings (period ~0.02 s, +-1.3% of v; no
    # tangential dashpot in Cundall-Strack): the speeds are averaged over 0.1 s
    v, w = [], []
    for _ in range(1000):
        sim.advance(1, 1e-4)
        v.append(sim.get_velocities()[0, 0])
        w.append(sim.get_angular_velocities()[0, 2])
    assert np.mean(v) == pytest.approx(5.0 / 7.0, rel=3e-3)
    assert -np.mean(w) * 0.1 == pytest.approx(np.mean(v), rel=3e-3)   # rolling: v = -w_z r


def _pile_script(law_kwargs):
    return textwrap.dedent(f"""
        import math, numpy as np
        from peclet.core import geom
        from peclet.dem import Simulation, scene_particle, hertz
        hertz.PARALLEL_MIN = 0            # every per-row kernel on its parallel path
        hertz.PATCH_PARALLEL_MIN = 0
        hertz.DIST_PARALLEL_MIN = 0
        r = 0.01
        b = geom.SceneBuilder()
        s1 = b.add_leaf("sphere", [r], translation=[-1.5 * r, 0, 0])
        s2 = b.add_leaf("sphere", [r], translation=[1.5 * r, 0, 0])
        two = scene_particle.build(b, b.add_union(s1, s2), bounds=([-2.8 * r, -1.1 * r,
                                   -1.1 * r], [2.8 * r, 1.1 * r, 1.1 * r]), n=8,
                                   shell_resolution=40, target_shell_points=600, density=2500.0)
        sim = Simulation(12)
        ids = [two.register(sim), sim.add_sphere_shape(r)]
        rng = np.random.default_rng(3)
        # in touch from the start: the bodies slightly into the floor and into each other
        pos = [[-3 * r, 0.99 * r, 4 * r], [3.5 * r, 0.99 * r, 4.3 * r]]
        pos += [[(i % 4 - 1.5) * 1.98 * r, 0.99 * r + (i // 4) * 1.98 * r, 0.0]
                for i in range(10)]
        sim.set_shape_ids([ids[0]] * 2 + [ids[1]] * 10)
        sim.set_positions(np.array(pos) + rng.uniform(-1e-4, 1e-4, (12, 3)))
        sim.set_inv_mass([1 / two.mass] * 2 + [1 / (2500 * 4 / 3 * math.pi * r ** 3)] * 10)
        sim.set_velocities(rng.uniform(-0.05, 0.05, (12, 3)))
        sim.set_gravity(0, -9.81, 0)
        sim.set_material_params(0.4, 0.0, 0.5)
        fb = geom.SceneBuilder()
        root = fb.add_leaf("box", [1.0, 1.0, 1.0], translation=[0.0, -1.0, 0.0])
        ni, nr, _, _ = fb.encode()
        sim.add_analytic_wall(ni, nr, root, False, 0.4, 0.5)
        sim.set_contact_law("linear", **{law_kwargs!r})
        sim.advance(400, 5e-5)
        print(sim.state_hash(), sim.num_contacts())
    """)


def test_one_and_two_threads_give_the_same_bits():
    # spheres and composed two-ball bodies piling on a floor, every kernel forced parallel,
    # in fresh processes at 1 and 2 threads
    out = []
    for threads in ("1", "2"):
        env = dict(os.environ, NUMBA_NUM_THREADS=threads)
        r = subprocess.run([sys.executable, "-c", _pile_script({"kn": 2e3})], env=env,
                           cwd=ROOT, capture_output=True, text=True, timeout=1200)
        assert r.returncode == 0, r.stderr[-3000:]
        out.append(r.stdout.split())
    assert out[0] == out[1]
    assert int(out[0][1]) > 0                  # the pile touches


def _two_ball_sim():
    b = geom.SceneBuilder()
    ball = scene_particle.build(b, b.add_leaf("sphere", [0.5]), bounds=([-0.55] * 3,
                                [0.55] * 3), n=8, shell_resolution=32,
                                target_shell_points=400, density=1.0)
    sim = Simulation(2)
    sid = ball.register(sim)
    sim.set_shape_ids([sid])
    sim.set_positions([[0.0, 0.5 + 1e-3, 0.0]])
    sim.set_velocities([[0.0, -1.0, 0.0]])
    sim.set_inv_mass([1.0 / ball.mass])
    _floor(sim, 0.0)
    sim.set_material_params(0.5, 0.0, 0.0)
    sim.set_pair_material(0, 0, 0.5, 0.0, 0.0)
    return sim, ball.mass


def test_composed_ball_rebounds_at_e():
    # a CSG ball (a composed particle: its contact is a patch of the engine) on a floor
    # rebounds at e like the analytic sphere
    sim, m = _two_ball_sim()
    kn = 1e5
    sim.set_contact_law("linear", kn=kn)
    dt = math.pi * math.sqrt(m / kn) / 400
    sim.advance(int(3 * 400 + 1e-3 / dt) + 50, dt)
    assert sim.get_velocities()[0, 1] == pytest.approx(0.5, abs=5e-3)


def test_save_resumes_bit_for_bit(tmp_path):
    sim = Simulation(2)
    sim.add_sphere_shape(0.5)
    _floor(sim)
    sim.set_positions([[0.0, 0.499, 0.0], [0.05, 1.5, 0.0]])
    sim.set_velocities([[0.3, 0.0, 0.0], [0.0, -1.0, 0.0]])
    sim.set_shape_ids([0, 0])
    sim.set_gravity(0, -9.81, 0)
    sim.set_contact_law("linear", kn=1e5, kt=1e4, substeps=2)
    sim.advance(50, 1e-4)
    path = tmp_path / "run.npz"
    sim.save(path)
    sim.advance(100, 1e-4)
    back = Simulation.load(path)
    assert back.contact_engine.name == "linear"
    assert back.contact_engine.parameters == sim.contact_engine.parameters
    back.advance(100, 1e-4)
    assert back.state_hash() == sim.state_hash()


@pytest.mark.parametrize("kwargs, name", [({"kn": 0.0}, "kn"), ({"kn": -1.0}, "kn"),
                                          ({"kn": float("nan")}, "kn"),
                                          ({"kn": 1.0, "kt": -1.0}, "kt"),
                                          ({"kn": 1.0, "substeps": 0}, "substeps"),
                                          ({"kn": 1.0, "skin_frac": 0.0}, "skin_frac")])
def test_bad_parameters_are_refused(kwargs, name):
    sim = Simulation(1)
    with pytest.raises(PecletArgumentError, match=name):
        sim.set_contact_law("linear", **kwargs)


def test_unknown_law_and_too_large_step_are_refused():
    sim = Simulation(1)
    with pytest.raises(PecletArgumentError, match="law"):
        sim.set_contact_law("hooke")
    sim.add_sphere_shape(0.5)
    sim.set_positions([[0.0, 0.0, 0.0]])
    sim.set_contact_law("linear", kn=1e5)
    with pytest.raises(PecletArgumentError, match="dt"):
        sim.advance(1, 1e-2)                  # the contact time is 7e-3 s
    assert sim.step_count == 0 and np.all(sim.get_positions() == 0.0)
