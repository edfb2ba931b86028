"""Torque-free rigid rotation (peclet.dem.rigid): conservation, the Dzhanibekov flip period
against the elliptic-integral closed form and a tight ODE solve, second-order convergence,
exact discrete solutions of special cases, locked axes, determinism, argument checks."""
import math

import numba
import numpy as np
import pytest

from peclet.core.geom import transforms
from peclet.core.validation import PecletArgumentError
from peclet.dem import rigid
from peclet_verify.reference import rotor

# The asymmetric body of the brief: moments 1, 2, 3; spin mostly about the intermediate axis.
IINV = np.array([1.0, 1.0 / 2.0, 1.0 / 3.0])
Q0 = transforms.quat_normalize(np.array([0.1, -0.2, 0.3, 0.9]))
OMEGA_BODY0 = np.array([0.05, 10.0, 0.05])
DTS = (4e-3, 2e-3, 1e-3, 5e-4)


def _omega_world0():
    return transforms.quat_rotate(Q0, OMEGA_BODY0)


def _unit(v):
    return v / np.linalg.norm(v)


# ---------------------------------------------------------------------------- quaternion helpers

def _axis_angle_matrix(axis, angle):
    # Rodrigues' formula: an independent construction of the rotation matrix.
    k = _unit(axis)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * (K @ K)


def test_quaternion_kernels_match_independent_formulas():
    rng = np.random.default_rng(7)
    for _ in range(20):
        axis, angle = rng.normal(size=3), rng.uniform(-math.pi, math.pi)
        k = _unit(axis)
        q = np.array([*(math.sin(angle / 2) * k), math.cos(angle / 2)])
        v = rng.normal(size=3)
        R = transforms.quat_to_matrix(q)
        np.testing.assert_allclose(R, _axis_angle_matrix(axis, angle), atol=1e-14)
        np.testing.assert_allclose(transforms.quat_rotate(q, v), R @ v, atol=1e-14)
        np.testing.assert_allclose(transforms.quat_rotate_inv(q, v), R.T @ v, atol=1e-14)
        # matrix -> quaternion recovers q up to the sign (w >= 0 chosen)
        back = transforms.matrix_to_quat(R)
        np.testing.assert_allclose(back, q * np.sign(q[3]), atol=1e-14)
        iinv = rng.uniform(0.1, 2.0, size=3)
        np.testing.assert_allclose(rigid.world_inv_inertia(q, iinv), R @ np.diag(iinv) @ R.T,
                                   atol=1e-14)
        w = rng.normal(size=3)
        Lw = R @ np.diag(1.0 / iinv) @ R.T @ w
        np.testing.assert_allclose(rigid.angular_momentum_world(q, w, iinv), Lw, rtol=1e-13)
        np.testing.assert_allclose(rigid.body_angular_momentum(q, w, iinv), R.T @ Lw,
                                   rtol=1e-13, atol=1e-14)
        assert rigid.kinetic_energy_rot(q, w, iinv) == pytest.approx(0.5 * w @ Lw, rel=1e-13)
    # Hamilton product composes rotations: R(a b) = R(a) R(b).
    a = transforms.quat_normalize(rng.normal(size=4))
    b = transforms.quat_normalize(rng.normal(size=4))
    np.testing.assert_allclose(transforms.quat_to_matrix(transforms.quat_multiply(a, b)),
                               transforms.quat_to_matrix(a) @ transforms.quat_to_matrix(b),
                               atol=1e-14)
    # A rotation of +pi/2 about z takes x to y (active rotation, (x, y, z, w) order).
    qz = np.array([0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4)])
    np.testing.assert_allclose(transforms.quat_rotate(qz, np.array([1.0, 0.0, 0.0])),
                               [0, 1, 0], atol=1e-15)


def test_normalisation_is_the_plain_formula_and_survives_any_magnitude():
    rng = np.random.default_rng(3)
    for _ in range(500):
        q = rng.normal(size=4) * 10.0 ** rng.uniform(-100, 100)
        x, y, z, w = (float(c) for c in q)
        n = math.sqrt(x * x + y * y + z * z + w * w)   # the plain formula, in this order
        assert np.array_equal(transforms.quat_normalize(q), q / n)   # same bits
    for scale in (1e200, 1e-200, 1e308, 5e-324):
        np.testing.assert_array_equal(transforms.quat_normalize(np.full(4, scale)), [0.5] * 4)
    np.testing.assert_array_equal(transforms.as_quaternion([1e200] * 4), [0.5] * 4)
    np.testing.assert_array_equal(transforms.as_quaternion([0, 0, 1e-200, 0]), [0, 0, 1, 0])
    assert transforms.quat_norm(np.array([3e300, 4e300, 0.0, 0.0])) == pytest.approx(5e300)
    out, bad = transforms.normalize_rows(np.array([[0, 0, 0, 2.0], [0, 0, 0, 0], [1, 0, 0, 0]]))
    assert bad == 1
    for q in (np.zeros(4), np.array([0, np.nan, 0, 1.0]), np.array([np.inf, 0, 0, 1.0])):
        with pytest.raises(PecletArgumentError, match="^q must be a finite, non-zero"):
            transforms.quat_normalize(q)
        with pytest.raises(PecletArgumentError, match="^rotation must be"):
            transforms.as_quaternion(q)


# ---------------------------------------------------------------------------- conservation

def test_asymmetric_body_conserves_world_momentum_and_energy_over_10000_steps():
    w0 = _omega_world0()
    quats, omegas, L_body = rotor.integrate_free_rotor(Q0, w0, IINV, 5e-4, 10_000)
    L0 = rigid.angular_momentum_world(Q0, w0, IINV)
    E0 = rigid.kinetic_energy_rot(Q0, w0, IINV)
    # The run must actually pass through a flip, or conservation would be trivially easy.
    assert L_body[:, 1].min() < -0.9 * abs(L_body[0, 1])
    worst_L = worst_E = 0.0
    for i in range(0, 10_001, 500):
        L = rigid.angular_momentum_world(quats[i], omegas[i], IINV)
        E = rigid.kinetic_energy_rot(quats[i], omegas[i], IINV)
        worst_L = max(worst_L, np.linalg.norm(L - L0) / np.linalg.norm(L0))
        worst_E = max(worst_E, abs(E - E0) / E0)
    assert worst_L < 1e-8 and worst_E < 1e-8
    # Measured ~1e-12: the conservation is structural, not approximate; keep a tight guard.
    assert worst_L < 1e-10 and worst_E < 1e-10
    norms = np.linalg.norm(quats, axis=1)
    assert np.abs(norms - 1.0).max() < 1e-15 * 4


# ---------------------------------------------------------------------------- flip period

def _measured_period(dt, t_end):
    n = int(round(t_end / dt))
    _, _, L = rotor.integrate_free_rotor(Q0, _omega_world0(), IINV, dt, n)
    t = np.arange(n + 1) * dt
    dLdt = np.cross(L, IINV * L)  # Euler's equations give the exact sample derivative
    up = rotor.crossing_times(t, L[:, 1], dLdt[:, 1], direction=+1)
    return rotor.period_from_crossings(up), up.size


def test_closed_form_period_matches_tight_ode_solve():
    L0 = OMEGA_BODY0 / IINV
    T = rotor.free_rotor_period(IINV, L0)
    ups = rotor.euler_reference_crossings(IINV, L0, 3.3 * T, component=1, direction=+1)
    assert ups.size == 3
    T_ivp = rotor.period_from_crossings(ups)
    assert abs(T_ivp - T) / T < 1e-9
    # The other branch (M^2 < 2 E I2, orbit round the I1 axis) and arbitrary axis order.
    L_other = np.array([20.0, 0.3, 0.4])
    perm = [2, 0, 1]
    T2 = rotor.free_rotor_period(IINV[perm], L_other[perm])
    ups2 = rotor.euler_reference_crossings(IINV, L_other, 3.3 * T2, component=2, direction=+1)
    assert abs(rotor.period_from_crossings(ups2) - T2) / T2 < 1e-9
    with pytest.raises(ValueError, match="inv_inertia_body"):
        rotor.free_rotor_period([1.0, 1.0, 0.5], L0)


def test_flip_period_matches_references_and_converges_at_second_order():
    L0 = OMEGA_BODY0 / IINV
    T_exact = rotor.free_rotor_period(IINV, L0)
    T_ivp = rotor.period_from_crossings(
        rotor.euler_reference_crossings(IINV, L0, 3.3 * T_exact, component=1, direction=+1))
    errors = []
    for dt in DTS:
        T, count = _measured_period(dt, 3.3 * T_exact)
        assert count == 3
        errors.append(abs(T - T_exact) / T_exact)
        if dt == 5e-4:
            assert abs(T - T_exact) / T_exact < 1e-4
            assert abs(T - T_ivp) / T_ivp < 1e-4
    orders = [math.log2(errors[i] / errors[i + 1]) for i in range(len(errors) - 1)]
    for p in orders:
        assert abs(p - 2.0) < 0.3, (errors, orders)


# ---------------------------------------------------------------------------- exact special cases

def test_spin_about_a_principal_axis_is_stationary_and_turns_by_the_cayley_angle():
    dt, n = 1e-3, 2000
    for iinv, axis in ((np.array([1.0, 1.0, 0.5]), 2),   # axisymmetric, symmetry axis
                       (np.array([1.0, 0.5, 0.25]), 2),  # asymmetric, major axis
                       (np.array([1.0, 0.5, 0.25]), 0)):  # asymmetric, minor axis
        wb = np.zeros(3)
        wb[axis] = 7.0
        w0 = transforms.quat_rotate(Q0, wb)
        quats, omegas, _ = rotor.integrate_free_rotor(Q0, w0, iinv, dt, n)
        # Round-off of the world->body->world round trip accumulates ~eps per step (measured
        # 7e-13 relative after 2000 steps).
        np.testing.assert_allclose(omegas, np.broadcast_to(w0, omegas.shape), rtol=0, atol=1e-11)
        # Discrete exact solution: each step is the Cayley rotation by 2 atan(dt w / 2).
        dq = transforms.quat_multiply(np.array([-Q0[0], -Q0[1], -Q0[2], Q0[3]]), quats[-1])
        angle = 2.0 * math.atan2(np.linalg.norm(dq[:3]), dq[3])
        expected = (n * 2.0 * math.atan(0.5 * dt * 7.0)) % (2.0 * math.pi)
        assert abs(angle - expected) < 1e-11
        np.testing.assert_allclose(_unit(dq[:3]) * np.sign(dq[:3][axis]), np.eye(3)[axis],
                                   atol=1e-12)


def test_axisymmetric_precession_rate_is_the_exact_discrete_one():
    # I1 = I2: body L precesses about e3 at rate Omega = L3 (1/I3 - 1/I1) (clockwise); the
    # midpoint rule maps this linear flow to the Cayley rotation by 2 atan(Omega dt / 2) per step.
    iinv = np.array([1.0, 1.0, 0.4])
    wb = np.array([1.5, 0.0, 6.0])
    L3 = wb[2] / iinv[2]
    Omega = L3 * (iinv[2] - iinv[0])
    dt, n = 2e-3, 3000
    _, _, L = rotor.integrate_free_rotor(Q0, transforms.quat_rotate(Q0, wb), iinv, dt, n)
    phi = np.unwrap(np.arctan2(L[:, 1], L[:, 0]))
    expected = -np.arange(n + 1) * 2.0 * math.atan(0.5 * Omega * dt)
    assert np.abs(phi - expected).max() < 1e-10
    assert np.abs(L[:, 2] - L3).max() < 1e-11 * L3


def test_time_reversal_returns_to_start():
    w0 = _omega_world0()
    q, w = Q0.copy(), w0.copy()
    for _ in range(200):
        q, w = rigid.advance_rotation(q, w, IINV, 2e-3)
    for _ in range(200):
        q, w = rigid.advance_rotation(q, w, IINV, -2e-3)
    np.testing.assert_allclose(q, Q0, atol=1e-13)
    np.testing.assert_allclose(w, w0, atol=1e-12)


def test_large_step_newton_fallback_keeps_the_invariants():
    # dt |omega| ~ 2: the fixed-point map no longer contracts; Newton solves the midpoint.
    wb = np.array([3.0, 10.0, 3.0])
    w0 = transforms.quat_rotate(Q0, wb)
    quats, omegas, _ = rotor.integrate_free_rotor(Q0, w0, IINV, 0.2, 200)
    E0, L0 = rigid.kinetic_energy_rot(Q0, w0, IINV), rigid.angular_momentum_world(Q0, w0, IINV)
    E = rigid.kinetic_energy_rot(quats[-1], omegas[-1], IINV)
    L = rigid.angular_momentum_world(quats[-1], omegas[-1], IINV)
    assert abs(E - E0) / E0 < 1e-12
    assert np.linalg.norm(L - L0) / np.linalg.norm(L0) < 1e-12
    # dt |omega| ~ 6: the midpoint equation has no real root (documented); the Cayley form still
    # conserves the world angular momentum exactly, the energy is not claimed.
    quats, omegas, _ = rotor.integrate_free_rotor(Q0, w0, IINV, 0.5, 200)
    L = rigid.angular_momentum_world(quats[-1], omegas[-1], IINV)
    assert np.linalg.norm(L - L0) / np.linalg.norm(L0) < 1e-12
    assert np.all(np.isfinite(omegas))


# ---------------------------------------------------------------------------- locked axes

def test_fully_locked_body_never_rotates():
    w0 = np.array([1.0, -2.0, 3.0])
    q1, w1 = rigid.advance_rotation(Q0, w0, np.zeros(3), 1e-2)
    assert np.array_equal(q1, Q0) and np.array_equal(w1, w0)


def test_partially_locked_body_keeps_locked_component_zero_and_free_ones_constant():
    iinv = np.array([0.0, 0.5, 1.0 / 3.0])  # infinite moment about body x
    wb = np.array([2.0, 3.0, -1.0])
    quats, omegas, _ = rotor.integrate_free_rotor(Q0, transforms.quat_rotate(Q0, wb), iinv, 1e-3, 500)
    body = np.array([transforms.quat_rotate_inv(q, w) for q, w in zip(quats[1:], omegas[1:])])
    assert np.abs(body[:, 0]).max() < 1e-14
    np.testing.assert_allclose(body[:, 1:], np.broadcast_to(wb[1:], body[:, 1:].shape), atol=1e-12)
    E = [rigid.kinetic_energy_rot(q, w, iinv) for q, w in zip(quats[1:], omegas[1:])]
    assert np.ptp(E) < 1e-12 * E[0]
    # Planar lock (x and y locked): a spin about world z stays one, rotating q about z.
    q2, w2 = Q0.copy(), transforms.quat_rotate(Q0, np.array([0.0, 0.0, 4.0]))
    for _ in range(100):
        q2, w2 = rigid.advance_rotation(q2, w2, np.array([0.0, 0.0, 2.0]), 1e-3)
    np.testing.assert_allclose(w2, transforms.quat_rotate(Q0, np.array([0.0, 0.0, 4.0])), atol=1e-13)


# ---------------------------------------------------------------------------- batch, determinism

def test_batch_is_bitwise_identical_at_1_and_2_threads_and_equals_scalar():
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.fail("NUMBA_NUM_THREADS < 2: the thread-count determinism check cannot run")
    rng = np.random.default_rng(3)
    n = 4001
    quats0 = rng.normal(size=(n, 4))
    quats0 /= np.linalg.norm(quats0, axis=1)[:, None]
    omegas0 = rng.normal(scale=5.0, size=(n, 3))
    iinv = rng.uniform(0.2, 3.0, size=(n, 3))
    iinv[::7, 0] = 0.0       # some partially locked bodies
    iinv[::11, :] = 0.0      # and some fully locked ones
    results = []
    old = numba.get_num_threads()
    try:
        for threads in (1, 2, 1, 2):
            numba.set_num_threads(threads)
            q, w = quats0.copy(), omegas0.copy()
            for _ in range(5):
                rigid.advance_rotations(q, w, iinv, 1e-3)
            results.append((q, w))
    finally:
        numba.set_num_threads(old)
    for q, w in results[1:]:
        assert np.array_equal(q, results[0][0]) and np.array_equal(w, results[0][1])
    for i in (0, 7, 11, 1234, n - 1):
        qs, ws = quats0[i], omegas0[i]
        for _ in range(5):
            qs, ws = rigid.advance_rotation(qs, ws, iinv[i], 1e-3)
        assert np.array_equal(qs, results[0][0][i]) and np.array_equal(ws, results[0][1][i])


def test_bad_arguments_raise_value_error():
    w = np.ones(3)
    with pytest.raises(ValueError, match="inv_inertia_body"):
        rigid.advance_rotation(Q0, w, np.array([1.0, -1.0, 1.0]), 1e-3)
    with pytest.raises(ValueError, match="inv_inertia_body"):
        rigid.advance_rotation(Q0, w, np.array([1.0, np.nan, 1.0]), 1e-3)
    with pytest.raises(ValueError, match="dt"):
        rigid.advance_rotation(Q0, w, IINV, np.nan)
    with pytest.raises(ValueError, match="non-zero quaternion"):
        rigid.advance_rotation(np.zeros(4), w, IINV, 1e-3)
    with pytest.raises(ValueError, match="omega"):
        rigid.advance_rotation(Q0, np.array([0.0, np.inf, 0.0]), IINV, 1e-3)
    quats = np.tile(Q0, (3, 1))
    quats[1] = 0.0
    with pytest.raises(ValueError, match="non-zero quaternion") as info:
        rigid.advance_rotations(quats, np.ones((3, 3)), np.ones((3, 3)), 1e-3)
    assert info.value.argument == "quats" and info.value.value == 1  # the bad body is named
    with pytest.raises(ValueError, match=r"\(N, 4\)"):
        rigid.advance_rotations(np.zeros((3, 4)), np.zeros((2, 3)), np.ones((3, 3)), 1e-3)
