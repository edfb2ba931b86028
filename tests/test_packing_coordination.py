"""Coordination from the engine's own contact detection (issue 26, item 1).

Lattices whose contact numbers are known exactly: simple cubic 6, body-centred cubic 8,
face-centred cubic 12, each in a periodic box (every element counts its images), and a random
sphere bed checked against the brute-force count of centre pairs closer than d (1 + gap/d). A
composed element (the Pall ring) is checked against a brute-force minimum of the exact tree
over the other ring's probes. The old probe-sampling count is shown to miss the sphere contacts
that these counts see, so the tests can fail the way the old figure did.
"""
import math

import numpy as np
import pytest

from peclet.core.geom import SceneBuilder
from peclet.core.validation import PecletArgumentError
from peclet.packing.analysis import geometry as A
from peclet.packing.bed import elements as E
from peclet.packing.analysis.coordination import engine_coordination, sphere_radius_of
from peclet.packing.bed.freeze import Pack
from peclet.packing.bed.api import _fibonacci_sphere


def sphere_pack(P, r, L, shell=600):
    el = E.sphere(r)
    ni, nr, _, _ = el.builder.encode()
    Q = np.tile([0, 0, 0, 1.0], (len(P), 1))
    return Pack(np.asarray(P, float), Q, L, el.envelope_volume, ni, nr, el.root, r,
                _fibonacci_sphere(shell, r), 1.0, [1, 1, 1], el.envelope_root,
                el.envelope_volume)


def lattice(basis, cells, a):
    g = np.arange(cells)
    cell = np.array(np.meshgrid(g, g, g, indexing="ij")).reshape(3, -1).T
    return ((cell[:, None, :] + np.asarray(basis)[None, :, :]).reshape(-1, 3) + 0.25) * a


@pytest.mark.parametrize("basis,z,nn", [
    ([[0, 0, 0]], 6, 1.0),                                               # simple cubic
    ([[0, 0, 0], [0.5, 0.5, 0.5]], 8, math.sqrt(3) / 2),                 # bcc
    ([[0, 0, 0], [0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5]], 12, math.sqrt(0.5)),   # fcc
])
def test_periodic_lattices_have_their_exact_coordination(basis, z, nn):
    d = 1.0
    a = d / nn                             # nearest neighbours just touch
    P = lattice(basis, 3, a)
    P[:, 1] += 5.0                         # far above the floor
    pack = sphere_pack(P, 0.5 * d, [3 * a, 3 * a])
    c = engine_coordination(pack, gap=1e-3)
    # along y the lattice is not periodic: the brute force counts the y neighbours that exist
    expect = []
    for i in range(len(P)):
        # brute force with x/z images
        k = 0
        for sx in (-1, 0, 1):
            for sz in (-1, 0, 1):
                S = P + np.array([sx * 3 * a, 0, sz * 3 * a])
                dist = np.linalg.norm(S - P[i], axis=1)
                k += int(((dist < d + 1e-3) & (dist > 1e-9)).sum())
        expect.append(k)
    assert c["elem"].tolist() == expect
    assert max(expect) == z                 # interior layers reach the lattice's number
    assert c["method"] == "engine: exact spheres"


def test_random_sphere_bed_matches_centre_pairs_and_beats_the_probe_count():
    """Spheres resting in contact (centre distances exactly d for a chain of neighbours) in a
    column-like cluster: the engine count equals the centre-pair count; the probe count of the
    old analysis misses most of them."""
    rng = np.random.default_rng(3)
    d = 1.0
    # grow a random cluster of touching spheres: each new one touches an existing one exactly
    P = [np.array([10.0, 10.0, 10.0])]
    while len(P) < 80:
        base = P[rng.integers(len(P))]
        v = rng.normal(size=3)
        cand = base + d * v / np.linalg.norm(v)
        if min(np.linalg.norm(cand - p) for p in P) >= d * (1 - 1e-12):
            P.append(cand)
    P = np.array(P)
    pack = sphere_pack(P, 0.5, [60.0, 60.0])
    c = engine_coordination(pack, gap=1e-3, periodic=False)
    dist = np.linalg.norm(P[:, None] - P[None], axis=2)
    brute = ((dist < d * (1 + 1e-3)) & (dist > 0)).sum(axis=1)
    assert c["elem"].tolist() == brute.tolist()
    assert c["pairs"] == int(brute.sum()) // 2
    assert c["pairs"] >= 79                # a tree of 80 touching spheres has >= 79 pairs
    old = A.probe_overlap(A.PackGeometry(pack), gap=0.0)
    assert old["probe_z_mean"] < 0.5 * c["z_elem"]   # the defect this replaces


def test_walls_count_once_and_a_floating_sphere_is_a_rattler():
    b = SceneBuilder()
    floor = b.add_leaf("box", [50.0, 1.0, 50.0], translation=[0.0, -1.0, 0.0])
    P = [[0.0, 0.5, 0.0], [0.0, 1.5, 0.0], [5.0, 3.0, 0.0]]
    c = engine_coordination(sphere_pack(P, 0.5, [60.0, 60.0]), walls=[(b, floor)], gap=1e-3,
                            periodic=False)
    assert c["wall"].tolist() == [1, 0, 0]
    assert c["elem"].tolist() == [1, 1, 0]
    assert c["rattlers"] == 1 and c["under_stable"] == 3
    # a gap of 2e-3 d is not a contact at gap 1e-3 but is one at gap 3e-3
    P2 = [[0.0, 0.502, 0.0]]
    pk = sphere_pack(P2, 0.5, [60.0, 60.0])
    assert engine_coordination(pk, [(b, floor)], gap=1e-3, periodic=False)["wall"][0] == 0
    assert engine_coordination(pk, [(b, floor)], gap=3e-3, periodic=False)["wall"][0] == 1


def test_pall_rings_agree_with_a_brute_force_tree_distance():
    """Ring pairs placed at known gaps along a line: the engine's count at gap 1e-3 D equals the
    brute-force minimum of the exact tree over the other ring's probes (both ways)."""
    el = E.pall_ring()
    from peclet.packing.bed.api import element_model
    m = element_model(el)
    ni, nr = m.node_ints, m.node_reals
    b = SceneBuilder.decode(ni, nr)
    pos, quat = [], []
    rng = np.random.default_rng(7)
    for k in range(6):
        q = rng.normal(size=4)
        pos.append([3.0 * k, 2.0, 0.0])
        quat.append(q / np.linalg.norm(q))
    pos = np.array(pos)
    quat = np.array(quat)
    # move each odd ring toward its even neighbour until the probe-tree distance is ~gap_k
    from peclet.packing.bed.freeze import rotation_matrices
    targets = [-2e-3, 5e-4, 5e-3]
    for k, tgt in enumerate(targets):
        i, j = 2 * k, 2 * k + 1
        R = rotation_matrices(quat)

        def dmin(x):
            pj = pos[i] + np.array([x, 0.0, 0.0])
            w1 = (R[j] @ m.shell.T).T + pj - pos[i]
            v1 = b.eval_root(m.home_root, w1 @ R[i]).min()
            w2 = (R[i] @ m.shell.T).T + pos[i] - pj
            v2 = b.eval_root(m.home_root, w2 @ R[j]).min()
            return min(v1, v2)
        lo, hi = 0.0, 1.5
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if dmin(mid) < tgt else (lo, mid)
        pos[j] = pos[i] + np.array([hi, 0.0, 0.0])
    pack = Pack(pos, quat, [60.0, 60.0], m.volume, ni, nr, m.home_root, m.bounding_radius,
                m.shell, m.mass, m.inv_inertia, m.envelope_root, m.envelope_volume)
    assert sphere_radius_of(pack) is None
    c = engine_coordination(pack, gap=1e-3, periodic=False)
    assert c["method"] == "engine: narrow phase"
    assert c["elem"].tolist() == [1, 1, 1, 1, 0, 0]


def test_bad_arguments_are_named():
    pk = sphere_pack([[0.0, 1.0, 0.0]], 0.5, [4.0, 4.0])
    with pytest.raises(PecletArgumentError, match="gap"):
        engine_coordination(pk, gap=-1.0)
    with pytest.raises(PecletArgumentError, match="gap"):
        engine_coordination(pk, gap=float("nan"))
    with pytest.raises(PecletArgumentError, match=r"walls\[0\]"):
        engine_coordination(pk, walls=[object()])
    with pytest.raises(PecletArgumentError, match="periodic"):
        engine_coordination(pk, periodic="no")
    with pytest.raises(PecletArgumentError, match="pack"):
        engine_coordination("pack.npz")
