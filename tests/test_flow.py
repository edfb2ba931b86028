"""peclet.flow at reduced size: the validation ladder's rungs, determinism across threads, bad
input, and the command line on a tiny pack (validation/flow.py runs the full sizes)."""
import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from peclet.core.validation import PecletArgumentError
from peclet.flow import Grid, build_geometry, solve
from validation import flow as vf

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.parametrize("q", [0.1, 0.3, 0.5, 0.7])
def test_slit_poiseuille_is_exact_for_any_wall_fraction(q):
    # TRT with magic 3/16 + the corrected linear rule: exact parabola for any q (tolerance-
    # limited at 1e-12 convergence; plain bounce-back is exact only at q = 1/2)
    assert vf.slit(q, n=6)["err"] < 1e-9


def test_plain_bouzidi_is_not_exact_but_second_order_in_a_pipe():
    e4 = vf.pipe(3.0, scheme="bouzidi", tol=1e-9)["err"]
    e8 = vf.pipe(6.0, scheme="bouzidi", tol=1e-9)["err"]
    assert e4 > 1e-3
    assert 1.6 < np.log2(e4 / e8) < 3.0          # 2.64 here: q differs between the radii
    assert vf.pipe(3.0, tol=1e-10)["err"] < 1e-7


def test_zick_homsy_dense_array_within_two_percent_at_16_cells():
    r = vf.sphere_array(0.5236, 16, tol=1e-7)
    assert abs(r["err"]) <= 0.02
    assert abs(r["balance"] - 1.0) < 1e-3        # wall force = body force at steady state


def test_zick_homsy_rows_rerun_replace_and_the_rest_are_marked_earlier():
    # validation/flow.py --zh-fractions/--zh-resolutions with --json: the rows run replace the
    # file's rows of the same fraction and resolution; the rows kept from before the
    # convergence field say they are from the earlier scheme, and so does an order using one
    old = [{"c": 0.125, "cells_per_d": 8.06, "err": -0.0087, "K": 4.25},
           {"c": 0.125, "cells_per_d": 16.13, "err": 0.0046, "K": 4.31},
           {"c": 0.5236, "cells_per_d": 8.0, "err": -0.0186, "K": 41.3}]
    new = [{"c": 0.125, "resolution": 8, "cells_per_d": 8.06, "err": -0.0088, "K": 4.254,
            "convergence": vf.CURRENT}]
    rows = vf._zh_merge(old, new)
    assert [(z["c"], z["resolution"]) for z in rows] == [(0.125, 8), (0.125, 16), (0.5236, 8)]
    assert rows[0] is new[0] and rows[1]["convergence"] == rows[2]["convergence"] == vf.EARLIER
    assert rows[1]["order_note"] == "from a row of the earlier scheme"
    assert rows[1]["order"] == pytest.approx(np.log(0.0088 / 0.0046) / np.log(16.13 / 8.06))
    assert vf._zh_ladder((0.5236,), (16, 8), False) == [(0.5236, 8), (0.5236, 16)]


@pytest.mark.parametrize("args, flag", [(["--zh-fractions", "0.3"], "--zh-fractions"),
                                        (["--zh-resolutions", "2,8"], "--zh-resolutions"),
                                        (["--column-resolutions", "8,x"],
                                         "--column-resolutions")])
def test_validation_options_refuse_bad_values_in_one_line(args, flag):
    p = subprocess.run([sys.executable, os.path.join(ROOT, "validation", "flow.py"), *args],
                       capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert p.returncode == 2 and flag in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1


def test_zick_homsy_dilute_array_at_8_cells():
    r = vf.sphere_array(0.125, 8, tol=1e-7)
    assert abs(r["err"]) <= 0.02


def test_thin_wall_between_fluid_nodes_is_cut_and_takes_the_force():
    grid = Grid((0.0, 0.0, 0.0), 1.0, (3, 8, 3), (True, True, True))
    phi = lambda p: np.abs(np.mod(p[:, 1] - 3.5 + 4.0, 8.0) - 4.0) - 0.1
    geo = build_geometry(grid, phi)
    assert geo.n_fluid == grid.n_cells and geo.thin_links == 2 * 5 * 9
    r = solve(geo, [0.0, 1e-6, 0.0], tol=1e-10, max_steps=3000)
    assert r.link_force[:, 1].sum() / (1e-6 * geo.n_fluid) == pytest.approx(1.0, abs=1e-9)


def _plate():
    # a plate 0.2 cells thick between node planes (walls at q = 0.4 of the links): both
    # neighbours are fluid, yet no link may cross it, so the flow through it (along y) stops
    grid = Grid((0.0, 0.0, 0.0), 1.0, (3, 8, 3), (True, True, True))
    phi = lambda p: np.abs(np.mod(p[:, 1] - 3.5 + 4.0, 8.0) - 4.0) - 0.1
    return build_geometry(grid, phi)


@pytest.mark.parametrize("scheme", ["linear", "bouzidi"])
def test_thin_wall_between_fluid_nodes_blocks_the_flow(scheme):
    geo = _plate()
    assert geo.n_fluid == geo.grid.n_cells and geo.thin_links > 0
    F = 1e-6
    r = solve(geo, [0.0, F, 0.0], tol=1e-10, max_steps=4000, scheme=scheme)
    # the mass flux over uncut links: zero once the wall rule conserves mass node by node
    assert abs(r.U[1]) < 1e-6 * F
    assert abs(r.mass_drift) < 1e-12
    # the hydrostatic state: dp/dy = F, p = rho / 3, so rho rises 3 F per cell from the
    # plate's top face (y = 4, unwrapped -4) to its bottom face (y = 3); nodes off the plate
    y = np.where(geo.ijk[:, 1] <= 3, geo.ijk[:, 1], geo.ijk[:, 1] - 8)
    bulk = (y >= -3) & (y <= 2)
    slope = np.polyfit(y[bulk], r.rho[bulk], 1)[0]
    assert slope == pytest.approx(3.0 * F, rel=1e-4)


def test_even_mass_correction_leaks_through_a_thin_wall():
    # the mechanism the local correction removes: with only the domain's total mass put back,
    # the interpolation destroys mass on the plate's high-pressure face and makes it on the
    # other, so mass "crosses" the plate and every other plane carries a flux
    geo = _plate()
    F = 1e-6
    r = solve(geo, [0.0, F, 0.0], tol=1e-10, max_steps=4000, mass="global")
    assert r.U[1] > 0.05 * F
    # the mean node velocity is not a flux: beside the plate it is not zero even when no
    # mass crosses it (local correction)
    r2 = solve(geo, [0.0, F, 0.0], tol=1e-10, max_steps=4000)
    assert abs(r2.U_nodes[1]) > 1e-3 * F and abs(r2.U[1]) < 1e-6 * F


def _slot(thickness):
    # a slot (fluid |y - 2| < thickness / 2) cut through a solid block, beside an open channel
    # (x in (3.5, 5.5)); a slot thinner than a cell leaves its inner nodes with every link
    # that has a component along y cut
    grid = Grid((0.0, 0.0, 0.0), 1.0, (6, 6, 3), (True, True, True))

    def phi(p):
        dx = np.mod(p[:, 0] - 4.5 + 3.0, 6.0) - 3.0
        dy = np.mod(p[:, 1] - 2.0 + 3.0, 6.0) - 3.0
        return np.maximum(1.0 - np.abs(dx), 0.5 * thickness - np.abs(dy))
    return build_geometry(grid, phi)


def test_the_period_2_mode_lives_on_nodes_enclosed_along_the_force():
    # (peclet.flow.solver, "Its source"): the collision conserves such a node's momentum along
    # the force and bounce-back reverses it, so the wall force alternates step by step and
    # barely decays; the two-step means still close the balance. A slot 3 cells thick: none.
    from peclet.flow.lattice import C
    along = C[:, 1] != 0
    geo = _slot(0.8)
    enclosed = np.all(geo.nb[along] < 0, axis=0)
    assert enclosed.sum() == 6
    r1 = solve(geo, [0.0, 1e-6, 0.0], tol=1e-30, max_steps=200, check_every=50)
    r2 = solve(geo, [0.0, 1e-6, 0.0], tol=1e-30, max_steps=2000, check_every=50)
    assert r1.parity_swing > 0.2 and r2.parity_swing > 0.98 * r1.parity_swing
    assert abs(r2.balance - 1.0) < 1e-8
    thick = _slot(2.8)
    assert not np.all(thick.nb[along] < 0, axis=0).any()
    r3 = solve(thick, [0.0, 1e-6, 0.0], tol=1e-30, max_steps=200, check_every=50)
    assert r3.parity_swing < 1e-3 * r1.parity_swing


def test_open_axis_without_walls_is_refused():
    grid = Grid((0.0, 0.0, 0.0), 1.0, (4, 4, 4), (True, False, True))
    with pytest.raises(PecletArgumentError, match="axis y is not periodic"):
        build_geometry(grid, lambda p: np.ones(len(p)))


_DETERMINISM = textwrap.dedent("""
    import hashlib, sys
    sys.path.insert(0, %r)
    from validation import flow as vf
    import numpy as np
    from peclet.flow import Grid, build_geometry, solve
    L, a = 12, 4.3
    def phi(p):
        d = p - 5.2
        d -= L * np.round(d / L)
        return np.sqrt((d * d).sum(1)) - a
    geo = build_geometry(Grid((0., 0., 0.), 1.0, (L, L, L), (True, True, True)), phi)
    r = solve(geo, [1e-6, 2e-7, 0.], tol=1e-30, max_steps=150, check_every=50)
    print(hashlib.sha256(r.u.tobytes() + r.U.tobytes() + r.link_force.tobytes()).hexdigest())
""") % ROOT


def test_same_bits_at_one_and_two_threads():
    out = []
    for n in ("1", "2"):
        env = dict(os.environ, NUMBA_NUM_THREADS=n)
        p = subprocess.run([sys.executable, "-c", _DETERMINISM], env=env, capture_output=True,
                           text=True, timeout=300)
        assert p.returncode == 0, p.stderr
        out.append(p.stdout.strip())
    assert out[0] == out[1] and len(out[0]) == 64


@pytest.fixture(scope="module")
def tiny_pack(tmp_path_factory):
    """12 spheres placed by hand in a periodic box:2 (a pack file as peclet writes it)."""
    from peclet.core import geom
    from peclet.packing.bed.freeze import Pack, save_pack
    b = geom.SceneBuilder()
    root = b.add_leaf("sphere", [0.5])
    ni, nr, _, _ = b.encode()
    rng = np.random.default_rng(4)
    pos = np.array([[0.5, 0.5, 0.5], [1.5, 0.5, 1.5], [0.5, 0.5, 1.5], [1.5, 0.5, 0.5],
                    [1.0, 1.2, 1.0], [0.0, 1.2, 0.0], [1.0, 1.2, 0.0], [0.0, 1.2, 1.0],
                    [0.5, 1.9, 0.5], [1.5, 1.9, 1.5], [0.5, 1.9, 1.5], [1.5, 1.9, 0.5]])
    pos += rng.uniform(-0.02, 0.02, pos.shape)
    pk = Pack(positions=pos, quaternions=np.tile([0.0, 0.0, 0.0, 1.0], (12, 1)),
              box=np.array([2.0, 2.0]), ring_volume=np.pi / 6, node_ints=ni, node_reals=nr,
              home_root=root, bounding_radius=0.5, shell=np.zeros((0, 3)), mass=np.nan,
              inv_inertia=np.full(3, np.nan))
    path = tmp_path_factory.mktemp("pack") / "pack.npz"
    save_pack(str(path), pk)
    return str(path)


def test_cli_flow_writes_real_files(tiny_pack, tmp_path):
    from peclet.flow.output import read_vti
    out = tmp_path / "flow"
    p = subprocess.run([sys.executable, "-m", "peclet.cli", "flow", tiny_pack, "--resolutions",
                        "6,8", "--window", "0.5,1.9", "--out", str(out), "--quiet",
                        "--tol", "1e-5"], capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert p.returncode == 0, p.stderr
    assert "k extrapolated" in p.stdout
    res = json.loads((out / "results.json").read_text())
    assert len(res["runs"]) == 2 and res["richardson"]["k0"] > 0
    r8 = res["runs"][1]
    assert 0.1 < r8["eps"] < 0.9 and r8["k_D2"] > 0 and r8["converged"]
    # a box pack along y: k from the body force over the wrapped window's whole period (its
    # seam included; peclet.flow.permeability), the force balance its check
    assert r8["dpdl_source"].startswith("body force (whole period of the wrapped window")
    assert r8["k_D2"] == pytest.approx(r8["k_D2_period"], rel=1e-12)
    assert abs(r8["solid_drag_balance"] - 1.0) < 1e-4
    assert "wall force / body force" in p.stdout
    v = read_vti(str(out / "velocity.vti"))
    nx, ny, nz = v["dims"]
    assert v["velocity"].shape == (nz, ny, nx, 3)
    fluid = v["fluid"].astype(bool)
    assert np.all(v["velocity"][~fluid] == 0) and np.all(v["speed"][fluid] >= 0)
    # the mean node velocity from the file is the run's k_D2_node_mean (k = nu U / g); the
    # reported k is from the mass flux over uncut links, which in this dense pack (eps 0.24,
    # pores of 1-2 cells at D/8) is 27% lower: the node sum over-counts the gaps
    U = v["velocity"][..., 1].mean()
    k_lu = r8["nu"] * U / r8["force"]
    assert k_lu == pytest.approx(r8["k_D2_node_mean"] * 8.0 ** 2, rel=1e-9)
    assert 0.5 < r8["k_lattice"] / k_lu < 1.0
    import meshio
    m = meshio.read(str(out / "velocity.vtu"))
    assert len(m.points) == fluid.sum()
    assert (out / "slice.png").stat().st_size > 1000


def test_cli_refuses_a_file_that_is_not_a_pack(tmp_path):
    bad = tmp_path / "x.npz"
    np.savez(bad, a=np.zeros(3))
    p = subprocess.run([sys.executable, "-m", "peclet.cli", "flow", str(bad), "--out",
                        str(tmp_path / "o")], capture_output=True, text=True, cwd=ROOT)
    assert p.returncode == 2 and "pack" in p.stderr and "missing fields" in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("args, flag", [(["--resolution", "D/2"], "--resolution"),
                                        (["--resolutions", "8"], "--resolutions"),
                                        (["--y-mode", "open"], "--y-mode"),
                                        (["--re", "0"], "--re"), (["--axis", "w"], "--axis")])
def test_cli_bad_options_are_one_line(tiny_pack, tmp_path, args, flag):
    p = subprocess.run([sys.executable, "-m", "peclet.cli", "flow", tiny_pack, *args, "--out",
                        str(tmp_path / "o")], capture_output=True, text=True, cwd=ROOT)
    assert p.returncode == 2 and flag in p.stderr
    assert not (tmp_path / "o").exists()


def test_thin_wall_warning_names_the_wall(tiny_pack):
    # spheres of diameter 1: at D/4 the "wall" (the sphere) spans 4 cells: no warning; a
    # ring wall 0.12 D thick would be named. Check the rule on a pack's tree directly.
    from peclet.flow.permeability import thinnest_wall
    from peclet.packing.bed.freeze import load_pack
    t, name = thinnest_wall(load_pack(tiny_pack))
    assert t == pytest.approx(1.0) and "sphere" in name


@pytest.mark.heavy
def test_page_pipeline_with_flow_adds_k_and_ergun(tmp_path):
    # the page at reduced size (tests/test_packing_pipeline.py's stand-in particle, 6 rings,
    # 0.14 of the steps) with the flow at D/6: k and dP/L / Ergun in results.json and the table
    from peclet.flow import page
    from peclet.packing.page import pipeline
    from test_packing_pipeline import standin_particle
    lines = []
    res = pipeline.run(out=str(tmp_path / "pall"), rings=6, seed=2, steps_scale=0.14, box=3.5,
                       mc_samples=20_000, sweep=(), mesh_n=60, progress=False,
                       write_figures=False, particle=standin_particle(), log=lines.append,
                       stages={"flow": page.stage(6)})
    fl = res["flow"]
    saved = json.loads((tmp_path / "pall" / "results.json").read_text())["flow"]
    assert saved["k_D2"] == fl["k_D2"] and fl["resolution"] == 6.0
    assert fl["converged"] and fl["dims"][0] == 21 and fl["y_mode"] == "wrap"
    assert fl["k_D2"] > 0 and 0.0 < fl["ergun_ratio_sauter"] < 10.0
    # the definitions tie the outputs together: Ergun ratio = eps^3 d^2 / (150 k (1-eps)^2)
    e, d = fl["eps"], fl["d_sauter"]
    assert fl["ergun_ratio_sauter"] == pytest.approx(e ** 3 * d ** 2
                                                     / (150 * fl["k_D2"] * (1 - e) ** 2))
    table = "\n".join(lines)
    assert "permeability k (lattice Boltzmann, D/6)" in table and f"{fl['k_D2']:.4g}" in table
    assert "dP/L / Ergun viscous term" in table


def test_page_flow_stage_refuses_a_resolution_off_the_box(tmp_path):
    from peclet.flow.page import check_resolution
    with pytest.raises(PecletArgumentError, match="flow"):
        check_resolution(7.3, 3.5)
    assert check_resolution(8, 3.5) == 8.0


@pytest.mark.parametrize("stages", [[("flow", print)], {"flow": 3}, {1: print},
                                    {"timing": print}])
def test_page_pipeline_refuses_bad_stages_before_any_work(tmp_path, stages):
    from peclet.packing.page import pipeline
    with pytest.raises(PecletArgumentError, match="stages"):
        pipeline.run(out=str(tmp_path / "p"), rings=6, steps_scale=0.14, stages=stages)
    assert not (tmp_path / "p").exists()


@pytest.mark.parametrize("args, flag", [(["--flow", "--flow-resolution", "D/3"],
                                         "--flow-resolution"),
                                        (["--flow", "--flow-resolution", "D/9.1"],
                                         "--flow-resolution"),
                                        (["--flow-resolution", "D/8"], "--flow-resolution")])
def test_pall_ring_cli_refuses_a_bad_flow_option(tmp_path, args, flag):
    p = subprocess.run([sys.executable, "-m", "peclet.cli", "pall-ring", "--out",
                        str(tmp_path / "o"), *args], capture_output=True, text=True, cwd=ROOT,
                       timeout=300)
    assert p.returncode == 2 and flag in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


def _links_agree(geo):
    """Links streamed one way but bounced back the other (0 when every link has one verdict)."""
    from peclet.flow.lattice import C, OPP
    dims = np.array(geo.grid.dims)
    bad = 0
    for i in range(1, 19):
        c = (geo.ijk - C[i]) % dims
        m = geo.cell[c[:, 0] + dims[0] * (c[:, 1] + dims[1] * c[:, 2])]
        back = (m >= 0) & (geo.nb[OPP[i], np.maximum(m, 0)] >= 0)
        bad += int(np.count_nonzero((geo.nb[i] >= 0) != back))
    return bad


def test_a_wrapped_window_has_one_verdict_per_link_and_conserves_mass(tiny_pack):
    # the window [0.45, 1.85] wrapped: the field jumps at the seam, and the samples at the
    # links' midpoints fall on it, so the two ends of a link can disagree without the fix
    from peclet.flow.permeability import pack_domain
    from peclet.packing.bed.freeze import load_pack
    grid, phi, info = pack_domain(load_pack(tiny_pack), 8, (0.45, 1.85), "wrap")
    geo = build_geometry(grid, phi, seams=(False, True, False))
    assert _links_agree(geo) == 0
    r = solve(geo, [0.0, 1e-6, 0.0], tol=1e-30, max_steps=200, check_every=100)
    assert abs(r.mass_drift) < 1e-13
