"""Detection does less work without changing a contact (issue 27 item 3, issue 22's stir).

- per-pair margins: a pair's speculative margin is its base plus what ITS two members (or the
  body and a moving wall near it) can close in a step, not the fastest body's speed;
- the broad phase's Verlet list: kept while every body stays inside its build sphere;
- wall distance grids: bounds that spare evaluations of a wall's tree;
- the parallel broad phase: the same arrays as the serial one.

The three work savers must leave every contact and every bit of a run as they were; the tests
run the same stirred column with each of them disabled and compare state hashes.
"""

import numba
import numpy as np
import pytest

from peclet.dem import Simulation, broadphase, distgrid
from peclet.core.geom.kernels import eval_point
from peclet.packing.experiments.stir import StirSpec, StirredColumn

from test_dem_moving_walls import _spheres

CAP = int(numba.config.NUMBA_NUM_THREADS)


def _new(n):
    sim = Simulation(n)
    sim.set_gravity(0.0, 0.0, 0.0)
    sim.set_dt(1e-2)
    return sim


def test_a_fast_body_does_not_widen_the_margin_of_a_slow_pair():
    # two slow spheres 0.1 apart, one fast sphere far away: with one global margin
    # (base + 2 v_max dt = 0.025 + 0.2) the slow pair would be a speculative contact
    sim = _new(3)
    _spheres(sim, [(0.0, 0.0, 0.0), (1.1, 0.0, 0.0), (20.0, 0.0, 0.0)],
             vel=[(0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (10.0, 0.0, 0.0)])
    assert len(sim.detect_contacts()["body_a"]) == 0
    # the fast body's own pairs do get its reach (0.025 + 10 x 0.01): a sphere 0.1 from it
    sim2 = _new(2)
    _spheres(sim2, [(0.0, 0.0, 0.0), (1.1, 0.0, 0.0)],
             vel=[(0.0, 0.0, 0.0), (-10.0, 0.0, 0.0)])
    c = sim2.detect_contacts()
    assert len(c["body_a"]) == 1 and c["depth"][0] == pytest.approx(-0.1)


def test_a_moving_wall_widens_only_the_margins_of_bodies_it_can_reach():
    from peclet.core.geom import SceneBuilder
    sim = _new(3)
    b = SceneBuilder()
    root = b.add_leaf("box", [5.0, 0.5, 5.0])
    ni, nr, _, _ = b.encode()
    w = sim.add_analytic_wall(ni, nr, root, False, 0.0, 0.5)
    # the plate (top face at y = 0.5) turns about the z axis through its end x = -5 at
    # 4 rad per unit time: its surface moves at 4 |x + 5|, 0.4 per step at the far end and
    # 4 |omega| r more over a sphere (0.089 with the base margin near the axis). Spheres sit
    # 0.1 above it at both ends, and a third 0.1 beside the
    # first: only the far sphere's wall pair may be speculative.
    _spheres(sim, [(-4.9, 1.1, 0.0), (4.5, 1.1, 0.0), (-4.9, 1.1, 1.1)],
             vel=[(0.0, 0.0, 0.0)] * 3)
    sim.set_wall_velocity(w, (0.0, 0.0, 0.0), (0.0, 0.0, 4.0), (-5.0, 0.0, 0.0))
    c = sim.detect_contacts()
    assert list(zip(c["body_a"].tolist(), c["body_b"].tolist())) == [(1, -1)]
    assert c["depth"][0] == pytest.approx(-0.1, abs=1e-9)


def _column(seed=3):
    spec = StirSpec(grain_radius=1.0, revolutions=0.05, settle=0.2, frames=0,
                    seed=seed).checked()
    col = StirredColumn(spec)
    sim = col.build()
    return spec, col, sim


def _count_builds(monkeypatch):
    # [n]: how many times the broad phase builds its pair list from here on
    builds = [0]
    real = broadphase.pairs

    def counted(*a):
        builds[0] += 1
        return real(*a)

    monkeypatch.setattr(broadphase, "pairs", counted)
    return builds


def _stir_hash(steps, *, skin=True, wall_grids=True, threads=1, monkeypatch=None):
    numba.set_num_threads(threads)
    try:
        spec, col, sim = _column()
        det = sim.world.detector
        builds = _count_builds(monkeypatch)
        monkeypatch.setattr(distgrid, "WALL_GRID_MIN_TASKS", 1000 if wall_grids else 10 ** 12)
        for k in range(steps):
            if k == steps // 3:
                col.turn(spec.omega)
            if not skin:
                det._pairs = None                # a fresh broad phase every step
            sim.step()
        walled = det._walled[1]
        has_grids = walled is not None and bool(np.any(walled.wall_grid_dims[:, 0] > 0))
        return sim.state_hash(), builds[0], has_grids
    finally:
        numba.set_num_threads(CAP)


def test_verlet_list_and_wall_grids_change_no_bit_of_a_stirred_column(monkeypatch):
    steps = 90
    ref, builds_ref, grids_ref = _stir_hash(steps, skin=False, wall_grids=False,
                                            monkeypatch=monkeypatch)
    fast, builds, grids = _stir_hash(steps, monkeypatch=monkeypatch)
    assert builds_ref == steps and not grids_ref
    assert builds < steps                       # the list was kept on some steps
    assert grids                                # and the walls had grids
    assert fast == ref
    if CAP >= 2:
        fast2, _, _ = _stir_hash(steps, threads=2, monkeypatch=monkeypatch)
        assert fast2 == ref


def test_wall_grid_bounds_never_exceed_the_signed_field():
    # the column (inverted: free space inside) and the impeller, at a turned pose
    spec, col, sim = _column()
    col.turn(spec.omega)
    for _ in range(5):
        sim.step()
    geo = sim.world.geometry()
    geo.wall_pos[:] = sim.world.wall_motion.pos
    geo.wall_rot[:] = sim.world.wall_motion.rotations()
    walled = distgrid.with_wall_grids(geo._replace(), np.asarray(sim.world.bodies.pos), 1.0) \
        if len(sim.world.bodies.pos) * len(geo.wall_op) >= distgrid.WALL_GRID_MIN_TASKS else None
    if walled is None:
        walled = _forced_grids(geo, np.asarray(sim.world.bodies.pos))
    rng = np.random.default_rng(1)
    st = np.empty((64, 16))
    checked = 0
    tight = 0
    for w in range(len(geo.wall_op)):
        assert walled.wall_grid_dims[w, 0] > 0
        o0, o1 = geo.wall_op[w]
        sgn = geo.wall_sign[w]
        pts = rng.uniform(-25.0, 25.0, (4000, 3)) + np.array([0.0, 12.0, 0.0])
        for p in pts:
            q = geo.wall_rot[w].T @ (p - geo.wall_pos[w])
            exact = sgn * eval_point(geo.ops, geo.lk, geo.lr, o0, o1, q[0], q[1], q[2], st)[0]
            low = distgrid.lower_bound(walled.grid, walled.wall_grid_off[w],
                                       walled.wall_grid_dims[w], walled.wall_grid_oh[w],
                                       q[0], q[1], q[2])
            assert low <= exact
            checked += 1
            tight += low > exact - 2.0
    assert checked == 8000
    assert tight > 2000                          # the bounds are useful, not just -inf


def _forced_grids(geo, pos):
    old = distgrid.WALL_GRID_MIN_TASKS
    distgrid.WALL_GRID_MIN_TASKS = 0
    try:
        return distgrid.with_wall_grids(geo, pos, 1.0)
    finally:
        distgrid.WALL_GRID_MIN_TASKS = old


@pytest.mark.parametrize("periodic", [False, True])
def test_parallel_broad_phase_gives_the_serial_arrays(periodic, monkeypatch):
    rng = np.random.default_rng(5)
    n = 5000
    box_l = 20.0
    pos = rng.uniform(0.0, box_l, (n, 3))
    radius = rng.uniform(0.2, 0.5, n)
    per = np.array([periodic] * 3)
    lo, cell, dims, box = broadphase.grid_for(pos, 2 * 0.5 + 0.1, np.zeros(3),
                                              np.full(3, box_l), per, 4 * n)
    a = broadphase.find_pairs(pos, radius, 0.1, lo, cell, dims, box, per)
    assert n >= broadphase.PARALLEL_BODIES
    b = broadphase.pairs(pos, radius, 0.1, lo, cell, dims, box, per)
    assert len(a[0]) > 1000
    for x, y in zip(a, b):
        assert x.dtype == y.dtype and np.array_equal(x, y)
    # workers whose buffers are too small say so, and the pass is repeated with larger ones
    assert not broadphase.find_pairs_parallel(pos, radius, 0.1, lo, cell, dims, box, per,
                                              np.int64(2))[3]
    monkeypatch.setattr(broadphase, "ROW_SLOTS", 1)
    c = broadphase.pairs(pos, radius, 0.1, lo, cell, dims, box, per)
    for x, y in zip(a, c):
        assert np.array_equal(x, y)


def test_pair_list_is_rebuilt_when_a_body_leaves_its_build_sphere():
    sim = _new(2)
    _spheres(sim, [(0.0, 0.0, 0.0), (3.0, 0.0, 0.0)], vel=[(0.0, 0.0, 0.0)] * 2)
    assert len(sim.detect_contacts()["body_a"]) == 0
    assert sim.world.detector._pairs is not None      # a list was built (and is kept)
    # teleport body 1 next to body 0: the kept list (no pair) must not be trusted
    sim.set_positions(np.array([[0.0, 0.0, 0.0], [1.01, 0.0, 0.0]]))
    c = sim.detect_contacts()
    assert len(c["body_a"]) == 1 and c["depth"][0] == pytest.approx(-0.01, abs=1e-12)


def _periodic_rain_hash(steps, skin, threads, monkeypatch):
    # spheres drifting sideways through the periodic x and z faces (each wraps several times)
    # and falling onto a floor: a kept list must refresh its image shifts, bit for bit
    from test_dem_moving_walls import _floor
    numba.set_num_threads(threads)
    try:
        sim = Simulation(64)
        sim.set_gravity(0.0, -9.81, 0.0)
        sim.set_domain([-2.0, -1.0, -2.0], [2.0, 6.0, 2.0])
        sim.enable_periodicity(True, False, True)
        _floor(sim, e=0.2, mu=0.5)
        g = np.arange(4) - 1.5
        pos = [(0.9 * x, 0.6 + 1.0 * y, 0.9 * z) for x in g for y in range(4) for z in g]
        rng = np.random.default_rng(2)
        vel = rng.normal(size=(len(pos), 3)) * 0.5 + [6.0, 0.0, -4.0]
        _spheres(sim, pos, r=0.4, vel=vel)
        builds = _count_builds(monkeypatch)
        wraps = 0
        for _ in range(steps):
            if not skin:
                sim.world.detector._pairs = None
            before = sim.get_positions()[:, 0].copy()
            sim.step(2e-3)
            wraps += int(np.sum(np.abs(sim.get_positions()[:, 0] - before) > 2.0))
        return sim.state_hash(), builds[0], wraps
    finally:
        numba.set_num_threads(CAP)


def test_a_kept_pair_list_on_periodic_axes_changes_no_bit(monkeypatch):
    steps = 150
    ref, builds_ref, wraps = _periodic_rain_hash(steps, False, 1, monkeypatch)
    kept, builds, _ = _periodic_rain_hash(steps, True, 1, monkeypatch)
    assert builds_ref == steps and builds < steps // 2      # the list was kept most steps
    assert wraps > 20                                       # bodies crossed the faces
    assert kept == ref
    if CAP >= 2:
        assert _periodic_rain_hash(steps, True, 2, monkeypatch)[0] == ref


def test_kept_image_shifts_are_the_broad_phases_own():
    rng = np.random.default_rng(9)
    per = np.array([True, False, True])
    pos = rng.uniform(-1.75, 1.75, size=(60, 3))
    lo, cell, dims, bx = broadphase.grid_for(pos, 1.2, np.array([-1.75, 0.0, -1.75]),
                                             np.array([1.75, 1.0, 1.75]), per, 256)
    pa, pb, shift = broadphase.find_pairs(pos, np.full(60, 0.5), 0.1, lo, cell, dims, bx, per)
    assert len(pa) > 50 and np.any(shift[:, 0] != 0.0)
    assert broadphase.image_shifts(pa, pb, pos, bx, per).tobytes() == shift.tobytes()
