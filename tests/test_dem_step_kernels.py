"""The step's small kernels against the array forms they replaced, bit for bit (a step's bits
must not depend on how its glue is written): the warm start's initial impulses
(contacts.WarmStart.initial: search the cached keys, project the world tangential impulse on
this step's tangents, clamp into the Coulomb cone), the periodic wrap (domain.wrap_into) and
the lever arms (contacts.lever_arms); and the parallel twins of serial kernels (the warm
start's lookups and its store, the narrow phase's gather, the world inverse inertias) against
them."""
import numpy as np

from peclet.dem import contacts, narrowphase
from peclet.dem.contacts import Contacts, WarmStart, lever_arms
from peclet.dem.domain import wrap_into
from peclet.dem.manifold import MAX_PER_TASK
from peclet.dem.solver import tangent_basis, world_inv_inertias, world_inv_inertias_parallel


def _array_form(old_keys, old_lam, keys, t1, t2, mu):
    nc = len(keys)
    lam = np.zeros((nc, 3))
    if nc and len(old_keys):
        j = np.minimum(np.searchsorted(old_keys, keys), len(old_keys) - 1)
        hit = old_keys[j] == keys
        old = old_lam[j[hit]]
        lam[hit, 0] = old[:, 0]
        lam[hit, 1] = (old[:, 1:] * t1[hit]).sum(axis=1)
        lam[hit, 2] = (old[:, 1:] * t2[hit]).sum(axis=1)
    tm = np.sqrt(lam[:, 1] ** 2 + lam[:, 2] ** 2)
    lim = mu * lam[:, 0]
    over = tm > lim
    sc = np.where(tm[over] > 0, lim[over] / np.where(tm[over] > 0, tm[over], 1.0), 0.0)
    lam[over, 1] *= sc
    lam[over, 2] *= sc
    return lam


def test_initial_impulses_have_the_bits_of_the_array_form():
    rng = np.random.default_rng(3)
    for trial in range(20):
        k_old = np.unique(rng.integers(0, 400, size=150))
        lam_old = rng.normal(size=(len(k_old), 4)) * 10.0 ** rng.integers(-9, 2, (len(k_old), 1))
        lam_old[:, 0] = np.abs(lam_old[:, 0])
        lam_old[::7, 1:] = 0.0                       # no tangential impulse
        lam_old[::11, 0] = 0.0                       # no normal impulse: clamped to zero
        keys = rng.integers(0, 400, size=120)        # hits and misses, repeated keys
        normal = rng.normal(size=(120, 3))
        normal /= np.linalg.norm(normal, axis=1)[:, None]
        t1, t2 = tangent_basis(normal)
        mu = rng.choice([0.0, 0.1, 0.5, 2.0], size=120)
        ws = WarmStart(k_old, lam_old)
        got = ws.initial(keys, t1, t2, mu)
        want = _array_form(k_old, lam_old, keys, t1, t2, mu)
        assert got.tobytes() == want.tobytes(), trial
        tm = np.hypot(got[:, 1], got[:, 2])
        assert np.all(tm <= mu * got[:, 0] * (1 + 1e-12) + 1e-300)


def test_an_empty_cache_gives_zero_impulses():
    t = np.zeros((3, 3))
    lam = WarmStart().initial(np.array([1, 2, 3], np.int64), t, t, np.ones(3))
    assert lam.shape == (3, 3) and not lam.any()


def test_the_periodic_wrap_has_the_bits_of_numpys_modulo():
    rng = np.random.default_rng(0)
    lo, hi = np.array([-1.75, 0.0, -1.75]), np.array([1.75, 9.0, 1.75])
    periodic = np.array([True, False, True])
    for trial in range(30):
        p = rng.normal(size=(500, 3)) * rng.choice([1e-17, 0.1, 2.0, 10.0])
        p[::17, 0] = hi[0]                          # exactly on the upper bound
        p[::19, 2] = lo[2] - 1e-18                  # rounds up to hi: must become lo
        p[::23, 0] = -0.0
        want = p.copy()
        for a in np.flatnonzero(periodic):
            L = hi[a] - lo[a]
            want[:, a] = lo[a] + np.mod(want[:, a] - lo[a], L)
            want[want[:, a] >= hi[a], a] = lo[a]
        got = p.copy()
        wrap_into(got, lo, hi, periodic)
        assert got.tobytes() == want.tobytes(), trial
        assert np.all((got[:, [0, 2]] >= lo[[0, 2]]) & (got[:, [0, 2]] < hi[[0, 2]]))
        assert np.array_equal(got[:, 1], p[:, 1])


def test_the_lever_arms_have_the_bits_of_the_array_form():
    rng = np.random.default_rng(5)
    pos = rng.normal(size=(40, 3)) * 3.0
    n = 300
    a = rng.integers(0, 40, n)
    b = rng.integers(-3, 40, n)                     # walls are -1 - index
    shift = rng.choice([-3.5, 0.0, 3.5], size=(n, 3))
    point = rng.normal(size=(n, 3)) * 3.0
    c = Contacts(a, b, shift, point, np.zeros((n, 3)), np.zeros(n), np.zeros(n, np.int64))
    ra, rb = lever_arms(c, pos)
    isw = b < 0
    want_b = np.where(isw[:, None], 0.0, point - (pos[np.where(isw, 0, b)] + shift))
    assert ra.tobytes() == (point - pos[a]).tobytes()
    assert rb.tobytes() == want_b.tobytes()


def test_parallel_warm_start_lookups_give_the_serial_impulses():
    rng = np.random.default_rng(8)
    k_old = np.unique(rng.integers(0, 200_000, size=60_000))
    lam_old = rng.normal(size=(len(k_old), 4))
    lam_old[:, 0] = np.abs(lam_old[:, 0])
    n = 50_000
    keys = rng.integers(0, 200_000, size=n)
    normal = rng.normal(size=(n, 3))
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    t1, t2 = tangent_basis(normal)
    mu = rng.choice([0.0, 0.5, 2.0], size=n)
    assert n >= contacts.PARALLEL_INITIAL_CONTACTS
    got = WarmStart(k_old, lam_old).initial(keys, t1, t2, mu)
    want = contacts._initial_impulses(k_old, lam_old, keys, t1, t2, mu)
    assert got.tobytes() == want.tobytes()
    assert got.tobytes() == _array_form(k_old, lam_old, keys, t1, t2, mu).tobytes()


def test_parallel_gather_gives_the_serial_contacts():
    rng = np.random.default_rng(9)
    ntask = 30_000
    tasks = narrowphase.Tasks(rng.integers(0, 5000, ntask), rng.integers(-2, 5000, ntask),
                              rng.normal(size=(ntask, 3)), rng.random(ntask))
    cap = ntask * MAX_PER_TASK
    slots = narrowphase.Slots(rng.integers(0, 5, ntask), rng.normal(size=(cap, 3)),
                              rng.normal(size=(cap, 3)), rng.normal(size=cap),
                              rng.integers(0, 1 << 30, cap),
                              np.arange(ntask + 1, dtype=np.int64) * MAX_PER_TASK)
    assert ntask >= narrowphase.PARALLEL_GATHER_TASKS
    a = narrowphase.gather(tasks, slots)
    b = narrowphase.gather_parallel(tasks, slots)
    assert len(a[0]) == int(slots.count.sum())
    # the array form: each task's used slots, in task order
    rows = np.concatenate([t * MAX_PER_TASK + np.arange(c) for t, c in
                           enumerate(slots.count)])
    task = np.repeat(np.arange(ntask), slots.count)
    want = (tasks.a[task], tasks.b[task], tasks.shift[task], slots.point[rows],
            slots.normal[rows], slots.gap[rows], slots.feat[rows])
    for x, y in zip(a, want):
        assert x.tobytes() == y.tobytes()
    for x, y in zip(a, b):
        assert x.dtype == y.dtype and x.tobytes() == y.tobytes()


def test_parallel_world_inverse_inertias_give_the_serial_ones():
    rng = np.random.default_rng(10)
    q = rng.normal(size=(5000, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    inv = rng.random((5000, 3))
    inv[::7] = 0.0
    assert world_inv_inertias_parallel(q, inv).tobytes() == world_inv_inertias(q, inv).tobytes()


def test_the_parallel_warm_start_store_gives_the_array_forms_cache():
    rng = np.random.default_rng(11)
    n = 40_000
    keys = rng.permutation(n * 3)[:n].astype(np.int64)
    keys[::50] = keys[1::50]                        # some repeated keys: the stable order
    lam = rng.normal(size=(n, 3))
    normal = rng.normal(size=(n, 3))
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    t1, t2 = tangent_basis(normal)
    assert n >= contacts.PARALLEL_INITIAL_CONTACTS
    ws = WarmStart()
    ws.store(keys, lam, t1, t2)
    world = np.empty((n, 4))
    world[:, 0] = lam[:, 0]
    world[:, 1:] = lam[:, 1:2] * t1 + lam[:, 2:3] * t2
    o = np.argsort(keys, kind="stable")
    assert ws.keys.dtype == np.int64 and ws.keys.tobytes() == keys[o].tobytes()
    assert ws.lam.tobytes() == world[o].tobytes()
