"""Freeze/load, figures and the command line's argument handling (no DEM needed)."""
import os

import matplotlib.image as mpimg
import numpy as np
import pytest

from peclet.core.geom.mesh import surface_mesh
from peclet.packing.bed import elements as E
from peclet.packing.output import figures as F
from peclet.core.validation import PecletArgumentError
from peclet.packing.bed.freeze import Pack, load_pack, pack_to_simulation, save_pack
from peclet.packing.bed.pour import Protocol, start_cloud


def ring_pack(n=6, seed=0):
    el = E.pall_ring()
    ni, nr, _, _ = el.builder.encode()
    g = np.random.default_rng(seed)
    P = np.c_[g.uniform(0, 3.5, n), g.uniform(0.5, 3.0, n), g.uniform(0, 3.5, n)]
    Q = g.normal(size=(n, 4))
    return Pack(P, Q, [3.5, 3.5], 0.2680, ni, nr, el.root, 0.7191,
                g.uniform(-0.5, 0.5, (50, 3)), 0.2680, [20.8, 20.7, 20.1], el.envelope_root,
                el.envelope_volume, [0.0, 1.0, 0.0])


def test_pack_round_trip_is_bitwise_and_atomic(tmp_path):
    pk = ring_pack()
    path = save_pack(tmp_path / "pall_ring_pack.npz", pk)
    assert sorted(os.listdir(tmp_path)) == ["pall_ring_pack.npz"]       # no temp file left
    back = load_pack(path)
    for k in ("positions", "quaternions", "box", "node_ints", "node_reals", "shell",
              "inv_inertia", "axis_home"):
        assert np.array_equal(getattr(back, k), getattr(pk, k)), k
    for k in ("ring_volume", "home_root", "bounding_radius", "mass", "envelope_root",
              "envelope_volume"):
        assert getattr(back, k) == getattr(pk, k), k
    # the stored tree evaluates exactly like the original
    p = np.random.default_rng(1).uniform(-0.7, 0.7, (1000, 3))
    assert np.array_equal(back.builder().eval_root(back.home_root, p),
                          pk.builder().eval_root(pk.home_root, p))
    with np.load(path) as z:     # the page's field names are all there
        assert {"positions", "quaternions", "box", "ring_volume", "node_ints", "node_reals",
                "home_root", "bounding_radius"} <= set(z.files)


def test_a_page_format_file_loads_but_cannot_make_a_simulation(tmp_path):
    pk = ring_pack()
    path = tmp_path / "page.npz"
    np.savez_compressed(path, positions=pk.positions.astype(np.float32),
                        quaternions=pk.quaternions.astype(np.float32),
                        box=np.float32([3.5, 3.5]), ring_volume=np.float32(0.268),
                        node_ints=pk.node_ints, node_reals=pk.node_reals.astype(np.float32),
                        home_root=np.int32(pk.home_root), bounding_radius=np.float32(0.7191))
    back = load_pack(path)
    assert back.n == pk.n and back.shell.shape == (0, 3)
    with pytest.raises(ValueError, match="shell"):
        pack_to_simulation(back)
    np.savez(tmp_path / "bad.npz", positions=pk.positions)
    with pytest.raises(PecletArgumentError, match="missing fields"):
        load_pack(tmp_path / "bad.npz")


def test_pack_validates():
    pk = ring_pack()
    with pytest.raises(ValueError, match="quaternions"):
        Pack(pk.positions, np.zeros((pk.n, 4)), pk.box, 1, pk.node_ints, pk.node_reals, 0, 1,
             pk.shell, 1, [1, 1, 1])
    with pytest.raises(ValueError, match="box"):
        Pack(pk.positions, pk.quaternions, [0, 1], 1, pk.node_ints, pk.node_reals, 0, 1,
             pk.shell, 1, [1, 1, 1])


def test_start_cloud_is_the_pages_and_reproducible():
    P, Q = start_cloud(48, 3.5, seed=5)
    P2, Q2 = start_cloud(48, 3.5, seed=5)
    assert np.array_equal(P, P2) and np.array_equal(Q, Q2)
    assert not np.array_equal(P, start_cloud(48, 3.5, seed=6)[0])
    assert np.all((P[:, [0, 2]] >= 0) & (P[:, [0, 2]] < 3.5)) and P[:, 1].min() == 1.2
    assert np.allclose(np.linalg.norm(Q, axis=1), 1.0)
    # the page's rule: against each of the 14 previously placed, apart horizontally or vertically
    for i in range(len(P)):
        for j in range(max(0, i - 14), i):
            d = P[i] - P[j]
            assert np.hypot(d[0], d[2]) > 1.55 or abs(d[1]) > 1.55
    with pytest.raises(ValueError, match="n must"):
        start_cloud(0, 3.5)


def test_protocol_defaults_scaling_and_validation():
    p = Protocol()
    assert p.total_steps == 3700
    assert p.phases() == [("pour", 0), ("tap", 1400), ("tap", 1800), ("relax", 2200),
                          ("quench", 2800)]
    s = p.scaled(0.05)
    assert (s.pour_steps, s.tap_steps, s.relax_steps, s.quench_steps) == (70, 20, 30, 45)
    for kw, m in [(dict(damp=1.5), "damp"), (dict(dt=0), "dt"), (dict(taps=-1), "taps"),
                  (dict(tap_speed=float("nan")), "tap_speed")]:
        with pytest.raises(ValueError, match=m):
            Protocol(**kw)
    with pytest.raises(ValueError, match="steps scale"):
        p.scaled(0)


def _check_png(path, min_kib=5):
    assert os.path.getsize(path) > min_kib * 1024
    img = mpimg.imread(path)
    assert img.ndim == 3 and img.shape[0] > 100 and img.shape[1] > 100
    assert img[..., :3].std() > 0.02                  # not a blank canvas
    return img


def test_figures_are_written_and_not_blank(tmp_path):
    el = E.pall_ring()
    v, f, area = surface_mesh(el.builder, el.root, [-0.62] * 3, [0.62] * 3, 40)
    assert 5.5 < area < 7.5          # the page: 6.56 on a 150^3 lattice
    _check_png(F.ring_views(v, f, tmp_path / "ring.png"))
    t = np.arange(80) * 45 * 2e-3
    ke = np.exp(-t) + 1e-4
    _check_png(F.kinetic_energy(t, ke, Protocol().phases(), 2e-3, tmp_path / "ke.png"))
    pk = ring_pack(8)
    _check_png(F.pack_by_height(pk.positions, pk.rotations(), v, pk.box,
                                tmp_path / "pack.png"))
    _check_png(F.orientation_histogram(np.random.default_rng(0).random(48),
                                       tmp_path / "ori.png"))
    rows = [dict(t_over_d=a, eps=1 - 0.58 * s, eps_err=0.002)
            for a, s in [(0.024, 0.07), (0.08, 0.24), (0.16, 0.44)]]
    _check_png(F.voidage_sweep(rows, 0.8, 0.12, tmp_path / "sweep.png"))
    assert not [n for n in os.listdir(tmp_path) if n.startswith(".")]     # no temp file left


def test_set_threads_takes_effect_and_validates():
    import numba

    from peclet.packing.bed.threads import set_threads

    cap = numba.config.NUMBA_NUM_THREADS
    try:
        assert set_threads(1) == 1 and numba.get_num_threads() == 1
        with pytest.raises(ValueError, match="threads"):
            set_threads(cap + 1)
    finally:
        numba.set_num_threads(cap)


def test_pour_animation_writes_a_multi_frame_gif(tmp_path):
    from PIL import Image

    g = np.random.default_rng(0)
    frames = [(np.c_[g.uniform(0, 3, 4), np.full(4, 3.0 - 0.3 * k), g.uniform(0, 3, 4)],
               g.normal(size=(4, 4))) for k in range(5)]
    shell = g.normal(size=(200, 3))
    shell /= 2 * np.linalg.norm(shell, axis=1)[:, None]
    path = F.pour_animation(frames, np.arange(5) * 0.1, shell, (3.0, 3.0), tmp_path / "a.gif")
    with Image.open(path) as im:
        assert im.n_frames == 5
