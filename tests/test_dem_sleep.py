"""Deterministic sleeping of bodies at rest (peclet.dem.sleep; issue 27 item 3).

Off by default and exact when off; on, a settled bed falls asleep, a sleeper does not move by a
bit, a body landing on the bed wakes what it hits, loads and API calls wake bodies, and a
sleeping run is the same at 1 and 2 threads and after a save and load.
"""
import math

import numba
import numpy as np
import pytest

from peclet.core.geom import SceneBuilder
from peclet.core.validation import PecletArgumentError
from peclet.dem import Simulation

CAP = int(numba.config.NUMBA_NUM_THREADS)
R = 0.5


def _box_walls(sim, half=2.8):
    b = SceneBuilder()
    floor = b.add_leaf("box", [half + 1.0, 1.0, half + 1.0], translation=[0.0, -1.0, 0.0])
    ni, nr, _, _ = b.encode()
    sim.add_analytic_wall(ni, nr, floor, False, 0.2, 0.5)
    for sx, sz in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        b = SceneBuilder()
        side = b.add_leaf("box", [0.5 if sx else half + 1.0, 20.0, 0.5 if sz else half + 1.0],
                          translation=[sx * (half + 0.5), 20.0, sz * (half + 0.5)])
        ni, nr, _, _ = b.encode()
        sim.add_analytic_wall(ni, nr, side, False, 0.2, 0.5)


def _bed(n_side=5, layers=3, seed=1):
    rng = np.random.default_rng(seed)
    sim = Simulation(n_side * n_side * layers + 1)
    sim.set_gravity(0.0, -9.81, 0.0)
    sim.set_dt(2e-3)
    sim.set_material_params(0.2, 0.0, 0.5)
    _box_walls(sim)
    sid = sim.add_sphere_shape(R)
    g = (np.arange(n_side) - (n_side - 1) / 2) * 1.1
    pos = np.array([(x, 0.6 + 1.1 * k, z) for k in range(layers) for x in g for z in g])
    pos += rng.uniform(-0.04, 0.04, pos.shape)
    n = len(pos)
    sim.set_positions(pos)
    sim.set_shape_ids(np.full(n, sid, np.int32))
    m = 4.0 / 3.0 * math.pi * R ** 3
    sim.set_inv_mass(np.full(n, 1.0 / m))
    # rotation locked: frictional spheres on a flat floor would otherwise roll for ever (no
    # rolling resistance) and never come to rest
    sim.set_inv_inertia(np.zeros((n, 3)))
    return sim


def _run(sim, steps):
    for _ in range(steps):
        sim.step()
    return sim


def test_sleeping_off_is_the_step_without_it():
    a = _run(_bed(), 200)
    b = _bed()
    b.set_sleeping(0.05, 10)
    b.disable_sleeping()
    _run(b, 200)
    assert a.state_hash() == b.state_hash()
    assert not b.get_sleeping().any()


def test_a_settled_bed_falls_asleep_and_sleepers_keep_their_bits():
    sim = _bed()
    sim.set_sleeping(0.05, 20)
    _run(sim, 900)
    asleep = sim.get_sleeping()
    assert asleep.mean() > 0.9
    pos, quat = sim.get_positions(), sim.get_quaternions()
    _run(sim, 50)
    still = asleep & sim.get_sleeping()
    assert np.array_equal(sim.get_positions()[still], pos[still])
    assert np.array_equal(sim.get_quaternions()[still], quat[still])
    assert np.all(sim.get_velocities()[still] == 0.0)
    # the bed without sleeping rests at the same place to within the sleep threshold's creep
    ref = _run(_bed(), 950)
    assert np.abs(ref.get_positions() - sim.get_positions()).max() < 0.05 * R


def test_a_body_landing_on_a_sleeping_bed_wakes_what_it_hits_and_sleeps_again():
    sim = _bed()
    sim.set_sleeping(0.05, 20)
    _run(sim, 900)
    assert sim.get_sleeping().all()
    # a ball appears above the centre (setting positions wakes everyone: let them resettle)
    pos = np.vstack([sim.get_positions(), [[0.05, 5.0, 0.0]]])
    n = len(pos)
    for setter, rows in ((sim.set_positions, pos),
                         (sim.set_shape_ids, np.zeros(n, np.int32)),
                         (sim.set_inv_mass, np.append(sim.get_inv_mass(),
                                                      sim.get_inv_mass()[0])),
                         (sim.set_inv_inertia, np.vstack([sim.get_inv_inertia(),
                                                          sim.get_inv_inertia()[:1]]))):
        setter(rows)
    assert not sim.get_sleeping().any()
    # let the old bed sleep again before the ball arrives (it falls 3.5 in ~0.85 s)
    woke = np.zeros(n, bool)
    slept_before_impact = False
    for k in range(900):
        before = sim.get_sleeping()
        sim.step()
        if sim.get_positions()[-1, 1] > 2.6:
            slept_before_impact = slept_before_impact or before[:-1].mean() > 0.8
        woke |= before & ~sim.get_sleeping()
    assert slept_before_impact
    assert woke[:-1].any()                       # the impact woke bodies of the bed
    assert sim.get_sleeping().mean() > 0.9       # and everything slept again
    over = sim.overlap_pairs()
    assert len(over["depth"]) == 0 or over["depth"].max() < 0.02 * R


def test_a_load_wakes_a_sleeper():
    sim = _bed()
    sim.set_sleeping(0.05, 20)
    _run(sim, 900)
    top = int(np.argmax(sim.get_positions()[:, 1]))
    assert sim.get_sleeping()[top]
    y0 = sim.get_positions()[top, 1]
    f = np.zeros((sim.num_particles(), 3))
    f[top, 1] = 40.0 / sim.get_inv_mass()[top]           # 40 g up: it leaves the bed
    sim.set_external_forces(f)
    _run(sim, 40)                                         # 0.5 x 30 g' x 0.08^2 = 0.096
    assert not sim.get_sleeping()[top]
    assert sim.get_positions()[top, 1] > y0 + 0.05


def _sleep_hash(threads, save_at=None, tmp=None):
    numba.set_num_threads(threads)
    try:
        sim = _bed()
        sim.set_sleeping(0.05, 20)
        for k in range(700):
            if save_at is not None and k == save_at:
                path = str(tmp / "mid.npz")
                sim.save(path)
                sim = Simulation.load(path)
            sim.step()
        return sim.state_hash(), int(sim.get_sleeping().sum())
    finally:
        numba.set_num_threads(CAP)


def test_sleeping_is_deterministic_across_threads_and_save_load(tmp_path):
    ref, asleep = _sleep_hash(1)
    assert asleep > 0
    assert _sleep_hash(1, save_at=500, tmp=tmp_path) == (ref, asleep)
    if CAP >= 2:
        assert _sleep_hash(2) == (ref, asleep)


@pytest.mark.parametrize("speed, steps, name", [(0.0, 10, "speed"), (-1.0, 10, "speed"),
                                                (float("nan"), 10, "speed"),
                                                (0.1, 0, "steps"), (0.1, 2.5, "steps"),
                                                (0.1, 10 ** 7, "steps")])
def test_bad_sleeping_arguments_are_named(speed, steps, name):
    sim = Simulation(1)
    with pytest.raises(PecletArgumentError, match=name):
        sim.set_sleeping(speed, steps)
