"""Exports (peclet.packing.output.export): real STL / VTU / CSV files written and read back.

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
from peclet.packing.output import export as E
from peclet.packing.bed.elements import pall_ring, sphere
from peclet.packing.bed.freeze import Pack

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


# ---- export resolution and layouts (issue 26, item 5) ---------------------------------------

#: Stated tolerance on the enclosed volume of a Pall ring at the default resolution (measured
#: -0.9 %) and at the coarse 400 triangles (measured about -1.5 %), relative to the exact volume.
VOL_TOL_DEFAULT = 0.02
VOL_TOL_COARSE = 0.04


@pytest.fixture(scope="module")
def ring_bed():
    """Four Pall rings at random poses, ring_volume the quadrature volume (D = 1)."""
    el = pall_ring()
    vol = el.builder.body_properties(el.root, *el.bounds).volume
    q = np.random.default_rng(11).normal(size=(4, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    pos = np.array([[0.0, 0.8, 0.0], [1.5, 0.8, 0.0], [0.0, 0.8, 1.5], [1.5, 2.3, 1.5]])
    ni, nr, _, _ = el.builder.encode()
    pack = Pack(pos, q, (50.0, 50.0), vol, ni, nr, el.root, math.hypot(0.5, 0.5) + 1e-9,
                np.zeros((1, 3)), 1.0, [1.0, 1.0, 1.0], -1, float("nan"))
    return el, pack, vol, E.export_mesh(pack, min_feature=el.min_feature)


def _solids(directory):
    return sorted(p.name for p in directory.iterdir())


def test_default_resolution_per_element_files_are_watertight_with_the_volume(ring_bed,
                                                                             tmp_path):
    el, pack, vol, (v0, f0, info) = ring_bed
    assert E.DEFAULT_RESOLUTION == "1000tri" and info["resolution"] == "1000tri"
    assert info["triangles"] == len(f0) == 1000 and info["watertight"]
    assert abs(info["volume_rel_error"]) <= VOL_TOL_DEFAULT
    out = E.write_stl_files(tmp_path / "bed_stl", pack, home_mesh=(v0, f0))
    names = [f"element_{i}.stl" for i in range(pack.n)]
    assert out["files"] == names == _solids(tmp_path / "bed_stl")
    t = E.read_transforms_csv(E.write_transforms_csv(tmp_path / "t.csv", pack))
    for i, nm in enumerate(names):
        p = tmp_path / "bed_stl" / nm
        assert p.stat().st_size == 84 + 50 * 1000  # binary STL
        m = trimesh.load(str(p))  # vertices merged on load, as a CFD mesher reads it
        assert m.is_watertight and m.is_winding_consistent and len(m.faces) == 1000
        assert abs(m.volume - vol) <= VOL_TOL_DEFAULT * vol
        vh = _home(m.vertices, t["positions"][i], t["quaternions"][i])
        # the chord error is what export_mesh reported (float32 rounding aside)
        assert _deviation(el.builder, el.root, vh, m.faces) <= info["chord_error"] + 1e-5


@pytest.mark.heavy
def test_coarse_budget_and_chord_error_are_followed_and_stay_closed(ring_bed, tmp_path):
    el, pack, vol, (_, _, default) = ring_bed
    coarse = E.export_mesh(pack, "400tri", min_feature=el.min_feature)
    fine = E.export_mesh(pack, "2000tri", min_feature=el.min_feature)
    assert len(coarse[1]) == 400 and len(fine[1]) == 2000
    for v, f, info in (coarse, fine):
        assert info["watertight"] and trimesh.Trimesh(v, f, process=False).is_watertight
    assert abs(coarse[2]["volume_rel_error"]) <= VOL_TOL_COARSE
    assert fine[2]["chord_error"] <= coarse[2]["chord_error"]
    # a chord error: the mesh keeps within it, with fewer triangles for a looser one
    v, f, info = E.export_mesh(pack, "0.02D", min_feature=el.min_feature)
    assert info["chord_error"] <= 0.02
    assert _deviation(el.builder, el.root, v, f) <= 0.02
    assert info["triangles"] < default["triangles"] * 1.2
    assert abs(info["volume_rel_error"]) <= VOL_TOL_COARSE
    # same arguments, same mesh
    v2, f2, _ = E.export_mesh(pack, 0.02, min_feature=el.min_feature)
    assert np.array_equal(v, v2) and np.array_equal(f, f2)
    # written at the coarse budget and read back: per element closed, 400 triangles each
    E.write_stl(tmp_path / "c.stl", pack, home_mesh=coarse[:2])
    tri = trimesh.load(str(tmp_path / "c.stl"), process=False).triangles
    for k in range(pack.n):
        m = trimesh.Trimesh(tri[400 * k:400 * (k + 1)].reshape(-1, 3),
                            np.arange(1200).reshape(-1, 3))
        assert m.is_watertight and abs(m.volume - vol) <= VOL_TOL_COARSE * vol


def test_vtu_at_the_resolution_and_default_sizes_for_1000_elements(ring_bed, tmp_path):
    _, pack, _, (v0, f0, _) = ring_bed
    info = E.write_vtu(tmp_path / "bed.vtu", pack, home_mesh=(v0, f0))
    vt = meshio.read(tmp_path / "bed.vtu")
    ids = vt.cell_data_dict["element_id"]["triangle"]
    assert len(vt.cells_dict["triangle"]) == info["n_triangles"] == 1000 * pack.n
    assert np.array_equal(np.bincount(ids), np.full(pack.n, 1000))
    for k in range(pack.n):  # each element's cells close on the VTU's shared points
        m = trimesh.Trimesh(vt.points, vt.cells_dict["triangle"][ids == k])
        assert m.is_watertight
    s = E.write_stl(tmp_path / "bed.stl", pack, home_mesh=(v0, f0))
    # the README's figure: 1000 elements at the default, STL 50 bytes a triangle exactly and
    # the VTU (zlib) under 30 bytes a triangle here (22.5 MB measured for 1000 Pall rings)
    assert s["bytes"] == 84 + 50 * 1000 * pack.n
    assert info["bytes"] / info["n_triangles"] < 30
    assert 84 + 50 * 1000 * 1000 + 30 * 1000 * 1000 < 100e6


def test_per_element_layout_with_a_container_and_rewrite(ring_bed, tmp_path):
    _, pack, _, (v0, f0, _) = ring_bed
    b = geom.SceneBuilder()
    wall = b.add_difference(b.add_leaf("box", [50.0, 50.0, 50.0]),
                            b.add_leaf("cone", [3.0, 3.0, 60.0]))
    box = (b, wall, np.array([-3.5, -0.5, -3.5]), np.array([3.5, 3.0, 3.5]))
    d = tmp_path / "bed_stl"
    E.write_stl_files(d, pack, home_mesh=(v0, f0),
                      container=box, container_spacing=0.25, name="ring")
    assert _solids(d) == ["container.stl"] + [f"ring_{i}.stl" for i in range(pack.n)]
    assert trimesh.load(str(d / "container.stl")).is_watertight
    E.write_stl_files(d, pack, home_mesh=(v0, f0))  # replaces the set whole
    assert _solids(d) == [f"element_{i}.stl" for i in range(pack.n)]
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".peclet")]
    # the container decimated to a budget stays closed, meshed once for the VTU
    full = E.container_mesh(*box, spacing=0.25)
    cv, cf = E.container_mesh(*box, spacing=0.25, max_triangles=len(full[1]) // 8)
    cm = trimesh.Trimesh(cv, cf, process=False)
    assert len(cf) <= len(full[1]) // 8 and cm.is_watertight
    assert cm.volume == pytest.approx(trimesh.Trimesh(*full).volume, rel=0.02)
    E.write_vtu(tmp_path / "c.vtu", pack, container=(cv, cf), home_mesh=(v0, f0))
    ids = meshio.read(tmp_path / "c.vtu").cell_data_dict["element_id"]["triangle"]
    assert np.sum(ids == -1) == len(cf)


@pytest.mark.parametrize("bad", [-0.01, 0.0, float("nan"), float("inf"), 0.001, 0.5, "abc",
                                 "", "10tri", "0tri", "-5tri", "1.5tri", "1e9tri", True,
                                 None, [0.01]])
def test_bad_resolutions_are_refused_naming_the_argument(ring_bed, tmp_path, bad):
    _, pack, _, hm = ring_bed
    with pytest.raises(PecletArgumentError, match="^resolution must be"):
        E.parse_resolution(bad)
    with pytest.raises(PecletArgumentError, match="^resolution must be"):
        E.write_stl(tmp_path / "x.stl", pack, resolution=bad)
    assert list(tmp_path.iterdir()) == []


def test_memory_caps_are_refused_naming_the_argument(ring_bed, tmp_path, monkeypatch):
    _, pack, _, (v0, f0, _) = ring_bed
    with pytest.raises(PecletArgumentError, match="stl_resolution.*whole bed"):
        E.check_bed_triangles(1000, "200000tri", "stl_resolution")
    E.check_bed_triangles(1000, E.DEFAULT_RESOLUTION)  # the default passes
    # the caps are read in the modules that use them (export.py only gathers the names)
    from peclet.packing.output import meshing, vtu

    monkeypatch.setattr(vtu, "MAX_BED_TRIANGLES", 3 * 1000)
    with pytest.raises(PecletArgumentError, match="^resolution must be at most 3000"):
        E.write_vtu(tmp_path / "x.vtu", pack, home_mesh=(v0, f0))
    monkeypatch.setattr(meshing, "EXPORT_LATTICE_MAX", 64)
    with pytest.raises(PecletArgumentError, match="memory"):
        E.export_mesh(pack, "0.01")
    assert list(tmp_path.iterdir()) == []


def test_cli_refuses_bad_export_options_in_one_line(tmp_path, capsys):
    from peclet.cli import main

    for argv, flag in ((["--stl-resolution", "-1"], "--stl-resolution"),
                       (["--stl-resolution", "nan"], "--stl-resolution"),
                       (["--stl-resolution", "0"], "--stl-resolution"),
                       (["--stl-resolution", "5tri"], "--stl-resolution"),
                       (["--stl-layout", "flat"], "--stl-layout")):
        with pytest.raises(SystemExit) as exc:
            main(["pack", "--out", str(tmp_path / "o")] + argv)
        assert exc.value.code == 2
        err = capsys.readouterr().err.strip()
        assert "\n" not in err and flag in err
    assert list(tmp_path.iterdir()) == []
