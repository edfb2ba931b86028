"""Pack analysis on synthetic packs placed by hand, against closed forms."""
import math

import numpy as np
import pytest

from peclet.core.validation import PecletArgumentError

from peclet.packing.analysis import geometry as A
from peclet.packing.bed import elements as E
from peclet.packing.bed.freeze import Pack


def fibonacci_shell(n, r):
    """Probes exactly on a sphere of radius r, plus the six axis points."""
    i = np.arange(n) + 0.5
    pol = np.arccos(1 - 2 * i / n)
    az = np.pi * (1 + 5 ** 0.5) * i
    p = np.c_[np.cos(az) * np.sin(pol), np.cos(pol), np.sin(az) * np.sin(pol)]
    return r * np.vstack([p, np.eye(3), -np.eye(3)])


def sphere_pack(P, r, L, quats=None):
    el = E.sphere(r)
    ni, nr, _, _ = el.builder.encode()
    Q = np.tile([0, 0, 0, 1.0], (len(P), 1)) if quats is None else quats
    return Pack(P, Q, L, el.envelope_volume, ni, nr, el.root, r, fibonacci_shell(600, r), 1.0,
                [1, 1, 1], el.envelope_root, el.envelope_volume)


def random_quats(n, seed):
    q = np.random.default_rng(seed).normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1)[:, None]


def test_simple_cubic_lattice_porosity_is_exact():
    r = 0.45
    xs = np.arange(2) + 0.5
    P = np.array([[x, y, z] for x in xs for y in np.arange(5) + 0.5 for z in xs])
    geo = A.PackGeometry(sphere_pack(P, r, [2.0, 2.0]))
    res = A.cover_fractions(geo, (1.0, 3.0), n_samples=200_000, seed=1)
    exact = 1 - 4 / 3 * math.pi * r ** 3           # two whole lattice periods in y
    assert abs(res["eps"] - exact) < 4 * res["eps_se"]
    assert res["f_env"] == pytest.approx(1 - res["eps"], abs=1e-15)   # a sphere is its envelope
    assert res["double"] == 0.0


def test_periodic_images_and_rotation_of_a_pall_ring():
    """One rotated ring straddling both periodic boundaries: its volume and its envelope's
    volume are recovered in a window that contains it."""
    el = E.pall_ring()
    ni, nr, _, _ = el.builder.encode()
    q = random_quats(1, 7)
    pk = Pack([[0.05, 0.9, 1.95]], q, [2.0, 2.0], 0.268, ni, nr, el.root, 0.7072,
              np.zeros((1, 3)), 1.0, [1, 1, 1], el.envelope_root, el.envelope_volume)
    geo = A.PackGeometry(pk)
    n = 300_000
    res = A.cover_fractions(geo, (0.0, 1.8), n_samples=n, seed=2)
    vwin = 2.0 * 2.0 * 1.8
    # independent estimate of the ring volume: plain MC in its own frame
    lo, hi = el.bounds
    g = np.random.default_rng(9)
    p = g.uniform(lo, hi, size=(1_000_000, 3))
    f = (el.builder.eval_root(el.root, p) < 0).mean()
    v_ring = np.prod(hi - lo) * f
    se_ring = np.prod(hi - lo) * math.sqrt(f * (1 - f) / 1_000_000)
    v_meas = (1 - res["eps"]) * vwin
    assert abs(v_meas - v_ring) < 4 * math.hypot(res["eps_se"] * vwin, se_ring)
    assert abs(res["f_env"] * vwin - math.pi * 0.25) < 4 * res["f_env_se"] * vwin


def test_doubly_covered_volume_is_the_lens():
    r, d = 0.5, 0.7
    P = np.array([[1.0, 1.0, 1.0], [1.0 + d, 1.0, 1.0]])
    geo = A.PackGeometry(sphere_pack(P, r, [3.0, 3.0]))
    res = A.cover_fractions(geo, (0.0, 2.0), n_samples=400_000, seed=3)
    lens = math.pi * (4 * r + d) * (2 * r - d) ** 2 / 12      # two equal spheres
    vwin = 3.0 * 3.0 * 2.0
    assert abs(res["double"] * vwin - lens) < 4 * res["double_se"] * vwin
    union = 2 * 4 / 3 * math.pi * r ** 3 - lens
    assert abs((1 - res["eps"]) * vwin - union) < 4 * res["eps_se"] * vwin


def test_coordination_both_ways_and_overlap_depth():
    # a periodic row: each sphere overlaps its two neighbours (one of them an image) by 0.01
    r = 0.505
    P = np.array([[0.5, 0.6, 1.0], [1.5, 0.6, 1.0]])
    geo = A.PackGeometry(sphere_pack(P, r, [2.0, 2.0]))
    c = A.probe_overlap(geo)
    assert c["probe_counts"].tolist() == [2, 2]
    assert c["max_depth"] == pytest.approx(2 * r - 1.0, abs=1e-12)   # axis probes are exact
    # pulled apart to a gap: no contact, nothing deeper than zero
    P2 = np.array([[0.5, 0.6, 1.0], [1.5, 0.6, 1.0]])
    c2 = A.probe_overlap(A.PackGeometry(sphere_pack(P2, 0.49, [2.0, 2.0])))
    assert c2["probe_counts"].tolist() == [0, 0] and c2["max_depth"] == 0.0


def test_contact_seen_only_one_way_is_counted():
    """Sparse probes (the six axis points) and an overlap along a diagonal: only the rotated
    body's probe lands inside the other, so a one-way test from body 0 misses the contact and the
    two-way test must count it for both bodies."""
    r, dist = 0.5, 0.9
    d = np.array([1.0, 1.0, 0.0]) / math.sqrt(2)
    P = np.array([[1.0, 1.0, 1.0], [1.0, 1.0, 1.0] + dist * d])
    qz45 = [0.0, 0.0, math.sin(math.pi / 8), math.cos(math.pi / 8)]   # body 1's -x probe -> -d
    pk = sphere_pack(P, r, [4.0, 4.0], np.array([[0, 0, 0, 1.0], qz45]))
    pk.shell = np.ascontiguousarray(r * np.vstack([np.eye(3), -np.eye(3)]))
    geo = A.PackGeometry(pk)
    j = int(np.flatnonzero((geo.owner == 1) & np.all(geo.img_pos == P[1], axis=1))[0])
    assert geo.probe_min([0], [j])[0] > 0               # body 0's probes all miss body 1
    c = A.probe_overlap(geo)
    assert c["probe_counts"].tolist() == [1, 1]
    assert c["max_depth"] == pytest.approx(r - (dist - r), abs=1e-12)


def test_orientation_statistics():
    ax = A.orientation(sphere_pack(np.zeros((2, 3)) + 0.5, 0.1, [2, 2]))
    assert ax["cos"].tolist() == [1.0, 1.0]
    qx = [math.sin(math.pi / 4), 0, 0, math.cos(math.pi / 4)]        # 90 deg about x
    ax = A.orientation(sphere_pack(np.full((1, 3), 0.5), 0.1, [2, 2], np.array([qx])))
    assert ax["cos"][0] == pytest.approx(0.0, abs=1e-15)
    n = 20_000
    iso = A.orientation(sphere_pack(np.full((n, 3), 0.5), 0.1, [2, 2], random_quats(n, 4)))
    assert abs(iso["mean"] - 0.5) < 4 * iso["sem_iso"]
    assert iso["sem"] == pytest.approx(iso["sem_iso"], rel=0.05)


def test_floor_and_box():
    pk = sphere_pack(np.array([[0.5, 0.5, 0.5], [1.5, 0.49, 1.9]]), 0.5, [2.0, 2.0])
    chk = A.floor_and_box(pk)
    assert chk["lowest_probe"] == pytest.approx([0.0, -0.01], abs=1e-12)
    assert chk["all_in_box"]
    pk2 = sphere_pack(np.array([[2.5, 0.5, 0.5]]), 0.5, [2.0, 2.0])
    assert not A.floor_and_box(pk2)["all_in_box"]


def test_bulk_windows_are_the_pages_and_scale_down_for_shallow_beds():
    # a column of spheres from y = 0.5 to 5.53 (the windows need elements inside them)
    col = np.c_[np.full(12, 0.5), np.linspace(0.5, 5.53, 12), np.full(12, 0.5)]
    pk = sphere_pack(col, 0.3, [2, 2])
    w, s = A.bulk_windows(pk)
    assert s == 1.0 and np.allclose(w, [(1.0, 4.73), (0.8, 4.93), (1.2, 4.53)], atol=1e-12)
    with pytest.raises(PecletArgumentError, match="^pack "):     # nothing reaches a window
        A.bulk_windows(sphere_pack(np.array([[0.5, 0.5, 0.5], [0.5, 5.53, 0.5]]), 0.1, [2, 2]))
    pk = sphere_pack(np.array([[0.5, 0.5, 0.5], [0.5, 1.5, 0.5]]), 0.1, [2, 2])
    w, s = A.bulk_windows(pk)
    assert s < 1 and all(b - a >= 0.75 - 1e-12 for a, b in w)


def test_analysis_is_bitwise_identical_at_one_and_two_threads():
    import numba

    el = E.pall_ring()
    ni, nr, _, _ = el.builder.encode()
    g = np.random.default_rng(5)
    P = np.c_[g.uniform(0, 2.5, 12), g.uniform(0.5, 2.5, 12), g.uniform(0, 2.5, 12)]
    shell = g.uniform(-0.6, 0.6, (400, 3))
    pk = Pack(P, random_quats(12, 6), [2.5, 2.5], 0.27, ni, nr, el.root, 0.7072, shell, 1.0,
              [1, 1, 1], el.envelope_root, el.envelope_volume)
    out = []
    cap = numba.config.NUMBA_NUM_THREADS
    for t in sorted({1, min(2, cap)}):
        numba.set_num_threads(t)
        geo = A.PackGeometry(pk)
        r = A.cover_fractions(geo, (0.5, 2.5), n_samples=50_000, seed=0)
        c = A.probe_overlap(geo)
        out.append((r["eps"], r["f_env"], r["double"], c["probe_counts"].tolist(), c["max_depth"]))
    numba.set_num_threads(cap)
    assert all(o == out[0] for o in out)


@pytest.mark.parametrize("call,match", [
    (lambda g: A.cover_fractions(g, (2.0, 1.0)), "window"),
    (lambda g: A.cover_fractions(g, (0.0, 1.0), n_samples=0), "n_samples"),
])
def test_bad_arguments(call, match):
    geo = A.PackGeometry(sphere_pack(np.full((1, 3), 0.5), 0.4, [2, 2]))
    with pytest.raises(ValueError, match=match):
        call(geo)
