"""Reuse between steps (peclet.dem.reuse) never changes a contact or a bit of a pour.

The probe lists carried from step to step only decide which probes are tested again; a pour
with them must end in the same bits as one that scans every direction every step, at one and two
threads, with a buffer that overflows, after a body is moved by hand, or given another shape."""
import numba
import numpy as np

from peclet.dem.reuse import motion_bound, relative_pose
from peclet.core.geom.transforms import quats_to_matrices

from test_dem_composed import page_pour, pall_ring_particle
from test_dem_narrowphase_cull import _dense_bed


def _pour(steps, enabled, threads=1, capacity=None):
    numba.set_num_threads(threads)
    try:
        sim = page_pour(pall_ring_particle())
        reuse = sim.world.detector.reuse
        reuse.enabled = enabled
        if capacity is not None:
            reuse.capacity = capacity
        replayed = 0
        for _ in range(steps):
            sim.step(2e-3)
            replayed += int((reuse.prev.count >= 0).sum())
        return sim.state_hash(), replayed, reuse
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)


def test_pour_is_bitwise_the_same_with_and_without_reuse():
    off, listed_off, _ = _pour(700, False)
    on, listed_on, reuse = _pour(700, True)
    on2, _, _ = _pour(700, True, threads=2)
    assert listed_off == 0                      # disabled: nothing is ever listed
    assert listed_on > 1000                     # enabled: lists were made (and replayed)
    assert on == off
    assert on2 == off


def test_overflowing_list_buffer_keeps_the_bits_and_grows():
    off, _, _ = _pour(300, False)
    small, _, reuse = _pour(300, True, capacity=64)
    assert small == off
    assert reuse.capacity > 64                  # an overflow doubled it


def _listing_equal(a, b):
    assert set(a) == set(b)
    for k in a:
        assert np.array_equal(a[k], b[k]), k


def test_replayed_contacts_equal_a_fresh_scan_after_moves_and_shape_changes():
    sp, sim = _dense_bed()
    first = sim.detect_contacts()
    again = sim.detect_contacts()               # replays every listed direction
    _listing_equal(first, again)
    assert (sim.world.detector.reuse.prev.count >= 0).sum() > 20

    # a body moved by hand a little (within the lists' reach), one a lot, one turned
    pos = np.array(sim.get_positions(), dtype=np.float64)
    pos[0] += [1e-3, 0.0, 0.0]
    pos[1] += [0.4, 0.1, 0.0]
    sim.set_positions(pos)
    q = np.array(sim.get_quaternions(), dtype=np.float64)
    q[2] = [0.0, 0.0, np.sin(0.3), np.cos(0.3)]
    sim.set_quaternions(q)
    moved = sim.detect_contacts()
    sim.world.detector.reuse.reset()
    _listing_equal(moved, sim.detect_contacts())

    # a ring given the sphere's shape: its lists (of ring probes) must not be replayed
    ids = np.array(sim.get_shape_ids())
    ids[3] = ids[-1]
    sim.set_shape_ids(ids)
    changed = sim.detect_contacts()
    sim.world.detector.reuse.reset()
    _listing_equal(changed, sim.detect_contacts())


def test_motion_bound_covers_every_point_of_the_body():
    rng = np.random.default_rng(11)
    radius = 0.7
    for _ in range(200):
        q = rng.normal(size=(4, 4))
        q /= np.linalg.norm(q, axis=1)[:, None]
        R = quats_to_matrices(q)
        x = rng.normal(scale=3.0, size=(4, 3))
        # the second pose: a small random motion of both bodies
        small = rng.uniform(0, 0.02)
        R[2] = R[0] @ quats_to_matrices(np.array([[*(small * rng.normal(size=3)), 1.0]]) /
                                        np.linalg.norm([*(small * rng.normal(size=3)), 1.0]))[0]
        x[2] = x[0] + small * rng.normal(size=3)
        x[3] = x[1] + small * rng.normal(size=3)
        R[3] = R[1]
        then = np.empty(12)
        now = np.empty(12)
        relative_pose(x[0], R[0], x[1], R[1], then)
        relative_pose(x[2], R[2], x[3], R[3], now)
        mu = motion_bound(now, then, radius, x[2], x[3])
        p = rng.normal(size=(500, 3))
        p *= (radius * rng.uniform(0, 1, 500) ** (1 / 3) / np.linalg.norm(p, axis=1))[:, None]
        q_then = (R[1].T @ (x[0] + p @ R[0].T - x[1]).T).T
        q_now = (R[3].T @ (x[2] + p @ R[2].T - x[3]).T).T
        assert np.linalg.norm(q_now - q_then, axis=1).max() <= mu
        # and the pose map is the one the probes go through
        assert np.allclose(then[:9].reshape(3, 3) @ p.T + then[9:, None], q_then.T, atol=1e-12)


def test_a_stale_list_would_be_caught():
    """The equality tests above can fail: lists that claim an unlimited reach are replayed
    after every ring dropped by 0.15, and miss the contacts the drop made."""
    sp, sim = _dense_bed(seed=4)
    sim.detect_contacts()                       # lists made at this pose
    reuse = sim.world.detector.reuse
    pos = np.array(sim.get_positions(), dtype=np.float64)
    pos[:, 1] -= 0.15
    sim.set_positions(pos)
    reuse.prev = reuse.prev._replace(reach=np.where(reuse.prev.count >= 0, np.inf,
                                                    reuse.prev.reach))
    stale = sim.detect_contacts()
    reuse.reset()
    fresh = sim.detect_contacts()
    assert len(fresh["depth"]) > len(stale["depth"])


def _tilting_floor(steps, enabled, threads=1):
    # 16 rings poured on the page's floor while it tilts about z through the box centre: the
    # probe lists must see the wall's motion through the relative pose, like a body's
    numba.set_num_threads(threads)
    try:
        sim = page_pour(pall_ring_particle(), n=16)
        sim.world.detector.reuse.enabled = enabled
        sim.set_wall_velocity(0, angular=[0.0, 0.0, 0.3], center=[1.75, 0.0, 1.75])
        for _ in range(steps):
            sim.step(2e-3)
        return sim.state_hash(), sim
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)


def test_a_moving_wall_is_bitwise_the_same_with_and_without_reuse():
    off, _ = _tilting_floor(600, False)
    on, sim = _tilting_floor(600, True)
    on2, _ = _tilting_floor(600, True, threads=2)
    assert on == off and on2 == off
    t, q = sim.get_wall_transform(0)
    assert abs(q[2]) > 0.1                       # the floor did turn (0.36 rad)
    assert sim.num_contacts() > 0
