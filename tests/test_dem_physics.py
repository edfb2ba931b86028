"""peclet.dem against closed forms: impacts, bounces, rolling, friction on an incline, stacks."""
import numpy as np
import pytest

from peclet.core import geom
from peclet.core.geom.transforms import matrix_to_quat
from peclet.dem import Simulation

G = 9.81


def add_box_wall(sim, half, centre, rotation=None, invert=False, e=0.5, mu=0.5):
    b = geom.SceneBuilder()
    r = b.add_leaf("box", list(half), translation=list(centre), rotation=rotation)
    ni, nr, _, _ = b.encode()
    return sim.add_analytic_wall(ni, nr, r, invert, e, mu)


# binary restitution: tests/test_validation_sanity.py (validation/sanity.py item 1)


def test_drop_on_analytic_floor_first_apex():
    e, h0, r, dt = 0.7, 5.0, 0.5, 2e-4
    sim = Simulation(1)
    sim.add_sphere_shape(r)
    sim.set_positions([[0.0, r + h0, 0.0]])
    sim.set_shape_ids([0])
    sim.set_gravity(0, -G, 0)
    add_box_wall(sim, (10, 1, 10), (0, -1, 0), e=e, mu=0.5)
    sim.set_dt(dt)
    bounced, apex = False, 0.0
    for _ in range(int(2.4 / dt)):
        sim.step()
        vy = sim.get_velocities()[0, 1]
        y = sim.get_positions()[0, 1] - r
        if vy > 0:
            bounced = True
        if bounced:
            apex = max(apex, y)
            if vy < 0:
                break
    assert bounced
    assert apex / h0 == pytest.approx(e * e, rel=0.01)
    print(f"first apex / h0 = {apex / h0:.5f} (closed form {e * e})")


def test_slide_to_roll():
    v0, mu, r, dt = 3.0, 0.5, 0.5, 1e-3
    sim = Simulation(1)
    sim.add_sphere_shape(r)
    sim.set_positions([[0.0, r, 0.0]])
    sim.set_shape_ids([0])
    sim.set_inv_mass([1.0])
    sim.set_inv_inertia([[2.5 / r ** 2] * 3])       # solid sphere, unit mass
    sim.set_gravity(0, -G, 0)
    sim.set_velocities([[v0, 0, 0]])
    add_box_wall(sim, (100, 1, 100), (0, -1, 0), e=0.0, mu=mu)
    for _ in range(600):                            # rolling from t = 2 v0 / (7 mu g) = 0.175
        sim.step(dt)
    v = sim.get_velocities()[0]
    w = sim.get_angular_velocities()[0]
    slip = v[0] + w[2] * r                          # contact-point velocity (omega_z < 0)
    assert v[0] / v0 == pytest.approx(5 / 7, abs=1e-3)
    assert abs(slip) < 1e-6 * v0
    assert abs(sim.get_positions()[0, 1] - r) < 1e-6


def _block_probes(h, n=6):
    """Probes on the faces of a box of half-extents h, n per edge."""
    pts = []
    g = np.linspace(-1, 1, n)
    U, V = np.meshgrid(g, g, indexing="ij")
    for ax in range(3):
        o = [a for a in range(3) if a != ax]
        for s in (-1, 1):
            P = np.zeros((n * n, 3))
            P[:, ax] = s * h[ax]
            P[:, o[0]] = U.ravel() * h[o[0]]
            P[:, o[1]] = V.ravel() * h[o[1]]
            pts.append(P)
    return np.unique(np.round(np.concatenate(pts), 14), axis=0)


def _incline(mu, theta, t_end, dt=1e-3):
    h = np.array([0.2, 0.1, 0.15])
    b = geom.SceneBuilder()
    blk = b.add_leaf("box", list(h))
    ni, nr, _, _ = b.encode()
    sim = Simulation(1)
    sid = sim.add_scene_shape(ni, nr, blk, _block_probes(h), float(np.linalg.norm(h)))
    c, s = np.cos(theta), np.sin(theta)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])   # slope descends towards -x
    q = matrix_to_quat(R)
    add_box_wall(sim, (20, 1, 20), R @ [0, -1, 0], rotation=q, e=0.0, mu=mu)
    m = 1.0
    I = m / 3 * np.array([h[1] ** 2 + h[2] ** 2, h[0] ** 2 + h[2] ** 2, h[0] ** 2 + h[1] ** 2])
    x0 = R @ np.array([0.0, h[1], 0.0])
    sim.set_positions([x0])
    sim.set_shape_ids([sid])
    sim.set_quaternions([q])
    sim.set_inv_mass([1 / m])
    sim.set_inv_inertia([1 / I])
    sim.set_gravity(0, -G, 0)
    sim.set_material_params(0.0, 0.0, mu)
    steps = int(round(t_end / dt))
    for _ in range(steps):
        sim.step(dt)
    d = sim.get_positions()[0] - x0
    down = R @ np.array([-1.0, 0, 0])
    return float(d @ down), float(np.linalg.norm(d)), sim


def test_incline_block_sticks_when_mu_exceeds_tan_theta():
    theta = np.radians(20)                          # tan = 0.364
    along, dist, _ = _incline(0.5, theta, 2.0)
    assert dist < 1e-3


def test_incline_block_slides_when_mu_is_below_tan_theta():
    theta, mu, t = np.radians(20), 0.2, 1.0
    along, dist, sim = _incline(mu, theta, t)
    expect = 0.5 * G * (np.sin(theta) - mu * np.cos(theta)) * t * t
    print(f"slid {along:.5f}, closed form {expect:.5f}")
    assert along == pytest.approx(expect, rel=0.05)
    assert np.abs(sim.get_angular_velocities()).max() < 1e-2   # slides, does not tumble


def test_six_sphere_column_comes_to_rest_without_sinking():
    r, n = 0.5, 6
    sim = Simulation(1)
    sim.add_sphere_shape(r)
    sim.set_positions([[0, r + 2 * r * k, 0] for k in range(n)])
    sim.set_shape_ids(np.zeros(n, int))
    sim.set_gravity(0, -G, 0)
    sim.set_material_params(0.5, 0.0, 0.3)
    add_box_wall(sim, (10, 1, 10), (0, -1, 0), e=0.5, mu=0.3)
    for _ in range(500):
        sim.step(1e-3)
    v = np.abs(sim.get_velocities()).max()
    y = sim.get_positions()[:, 1]
    assert v < 1e-3
    np.testing.assert_allclose(y, r + 2 * r * np.arange(n), rtol=0, atol=1e-3)
    np.testing.assert_allclose(sim.get_positions()[:, [0, 2]], 0.0, atol=1e-9)


@pytest.mark.heavy
def test_lattice_bed_5x5x40_in_a_box_comes_to_rest_without_sinking():
    r, nx, ny = 0.5, 5, 40
    gap = 1e-3                                      # side clearance per sphere
    pitch = 2 * r + gap
    sim = Simulation(1)
    sim.add_sphere_shape(r)
    X, Y, Z = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nx), indexing="ij")
    order = np.argsort(Y.ravel(), kind="stable")   # bottom layer first
    P = np.column_stack([X.ravel() * pitch, Y.ravel() * 2 * r, Z.ravel() * pitch])[order]
    P[:, 0] += r + gap / 2
    P[:, 2] += r + gap / 2
    P[:, 1] += r
    sim.set_positions(P)
    sim.set_shape_ids(np.zeros(len(P), int))
    sim.set_gravity(0, -G, 0)
    sim.set_material_params(0.3, 0.0, 0.3)
    w = nx * pitch
    # the container: the complement of an open-topped box's interior
    add_box_wall(sim, (w / 2, 30.0, w / 2), (w / 2, 30.0, w / 2), invert=True, e=0.3, mu=0.3)
    for _ in range(1000):                           # 1 s; the slowest (column) mode of the
        sim.step(1e-3)                              # warm-started PGS decays by then
    v = np.abs(sim.get_velocities()).max()
    y = sim.get_positions()[:, 1].reshape(ny, nx * nx)
    print(f"max |v| {v:.2e}, bottom layer y - r {np.abs(y[0] - r).max():.2e}, "
          f"max spacing error {np.abs(np.diff(y, axis=0) - 2 * r).max():.2e}")
    assert v < 1e-3
    np.testing.assert_allclose(y[0], r, atol=1e-3)
    np.testing.assert_allclose(np.diff(y, axis=0), 2 * r, atol=1e-3)
