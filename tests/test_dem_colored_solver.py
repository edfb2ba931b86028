"""The coloured velocity solve and position projection (peclet/dem/solver.py, used from
``solver.COLORED_MIN_CONTACTS`` contacts on): a greedy colouring in contact order, no two
contacts of a colour sharing a body; each colour swept in parallel, the colours in alternating
order. It must give the bits of the serial sweep over the contacts in colour order, the same
bits at 1 and 2 threads, and the physics of the serial solve (a resting column stays at rest).
"""
import numba
import numpy as np
import pytest

from peclet.core import geom
from peclet.dem import Simulation, solver
from peclet.dem.contacts import Contacts, reorder

CAP = int(numba.config.NUMBA_NUM_THREADS)
DT, REST, SLOP = 2e-3, 0.04, 1e-4


def _random_contacts(rng, n_bodies=400, n=4000):
    """Contacts sorted by (a, b) like a detection's, with wall contacts, bodies of inverse
    mass and inertia 0, warm-start impulses, moving-wall velocities."""
    a = rng.integers(0, n_bodies - 1, n)
    b = np.minimum(a + 1 + rng.integers(0, 6, n), n_bodies - 1)
    a = np.minimum(a, b - 1)
    wall = rng.random(n) < 0.2
    b = np.where(wall, -1 - rng.integers(0, 2, n), b)
    o = np.lexsort((b, a))
    a, b = a[o], b[o]
    nrm = rng.normal(size=(n, 3))
    nrm /= np.linalg.norm(nrm, axis=1)[:, None]
    t1, t2 = solver.tangent_basis(nrm)
    ra = rng.normal(size=(n, 3)) * 0.3
    rb = np.where((b >= 0)[:, None], rng.normal(size=(n, 3)) * 0.3, 0.0)
    gap = rng.normal(size=n) * 0.01
    con = solver.Constraints(a, b, nrm, t1, t2, ra, rb, gap, rng.choice([0.0, 0.2, 0.8], n),
                             rng.choice([0.0, 0.3], n), rng.choice([0.0, 0.5, 1.0], n),
                             np.where((b < 0)[:, None], rng.normal(size=(n, 3)), 0.0))
    v = rng.normal(size=(n_bodies, 3))
    w = rng.normal(size=(n_bodies, 3))
    inv_mass = rng.random(n_bodies) + 0.5
    inv_inertia = rng.random((n_bodies, 3)) + 0.5
    inv_mass[::17] = 0.0
    inv_inertia[::17] = 0.0
    q = rng.normal(size=(n_bodies, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    lam = np.abs(rng.normal(size=(n, 3))) * (rng.random((n, 1)) < 0.5)
    return con, v, w, inv_mass, solver.world_inv_inertias(q, inv_inertia), q, lam


def _solve_and_project(con, lam, v, w, inv_mass, invI, q, colors):
    """(v, w, lam, vn, x, q) bytes after the velocity solve and the projection."""
    v, w, lam, q = v.copy(), w.copy(), lam.copy(), q.copy()
    vn = solver.solve(con, lam, v, w, inv_mass, invI, DT, REST, SLOP, 8, colors)
    x = np.ones((len(v), 3))
    solver.project(con, con.gap + DT * vn, inv_mass, invI, SLOP, 10, x, q, colors)
    return b"".join(a.tobytes() for a in (v, w, lam, vn, x, q))


def _in_order(con, order):
    return solver.Constraints(*[f[order] for f in con])


def test_the_colouring_is_greedy_in_contact_order_and_no_colour_shares_a_body():
    rng = np.random.default_rng(0)
    con = _random_contacts(rng)[0]
    order, start, body_start, body_items = solver.color_contacts(con.a, con.b, np.int64(400))
    colour = np.empty(len(con.a), np.int64)
    for k in range(len(start) - 1):
        members = order[start[k]:start[k + 1]]
        assert np.all(np.diff(members) > 0)             # contact order within a colour
        colour[members] = k
    assert sorted(order.tolist()) == list(range(len(con.a)))
    # the greedy rule, by a plain reference: the lowest colour free at both bodies (walls are
    # no bodies: two contacts of one body with different walls still differ)
    used = {}
    for i, (a, b) in enumerate(zip(con.a.tolist(), con.b.tolist())):
        taken = used.get(a, set()) | (used.get(b, set()) if b >= 0 else set())
        c = next(k for k in range(len(taken) + 1) if k not in taken)
        assert colour[i] == c, i
        used.setdefault(a, set()).add(c)
        if b >= 0:
            used.setdefault(b, set()).add(c)
    # each body's positions in the colour order, ascending
    pos_of = np.empty(len(order), np.int64)
    pos_of[order] = np.arange(len(order))
    for j in range(400):
        mine = np.flatnonzero((con.a == j) | (con.b == j))
        assert body_items[body_start[j]:body_start[j + 1]].tolist() == sorted(pos_of[mine])


def test_colors_for_switches_on_the_contact_count_alone():
    rng = np.random.default_rng(1)
    con = _random_contacts(rng, n=500)[0]
    assert solver.colors_for(con.a, con.b, 400) is None        # below the module threshold
    assert solver.COLORED_MIN_CONTACTS > 500
    assert solver.colors_for(con.a, con.b, 400, threshold=500) is not None
    assert solver.colors_for(con.a, con.b, 400, threshold=501) is None


@pytest.mark.parametrize("seed", [2, 3])
def test_the_coloured_solve_is_the_serial_sweep_in_colour_order(seed):
    rng = np.random.default_rng(seed)
    con, v, w, inv_mass, invI, q, lam = _random_contacts(rng)
    colors = solver.colors_for(con.a, con.b, len(v), threshold=0)
    assert len(colors.start) > 10                   # many colours, large and small ones
    pc, plam = _in_order(con, colors.order), lam[colors.order]
    coloured = _solve_and_project(pc, plam, v, w, inv_mass, invI, q, colors)
    serial = _solve_and_project(pc, plam, v, w, inv_mass, invI, q, None)
    assert coloured == serial
    # and it is not merely the serial sweep in contact order (the order does matter)
    assert _solve_and_project(con, lam, v, w, inv_mass, invI, q, None) != coloured


@pytest.mark.skipif(CAP < 2, reason="needs 2 numba threads")
def test_the_coloured_solve_has_the_same_bits_at_one_and_two_threads():
    rng = np.random.default_rng(4)
    con, v, w, inv_mass, invI, q, lam = _random_contacts(rng, n_bodies=3000, n=30000)
    colors = solver.colors_for(con.a, con.b, len(v), threshold=0)
    pc, plam = _in_order(con, colors.order), lam[colors.order]
    out = {}
    try:
        for t in (1, 2):
            numba.set_num_threads(t)
            out[t] = _solve_and_project(pc, plam, v, w, inv_mass, invI, q, colors)
    finally:
        numba.set_num_threads(CAP)
    assert out[1] == out[2]


def test_reorder_moves_whole_contact_rows():
    rng = np.random.default_rng(6)
    n = 3000
    c = Contacts(rng.integers(0, 50, n), rng.integers(-2, 50, n), rng.normal(size=(n, 3)),
                 rng.normal(size=(n, 3)), rng.normal(size=(n, 3)), rng.normal(size=n),
                 rng.integers(0, 1 << 30, n))
    order = rng.permutation(n)
    r = reorder(c, order)
    for got, field in zip(r, c):
        assert got.dtype == field.dtype and np.array_equal(got, field[order])


def _resting_column(nx=4, layers=10, r=0.5):
    """nx x nx columns of ``layers`` spheres resting on a floor wall, exactly touching."""
    sim = Simulation(nx * nx * layers)
    sim.add_sphere_shape(r)
    g = np.arange(nx) * 2.0 * r
    x, y, z = np.meshgrid(g, r + 2.0 * r * np.arange(layers), g, indexing="ij")
    sim.set_positions(np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1))
    sim.set_shape_ids(np.zeros(x.size, np.int64))
    sim.set_gravity(0.0, -9.81, 0.0)
    sim.set_material_params(0.2, 0.0, 0.5)
    b = geom.SceneBuilder()
    root = b.add_leaf("box", [20.0, 1.0, 20.0], translation=[0.0, -1.0, 0.0])
    ni, nr, _, _ = b.encode()
    sim.add_analytic_wall(ni, nr, root, False, 0.2, 0.5)
    sim.set_dt(DT)
    return sim


def _count_coloured(monkeypatch):
    calls = []
    real = solver.solve_velocities_colored

    def counting(*args):
        calls.append(len(args[0].a))
        return real(*args)

    monkeypatch.setattr(solver, "solve_velocities_colored", counting)
    return calls


def test_a_resting_column_stays_at_rest_on_the_coloured_path(monkeypatch):
    monkeypatch.setattr(solver, "COLORED_MIN_CONTACTS", 1)
    calls = _count_coloured(monkeypatch)
    r = 0.5
    sim = _resting_column(r=r)
    top0 = sim.get_positions()[:, 1].max()
    for _ in range(300):
        sim.step()
    assert len(calls) == 300 and min(calls) > 100       # every step on the coloured path
    pos = sim.get_positions()
    # (the serial path: overlap 8e-5, sinking 2.5e-4, speeds 2e-13; the coloured 1.6e-4,
    # 4.7e-4, 1.5e-8)
    assert sim.compute_overlaps() < 2e-3 * r              # overlaps stay small
    assert top0 - pos[:, 1].max() < 4e-3 * r              # the top does not sink
    assert np.abs(pos[:, [0, 2]] - _resting_column(r=r).get_positions()[:, [0, 2]]).max() \
        < 1e-3 * r                                        # nothing slides sideways
    assert np.abs(sim.get_velocities()).max() < 1e-4      # and it is at rest


@pytest.mark.skipif(CAP < 2, reason="needs 2 numba threads")
def test_a_coloured_run_has_the_same_bits_at_one_and_two_threads(monkeypatch):
    monkeypatch.setattr(solver, "COLORED_MIN_CONTACTS", 1)
    calls = _count_coloured(monkeypatch)
    hashes = []
    try:
        for t in (1, 2):
            numba.set_num_threads(t)
            sim = _resting_column()
            v = np.random.default_rng(7).normal(size=(sim.num_particles(), 3))
            sim.set_velocities(v)                         # a stirred-up start
            for _ in range(60):
                sim.step()
            hashes.append(sim.state_hash())
    finally:
        numba.set_num_threads(CAP)
    assert len(calls) == 120
    assert hashes[0] == hashes[1]



def test_a_coloured_run_saved_and_resumed_equals_the_uninterrupted_one(monkeypatch, tmp_path):
    monkeypatch.setattr(solver, "COLORED_MIN_CONTACTS", 1)
    calls = _count_coloured(monkeypatch)

    def stirred():
        sim = _resting_column()
        sim.set_velocities(np.random.default_rng(8).normal(size=(sim.num_particles(), 3)))
        return sim

    ref = stirred()
    for _ in range(40):
        ref.step()
    run = stirred()
    for _ in range(20):
        run.step()
    run.save(str(tmp_path / "mid.npz"))
    resumed = Simulation.load(str(tmp_path / "mid.npz"))
    for _ in range(20):
        resumed.step()
    assert len(calls) == 80
    assert resumed.state_hash() == ref.state_hash()
