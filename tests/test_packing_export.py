"""Exports (peclet.packing.export): real STL / VTU / CSV files written and read back.

The volume bound: every mesh point lies in a lattice cube whose corners change sign, so with a
1-Lipschitz phi it is within sqrt(3) h of the zero set (h the lattice step); the measured
deviation delta = max |phi| over the mesh's vertices, edge midpoints and centroids is at most
that. The enclosed region then lies between {phi < -delta} and {phi < delta}, whose volumes
differ from the solid's by delta * area to first order, so |V_mesh - V| <= delta * A_mesh.
"""
import math

import meshio
import numpy as np
import pytest
import trimesh

from peclet.core import geom
from peclet.core.validation import PecletArgumentError
from peclet.packing import export as E
from peclet.packing.elements import pall_ring, sphere
from peclet.packing.freeze import Pack

H = 0.04  # lattice step, element diameters (D = 1)


def _pack(el, pos, quats, r_b):
    ni, nr, _, _ = el.builder.encode()
    return Pack(pos, quats, (50.0, 50.0), 1.0, ni, nr, el.root, r_b, np.zeros((1, 3)), 1.0,
                [1.0, 1.0, 1.0], -1, float("nan"))


@pytest.fixture(scope="module")
def rings():
    el = pall_ring()
    q = np.random.default_rng(7).normal(size=(3, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    pos = np.array([[0.1, 0.6, 0.2], [1.7, 0.7, -0.3], [0.4, 1.9, 1.1]])
    pack = _pack(el, pos, q, math.hypot(0.5, 0.5) + 1e-9)
    vol = el.builder.body_properties(el.root, *el.bounds).volume
    return el, pack, vol, E.element_mesh(pack, H)


def _deviation(builder, root, v, f, s=0.0):
    tri = v[f]
    pts = np.vstack([v, tri.mean(axis=1), 0.5 * (tri[:, 0] + tri[:, 1]),
                     0.5 * (tri[:, 1] + tri[:, 2]), 0.5 * (tri[:, 2] + tri[:, 0])])
    return float(np.abs(builder.eval_root(root, pts) + s).max())


def _home(v, p, q):
    """World vertices back to the home frame of the pose (p, q)."""
    return (v - p) @ geom.quat_to_matrix(q)


def test_per_element_stl_reads_back_watertight_with_the_quadrature_volume(rings, tmp_path):
    el, pack, vol, (v0, f0) = rings
    path = tmp_path / "bed.stl"
    E.write_stl(path, pack, per_element=True, home_mesh=(v0, f0))
    E.write_transforms_csv(tmp_path / "t.csv", pack, "pall_ring")
    t = E.read_transforms_csv(tmp_path / "t.csv")
    scene = trimesh.load(str(path), force="scene")
    assert sorted(scene.geometry) == ["element_0", "element_1", "element_2"]
    for i in range(pack.n):
        m = scene.geometry[f"element_{i}"]  # read as a triangle soup, vertices merged on load
        assert m.is_watertight and len(m.faces) == len(f0)
        vh = _home(m.vertices, t["positions"][i], t["quaternions"][i])
        delta = _deviation(el.builder, el.root, vh, m.faces)
        assert delta <= math.sqrt(3) * H
        assert abs(m.volume - vol) <= delta * m.area
        assert m.volume < vol  # marching cubes cuts the ring's convex edges


def test_container_is_its_own_closed_solid(rings, tmp_path):
    el, pack, _, hm = rings
    R, lo, hi = 3.0, np.array([-3.5, -0.5, -3.5]), np.array([3.5, 3.0, 3.5])
    b = geom.SceneBuilder()
    wall = b.add_difference(b.add_leaf("box", [50.0, 50.0, 50.0]),
                            b.add_leaf("cone", [R, R, 60.0]))
    path = tmp_path / "bed_c.stl"
    E.write_stl(path, pack, per_element=True, container=(b, wall, lo, hi),
                container_spacing=0.15, home_mesh=hm)
    m = trimesh.load(str(path), force="scene").geometry["container"]
    assert m.is_watertight
    exact = np.prod(hi - lo) - math.pi * R * R * (hi[1] - lo[1])
    h = float((hi - lo).max()) / (math.ceil(float((hi - lo).max()) / 0.15))
    assert abs(m.volume - exact) <= math.sqrt(3) * h * m.area


def test_merged_binary_stl_and_vtu_hold_the_same_triangles(rings, tmp_path):
    _, pack, _, (v0, f0) = rings
    E.write_stl(tmp_path / "m.stl", pack, per_element=False, home_mesh=(v0, f0))
    m = trimesh.load(str(tmp_path / "m.stl"), process=False)
    assert len(m.faces) == pack.n * len(f0)
    tri = m.triangles.reshape(pack.n, len(f0), 3, 3)
    for i in range(pack.n):
        assert trimesh.Trimesh(tri[i].reshape(-1, 3), np.arange(3 * len(f0)).reshape(-1, 3)) \
            .is_watertight
    info = E.write_vtu(tmp_path / "bed.vtu", pack, home_mesh=(v0, f0), compress=False)
    vt = meshio.read(tmp_path / "bed.vtu")
    cells = vt.cells_dict["triangle"]
    ids = vt.cell_data_dict["element_id"]["triangle"]
    assert len(cells) == info["n_triangles"] == pack.n * len(f0)
    assert np.array_equal(np.bincount(ids), np.full(pack.n, len(f0)))
    # binary STL stores float32: the VTU's float64 triangles agree to single precision
    assert np.allclose(vt.points[cells].reshape(tri.shape), tri, rtol=0, atol=1e-6)


def test_transforms_csv_round_trips_bit_for_bit(tmp_path):
    el = sphere(0.5)
    pos = np.array([[0.1, 1 / 3, 1e-300], [-2.5e-17, 7.000000000000001, 12345.678901234567]])
    q = np.array([[0.1, 0.2, 0.3, math.sqrt(1 - 0.14)], [0.0, 0.0, 0.0, 1.0]])
    pack = _pack(el, pos, q, 0.5)
    E.write_transforms_csv(tmp_path / "t.csv", pack, "sphere")
    t = E.read_transforms_csv(tmp_path / "t.csv")
    assert t["ids"].tolist() == [0, 1] and t["element"] == ["sphere", "sphere"]
    assert np.array_equal(t["positions"], pack.positions)
    assert np.array_equal(t["quaternions"], pack.quaternions)
    assert open(tmp_path / "t.csv").readline().strip() == "id,element,x,y,z,qx,qy,qz,qw"


def test_shrink_offsets_the_sphere_and_opens_its_contact(tmp_path):
    el = sphere(0.5)
    s = 0.01
    pack = _pack(el, [[0.0, 0.5, 0.0], [1.0, 0.5, 0.0]], np.tile([0, 0, 0, 1.0], (2, 1)), 0.5)
    E.write_stl(tmp_path / "s.stl", pack, per_element=True, shrink=s, spacing=H)
    sc = trimesh.load(str(tmp_path / "s.stl"), force="scene")
    a, b = sc.geometry["element_0"], sc.geometry["element_1"]
    for m in (a, b):
        assert m.is_watertight
        delta = _deviation(el.builder, el.root, m.vertices - m.vertices.mean(0), m.faces, s)
        assert abs(m.volume - 4 / 3 * math.pi * (0.5 - s) ** 3) <= delta * m.area
    # the touching pair is opened: a's surface stays about s outside b's true solid
    phi_b = el.builder.eval_root(el.root, a.vertices - [1.0, 0.5, 0.0])
    assert phi_b.min() > 0.5 * s


def test_bad_arguments_are_named_and_nothing_is_written(rings, tmp_path):
    _, pack, _, hm = rings
    b = geom.SceneBuilder()
    box = b.add_leaf("box", [1.0, 1.0, 1.0])
    with pytest.raises(PecletArgumentError, match="per_element"):
        E.write_stl(tmp_path / "x.stl", pack, container=(b, box, -2, 2), home_mesh=hm)
    with pytest.raises(PecletArgumentError, match="shrink"):
        E.element_mesh(pack, shrink=0.3)
    with pytest.raises(PecletArgumentError, match="shrink"):  # eats the 0.12 D wall
        E.element_mesh(pack, spacing=0.05, shrink=0.19)
    with pytest.raises(PecletArgumentError, match="path"):
        E.write_stl(tmp_path, pack, home_mesh=hm)
    with pytest.raises(PecletArgumentError, match="element"):
        E.write_transforms_csv(tmp_path / "t.csv", pack, "a,b")
    assert list(tmp_path.iterdir()) == []
