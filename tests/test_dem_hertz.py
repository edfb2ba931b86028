"""The Hertz–Mindlin engine (peclet/dem/hertz.py, Simulation.step_hertz) against closed forms.

The analytic Hertz impact is written out here, independently of validation/chung_ooi.py:
delta_max = (15 m* v^2 / (16 E* sqrt R*))^(2/5), f_max = 4/3 E* sqrt(R*) delta_max^(3/2),
t_c = 2.868 (m*^2 / (R* E*^2 v))^(1/5) (the constant to the 4 digits quoted in the
literature, so t_c is checked to 0.1%).
"""
import math
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from peclet.core import geom
from peclet.core.validation import PecletArgumentError
from peclet.dem import Simulation, hertz
from validation import chung_ooi

G = 9.81


@pytest.fixture(autouse=True)
def _one_thread():
    # these runs have one to a few bodies: a parallel launch per kernel call costs more than it
    # saves on a shared machine (the results are the same bits at any count, see the
    # subprocess test below)
    import numba
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    yield
    numba.set_num_threads(before)


def _wall_right(sim, size, e, mu):
    # a box filling x > 0 near the origin: the plane x = 0, normal -x
    b = geom.SceneBuilder()
    root = b.add_leaf("box", [size, 10 * size, 10 * size], translation=[size, 0.0, 0.0])
    ni, nr, _, _ = b.encode()
    return sim.add_analytic_wall(ni, nr, root, False, e, mu)


def _floor(sim, size, e, mu):
    b = geom.SceneBuilder()
    root = b.add_leaf("box", [size, size, size], translation=[0.0, -size, 0.0])
    ni, nr, _, _ = b.encode()
    return sim.add_analytic_wall(ni, nr, root, False, e, mu)


def _sphere_sim(radii, pos, vel, rho, youngs, poisson):
    sim = Simulation(len(radii))
    for r in radii:
        sim.add_sphere_shape(r)
    sim.set_positions(pos)
    sim.set_shape_ids(list(range(len(radii))))
    masses = [rho * 4.0 / 3.0 * math.pi * r ** 3 for r in radii]
    sim.set_inv_mass([1.0 / m for m in masses])
    sim.set_velocities(vel)
    big = 100.0 * max(radii)
    sim.set_domain([-big] * 3, [big] * 3)
    sim.set_hertz_material(0, youngs, poisson)
    return sim, masses


def _run_impact(sim, gap, dt):
    """(delta_max, f_max, contact time) of the impact gap() follows (validation/chung_ooi.py's
    measurement)."""
    dmax, fmax, tc, _ = chung_ooi.follow_impact(sim, gap, dt, 100000)
    assert tc is not None, "the impact did not end"
    return dmax, fmax, tc


def _analytic(m, r, es, v):
    dmax = (15.0 * m * v * v / (16.0 * es * math.sqrt(r))) ** 0.4
    return dmax, 4.0 / 3.0 * es * math.sqrt(r) * dmax ** 1.5, \
        2.868 * (m * m / (r * es * es * v)) ** 0.2


def test_sphere_wall_elastic_impact_matches_hertz():
    # Chung & Ooi test 2, aluminium alloy: R 0.1 m, 0.2 m/s on a rigid plane
    r, E, nu, rho, v = 0.1, 7.0e10, 0.30, 2699.0, 0.2
    sim, (m,) = _sphere_sim([r], [[-r - 1e-7, 0, 0]], [[v, 0, 0]], rho, E, nu)
    _wall_right(sim, r, 1.0, 0.0)
    dmax_a, fmax_a, tc_a = _analytic(m, r, E / (1 - nu * nu), v)
    dmax, fmax, tc = _run_impact(sim, lambda: -sim.get_positions()[0, 0] - r, tc_a / 500)
    assert dmax == pytest.approx(dmax_a, rel=1e-4)
    assert fmax == pytest.approx(fmax_a, rel=1e-4)
    assert tc == pytest.approx(tc_a, rel=1e-3)
    assert -sim.get_velocities()[0, 0] == pytest.approx(v, rel=1e-6)   # elastic: e = 1


def test_sphere_sphere_elastic_impact_matches_hertz():
    # Chung & Ooi test 1, glass: R 0.01 m, each at 10 m/s towards the other
    r, E, nu, rho, v = 0.010, 4.8e10, 0.20, 2800.0, 10.0
    sim, (m, _) = _sphere_sim([r, r], [[-r - 1e-6, 0, 0], [r + 1e-6, 0, 0]],
                              [[v, 0, 0], [-v, 0, 0]], rho, E, nu)
    sim.set_material_params(1.0, 0.0, 0.0)
    es = 1.0 / (2 * (1 - nu * nu) / E)
    dmax_a, fmax_a, tc_a = _analytic(m / 2, r / 2, es, 2 * v)

    def gap():
        x = sim.get_positions()
        return x[1, 0] - x[0, 0] - 2 * r
    dmax, fmax, tc = _run_impact(sim, gap, tc_a / 500)
    assert dmax == pytest.approx(dmax_a, rel=1e-4)
    assert fmax == pytest.approx(fmax_a, rel=1e-4)
    assert tc == pytest.approx(tc_a, rel=1e-3)
    vel = sim.get_velocities()
    assert vel[0, 0] == pytest.approx(-v, rel=1e-6) and vel[1, 0] == pytest.approx(v, rel=1e-6)


def test_wall_with_material_id_and_mixed_body_materials():
    # a wall given a material id is no longer rigid: E* = 1 / (2 (1 - nu^2) / E) for a wall of
    # the sphere's own material
    r, E, nu, rho, v = 0.1, 7.0e10, 0.30, 2699.0, 0.2
    sim, (m,) = _sphere_sim([r], [[-r - 1e-7, 0, 0]], [[v, 0, 0]], rho, E, nu)
    w = _wall_right(sim, r, 1.0, 0.0)
    sim.set_wall_material_id(w, 4)
    sim.set_pair_material(0, 4, 1.0, 0.0, 0.0)
    sim.set_hertz_material(4, E, nu)
    dmax_a, fmax_a, tc_a = _analytic(m, r, E / (2 * (1 - nu * nu)), v)
    dmax, fmax, tc = _run_impact(sim, lambda: -sim.get_positions()[0, 0] - r, tc_a / 300)
    assert (dmax, fmax, tc) == pytest.approx((dmax_a, fmax_a, tc_a), rel=1e-3)
    # glass (id 0) against limestone (id 1), unequal radii
    (r0, E0, nu0, rho0), (r1, E1, nu1, rho1) = (0.01, 4.8e10, 0.2, 2800.0), \
        (0.02, 2.0e10, 0.25, 2500.0)
    sim, (m0, _) = _sphere_sim([r0, r1], [[-r0 - 1e-7, 0, 0], [r1 + 1e-7, 0, 0]],
                               [[1.0, 0, 0], [0, 0, 0]], rho0, E0, nu0)
    m1 = rho1 * 4 / 3 * math.pi * r1 ** 3
    sim.set_inv_mass([1 / m0, 1 / m1])
    sim.set_material_ids([0, 1])
    for a, b in ((0, 0), (0, 1), (1, 1)):
        sim.set_pair_material(a, b, 1.0, 0.0, 0.0)
    sim.set_hertz_material(1, E1, nu1)
    es = 1 / ((1 - nu0 ** 2) / E0 + (1 - nu1 ** 2) / E1)
    dmax_a, fmax_a, tc_a = _analytic(m0 * m1 / (m0 + m1), r0 * r1 / (r0 + r1), es, 1.0)

    def gap():
        x = sim.get_positions()
        return x[1, 0] - x[0, 0] - r0 - r1
    dmax, fmax, tc = _run_impact(sim, gap, tc_a / 300)
    assert (dmax, fmax, tc) == pytest.approx((dmax_a, fmax_a, tc_a), rel=1e-3)


@pytest.mark.parametrize("e", [0.3, 0.6, 0.9])
def test_damping_reproduces_restitution(e):
    r, E, nu, rho, v = 0.0025, 3.8e11, 0.23, 4000.0, 3.9     # C&O test 3, aluminium oxide
    sim, (m,) = _sphere_sim([r], [[-r - 1e-8, 0, 0]], [[v, 0, 0]], rho, E, nu)
    _wall_right(sim, r, e, 0.0)
    tc = _analytic(m, r, E / (1 - nu * nu), v)[2]
    _run_impact(sim, lambda: -sim.get_positions()[0, 0] - r, tc / 500)
    assert -sim.get_velocities()[0, 0] / v == pytest.approx(e, rel=2e-3)


def test_linear_spring_damping_formula_would_not_reproduce_e():
    # why the engine calibrates gamma: the EDEM/LIGGGHTS formula, on the clamped Hertz law,
    # rebounds faster than asked (the calibration ODE, not the engine)
    assert hertz.restitution_of(hertz.edem_gamma(0.3)) > 0.35
    assert hertz.restitution_of(hertz.damping_gamma(0.3)) == pytest.approx(0.3, abs=1e-9)


def test_coulomb_limit_while_sliding_then_rolling():
    # a solid sphere set down sliding (v0, no spin) on a floor: |F_t| = mu F_n while it slides
    # and it rolls at 5/7 v0 from t = 2 v0 / (7 mu g)
    r, E, nu, rho, mu, v0 = 0.01, 1e7, 0.3, 2500.0, 0.5, 0.5
    m = rho * 4 / 3 * math.pi * r ** 3
    es = E / (1 - nu * nu)
    d0 = (m * G / (4 / 3 * es * math.sqrt(r))) ** (2 / 3)       # static Hertz overlap
    sim, _ = _sphere_sim([r], [[0.0, r - d0, 0.0]], [[v0, 0, 0]], rho, E, nu)
    sim.set_gravity(0, -G, 0)
    _floor(sim, 10 * r, 0.5, mu)
    dt = 1e-4
    t_roll = 2 * v0 / (7 * mu * G)
    ratios = []
    for k in range(int(2 * t_roll / dt)):
        sim.step_hertz(1, dt)
        c = sim.hertz_contacts()
        assert len(c["depth"]) == 1
        fn = c["normal_force"][0]
        ft = c["force"][0] - fn * c["normal"][0]
        if (k + 1) * dt < 0.8 * t_roll:
            ratios.append(np.linalg.norm(ft) / fn)
        assert np.linalg.norm(ft) <= mu * fn * (1 + 1e-12)
    assert np.allclose(ratios, mu, rtol=1e-9)
    v = sim.get_velocities()[0, 0]
    w = sim.get_angular_velocities()[0, 2]
    assert v == pytest.approx(5 / 7 * v0, rel=0.01)
    assert -w * r == pytest.approx(v, rel=0.01)                  # rolling without slip


_THREAD_SCRIPT = textwrap.dedent("""
    import hashlib, math, sys
    import numpy as np
    from peclet.core import geom
    from peclet.dem import Simulation, hertz
    hertz.PARALLEL_MIN = int(sys.argv[1])
    rng = np.random.default_rng(3)
    n, r = 64, 0.01
    sim = Simulation(n)
    sim.add_sphere_shape(r)
    g = np.stack(np.meshgrid(np.arange(4), np.arange(4), np.arange(4), indexing="ij"), -1)
    pos = g.reshape(-1, 3) * 2.05 * r + rng.uniform(-2e-4, 2e-4, (n, 3))
    pos[:, 1] += r
    sim.set_positions(pos)
    sim.set_shape_ids(np.zeros(n, np.int64))
    sim.set_inv_mass(np.full(n, 1.0 / (2500 * 4 / 3 * math.pi * r ** 3)))
    sim.set_velocities(rng.uniform(-0.3, 0.3, (n, 3)))
    sim.set_domain([-1, -1, -1], [1, 1, 1])
    sim.set_gravity(0, -9.81, 0)
    sim.set_material_params(0.5, 0.0, 0.4)
    b = geom.SceneBuilder()
    root = b.add_leaf("box", [1, 0.1, 1], translation=[0, -0.1, 0])
    ni, nr, _, _ = b.encode()
    sim.add_analytic_wall(ni, nr, root, False, 0.6, 0.3)
    sim.set_hertz_material(0, 1e7, 0.3)
    sim.step_hertz(300, 1e-4)
    h = hashlib.sha256(sim.state_hash().encode())
    h.update(np.ascontiguousarray(sim.hertz_contacts()["tangential_displacement"]).tobytes())
    print(sim.num_contacts(), h.hexdigest())
""")


#: the three runs a same-bits test compares: the parallel kernels forced on every call at one
#: and at two threads, and the serial kernels at two threads
VARIANTS = ((1, 1), (2, 1), (2, 10 ** 9))


def run_thread_variants(script=None, variants=VARIANTS, timeout=600):
    """The output words of ``script`` (default the pile above) for each (threads,
    parallel_min) of ``variants``, the children run at the same time (they are independent;
    one after the other took most of these tests' time)."""
    procs = []
    for threads, parallel_min in variants:
        env = dict(os.environ, NUMBA_NUM_THREADS=str(threads))
        procs.append(subprocess.Popen(
            [sys.executable, "-c", script or _THREAD_SCRIPT, str(parallel_min)], env=env,
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True))
    outs = []
    try:
        for p in procs:
            out, err = p.communicate(timeout=timeout)
            assert p.returncode == 0, err
            outs.append(out.split())
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()
    return outs


def test_same_bits_at_1_and_2_threads_and_serial():
    par1, par2, ser2 = run_thread_variants()
    assert int(par1[0]) > 20           # a pile with many contacts, not a trivial run
    assert par1 == par2 == ser2


def _pile(skin, substeps_per_call):
    rng = np.random.default_rng(7)
    n, r = 27, 0.01
    sim, _ = _sphere_sim([r] * n, np.zeros((n, 3)), np.zeros((n, 3)), 2500.0, 1e7, 0.3)
    g = np.stack(np.meshgrid(*(np.arange(3),) * 3, indexing="ij"), -1).reshape(-1, 3)
    sim.set_positions(g * 2.05 * r + rng.uniform(-2e-4, 2e-4, (n, 3)) + [0, r, 0])
    sim.set_velocities(rng.uniform(-0.3, 0.3, (n, 3)))
    sim.set_gravity(0, -G, 0)
    sim.set_material_params(0.5, 0.0, 0.4)
    _floor(sim, 1.0, 0.6, 0.3)
    for _ in range(300 // substeps_per_call):
        sim.step_hertz(substeps_per_call, 1e-4, skin_frac=skin)
    return sim.num_contacts(), sim.state_hash()


def test_skin_sets_speed_not_result():
    # the candidate list's skin and its rebuild schedule (also cut by the call boundaries)
    # change which candidates are carried, never which touch nor their forces
    runs = [_pile(skin, k) for skin, k in ((0.02, 300), (0.1, 300), (1.0, 300), (0.1, 1))]
    assert runs[0][0] > 10
    assert len(set(runs)) == 1


def test_save_load_resumes_hertz_run_bitwise(tmp_path):
    # a sphere resting on a floor and pushed sideways below the Coulomb limit: the contact
    # sticks and the Mindlin spring's history carries the push, so it must survive the save
    r, E, nu, rho, mu = 0.01, 1e7, 0.3, 2500.0, 0.5
    m = rho * 4 / 3 * math.pi * r ** 3
    d0 = (m * G / (4 / 3 * E / (1 - nu * nu) * math.sqrt(r))) ** (2 / 3)
    sim, _ = _sphere_sim([r], [[0.0, r - d0, 0.0]], [[0, 0, 0]], rho, E, nu)
    sim.set_gravity(0, -G, 0)
    sim.set_external_forces([[0.2 * mu * m * G, 0, 0]])
    _floor(sim, 10 * r, 0.5, mu)
    sim.step_hertz(40, 1e-4)
    assert np.linalg.norm(sim.hertz_contacts()["tangential_displacement"]) > 0
    path = tmp_path / "h.npz"
    sim.save(path)
    other = Simulation.load(path)
    sim.step_hertz(60, 1e-4)
    other.step_hertz(60, 1e-4)
    assert other.state_hash() == sim.state_hash()
    # and the history mattered: a load with the history dropped ends elsewhere
    third = Simulation.load(path)
    third.world.hertz.clear_history()
    third.step_hertz(60, 1e-4)
    assert third.state_hash() != sim.state_hash()


def test_save_without_hertz_has_no_hertz_keys(tmp_path):
    sim = Simulation(1)
    sim.add_sphere_shape(0.5)
    sim.set_positions([[0, 1, 0]])
    sim.save(tmp_path / "s.npz")
    with np.load(tmp_path / "s.npz") as z:
        assert not any(k.startswith("hertz") for k in z.files)


def _one_sphere():
    sim, _ = _sphere_sim([0.01], [[0, 0.02, 0]], [[0, 0, 0]], 2500.0, 1e7, 0.3)
    return sim


@pytest.mark.parametrize("youngs", [-1e9, 0.0, float("nan"), float("inf")])
def test_bad_modulus(youngs):
    with pytest.raises(PecletArgumentError, match="youngs"):
        _one_sphere().set_hertz_material(0, youngs, 0.3)


@pytest.mark.parametrize("poisson", [-1.0, 0.5, 0.7, -2.0, float("nan")])
def test_bad_poisson(poisson):
    with pytest.raises(PecletArgumentError, match="poisson"):
        _one_sphere().set_hertz_material(0, 1e9, poisson)


def test_bad_material_id():
    with pytest.raises(PecletArgumentError, match="material_id"):
        _one_sphere().set_hertz_material(1024, 1e9, 0.3)


def test_dt_above_rayleigh_limit():
    sim = _one_sphere()
    r, rho, E, nu = 0.01, 2500.0, 1e7, 0.3
    tr = math.pi * r * math.sqrt(rho / (E / (2 * (1 + nu)))) / (0.1631 * nu + 0.8766)
    sim.step_hertz(1, 0.29 * tr)                               # under the limit: runs
    with pytest.raises(PecletArgumentError, match="Rayleigh"):
        sim.step_hertz(1, 0.31 * tr)


def test_undeclared_material():
    sim = _one_sphere()
    sim.set_material_ids([3])
    sim.set_pair_material(3, 3, 0.5, 0.0, 0.5)
    with pytest.raises(PecletArgumentError, match="set_hertz_material"):
        sim.step_hertz(1, 1e-6)
    sim.set_hertz_material(3, 1e9, 0.3)
    sim.step_hertz(1, 1e-6)


def test_wall_material_without_moduli():
    sim = _one_sphere()
    w = _floor(sim, 0.1, 0.5, 0.5)
    sim.set_wall_material_id(w, 5)
    sim.set_pair_material(0, 5, 0.5, 0.0, 0.5)
    with pytest.raises(PecletArgumentError, match="wall material id 5"):
        sim.step_hertz(1, 1e-6)


def test_other_bad_calls():
    sim = _one_sphere()
    with pytest.raises(PecletArgumentError, match="substeps"):
        sim.step_hertz(0, 1e-6)
    with pytest.raises(PecletArgumentError, match="dt"):
        sim.step_hertz(1)                                      # no dt given or set
    with pytest.raises(PecletArgumentError, match="skin_frac"):
        sim.step_hertz(1, 1e-6, skin_frac=-1)
    sim.set_material_params(0.0, 0.0, 0.5)
    with pytest.raises(PecletArgumentError, match="e_n"):
        sim.step_hertz(1, 1e-6)


def test_composed_particle_in_free_flight():
    # composed particles are accepted (their contacts: tests/test_dem_hertz_composed.py); one
    # far from everything falls freely: v = -g t after n substeps of the kick-drift
    b = geom.SceneBuilder()
    root = b.add_leaf("box", [0.01, 0.01, 0.01])
    ni, nr, _, _ = b.encode()
    sim = Simulation(1)
    sim.add_scene_shape(ni, nr, root, np.array([[0.01, 0.0, 0.0], [-0.01, 0, 0]]), 0.02)
    sim.set_positions([[0, 1, 0]])
    sim.set_gravity(0, -G, 0)
    sim.set_hertz_material(0, 1e9, 0.3)
    sim.step_hertz(10, 1e-7)
    assert sim.num_contacts() == 0
    assert sim.get_velocities()[0, 1] == pytest.approx(-G * 1e-6, rel=1e-12)


def test_load_refuses_a_partial_hertz_save(tmp_path):
    sim = _one_sphere()
    sim.save(tmp_path / "h.npz")
    with np.load(tmp_path / "h.npz") as z:
        d = {k: z[k] for k in z.files}
    assert "hertz_xi" in d
    del d["hertz_xi"]
    with open(tmp_path / "bad.npz", "wb") as fh:
        np.savez(fh, **d)
    with pytest.raises(PecletArgumentError, match="hertz_xi"):
        Simulation.load(tmp_path / "bad.npz")
