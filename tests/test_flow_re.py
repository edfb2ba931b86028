"""peclet.flow beyond creeping flow (issue 44), at reduced size: the correlations, the
Forchheimer fit, the honest stops of the pressure-drop curve, the tube referee for thin walls,
grown (triply periodic) packs through ``peclet flow``, and the default grid study.
validation/flow_re.py runs the full sizes."""
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

from peclet.core.validation import PecletArgumentError
from peclet.flow import correlations as cor
from peclet.flow.curve import forchheimer_fit, oscillation_stop, parse_reynolds

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_ergun_and_eisfeld_schnitzlein_are_their_formulas():
    e, d, mu, rho, U = 0.4, 2e-3, 1.8e-5, 1.2, 0.5
    dp, visc = cor.ergun(U, e, d, mu, rho)
    assert visc == pytest.approx(150 * 0.36 / 0.064 * mu * U / d ** 2, rel=1e-14)
    assert dp - visc == pytest.approx(1.75 * 0.6 / 0.064 * rho * U * U / d, rel=1e-14)
    # no wall: A_w = 1 and B_w = k2^2; a column of 5 d: the published wall terms
    es, A_w, B_w = cor.eisfeld_schnitzlein(U, e, d, math.inf, mu, rho)
    assert A_w == 1.0 and B_w == pytest.approx(0.87 ** 2)
    es, A_w, B_w = cor.eisfeld_schnitzlein(U, e, d, 5 * d, mu, rho)
    assert A_w == pytest.approx(1 + 2 / (3 * 5 * 0.6)) and B_w == pytest.approx((1.15 / 25 + 0.87) ** 2)
    assert cor.carman_kozeny(e, 1.0) == pytest.approx(0.064 / (180 * 0.36))
    with pytest.raises(PecletArgumentError, match="eps"):
        cor.ergun(U, 1.2, d, mu)


def test_happel_kozeny_rises_with_voidage_from_the_granular_value():
    # the cell model's Kozeny constant: near Carman's 5 for granular beds, well above Ergun's
    # 150/36 at the voidage of a ring bed; and its dilute limit is Stokes drag on each sphere
    K = [cor.happel_kozeny(e) for e in (0.36, 0.4, 0.6, 0.8, 0.9)]
    assert 4.3 < K[1] < 4.8 and all(b > a for a, b in zip(K, K[1:]))
    assert K[3] / cor.ergun_kozeny() > 1.6
    e = 0.999
    k_dilute = 1.0 / (18.0 * (1 - e))            # Stokes: n 3 pi mu d U = 18 mu U (1-e) / d^2
    k = e ** 3 / (36 * cor.happel_kozeny(e) * (1 - e) ** 2)
    assert 0.8 < k / k_dilute < 1.0              # the cell's hindrance: 1 - 1.5 gamma + ...


def test_forchheimer_fit_recovers_k_and_beta_with_errors():
    Re = np.geomspace(0.01, 100, 8)
    A, B = 1500.0, 20.0
    exact = forchheimer_fit(Re, A * Re + B * Re ** 2)
    assert exact["k_D2"] == pytest.approx(1 / A, rel=1e-10)
    assert exact["beta_D"] == pytest.approx(B, rel=1e-8) and exact["k_se"] < 1e-12
    rng = np.random.default_rng(2)
    noisy = forchheimer_fit(Re, (A * Re + B * Re ** 2) * (1 + 0.01 * rng.standard_normal(8)))
    assert noisy["k_se"] > 0 and noisy["beta_se"] > 0
    assert abs(noisy["k_D2"] - 1 / A) < 4 * noisy["k_se"]
    assert abs(noisy["beta_D"] - B) < 4 * noisy["beta_se"]
    two = forchheimer_fit(Re[:2], A * Re[:2] + B * Re[:2] ** 2)
    assert math.isnan(two["k_se"]) and forchheimer_fit(Re[:1], Re[:1]) is None


def test_reynolds_ranges_parse_or_are_refused_naming_the_flag():
    r = parse_reynolds("0.01:100:5")
    assert len(r) == 5 and r[0] == pytest.approx(0.01) and r[-1] == pytest.approx(100.0)
    assert r[2] == pytest.approx(1.0)
    assert parse_reynolds("3,1") == (1.0, 3.0)
    for bad in ("0:10:3", "1:2000:3", "1:10:0", "x", "-1", "1:2"):
        with pytest.raises(PecletArgumentError, match="--reynolds"):
            parse_reynolds(bad, "--reynolds")


def test_an_oscillating_history_stops_and_a_decaying_one_does_not():
    stop = oscillation_stop(1e-6)
    osc = [(i, 1.0 + 0.01 * (-1) ** i, 1.0) for i in range(20)]
    assert "oscillating" in stop(osc)
    decay = [(i, 1.0 + 0.01 * (-0.5) ** i, 1.0) for i in range(20)]
    assert stop(decay) == ""
    assert stop(osc[:5]) == ""


def test_the_tube_referee_bore_is_hagen_poiseuille_and_nothing_leaks():
    # wall 0.12 D (the page ring's) at D/8: under one cell thick, fluid on both sides, the outer
    # region closed by a plate: k within 1 % of the bore's closed form, the bore's nodal
    # velocities the parabola (the corrected linear rule is exact for it)
    from validation.flow_re import tube
    r = tube(8)
    assert r["converged"] and r["wall_cells"] < 1.0 and r["thin_links"] > 0
    assert abs(r["err"]) < 0.01, r
    assert r["bore_l2"] < 1e-8
    assert abs(r["balance"] - 1.0) < 1e-6


@pytest.fixture(scope="module")
def grown(tmp_path_factory):
    """A small grown sphere bed written by ``peclet pack --protocol grow``."""
    from peclet.cli import main
    out = tmp_path_factory.mktemp("grown") / "g"
    assert main(["pack", "--protocol", "grow", "--element", "sphere", "--count", "24",
                 "--mu", "0", "--seed", "2", "--out", str(out), "--quiet"]) == 0
    return str(out / "grown.npz")


def test_a_grown_pack_loads_as_a_periodic_cell(grown):
    from peclet.flow import PeriodicCell, load_flow_pack
    from peclet.flow.domain import pack_domain
    pk, cell, source = load_flow_pack(grown)
    assert isinstance(cell, PeriodicCell) and "grown" in source
    with np.load(grown) as z:
        L = float(z["box"][0]) / float(z["d"])
        assert pk.n == len(z["positions"])
    assert cell.Ly == pytest.approx(L) and np.allclose(pk.box, [L, L])
    assert 0.5 < pk.bounding_radius < 0.53
    grid, phi, info = pack_domain(pk, 6, container=cell)
    assert grid.periodic == (True, True, True) and info["container"] == "periodic"
    # periodic in y too: a sphere crossing y = 0 is solid again just below y = L
    low = pk.positions[pk.positions[:, 1] < 0.4]
    assert len(low) > 0
    below = low - [0.0, 0.45, 0.0]
    assert np.all(below[:, 1] < 0.0) and np.all(phi(below) < 0.0)
    assert np.all(phi(below + [0.0, L, 0.0]) < 0.0)
    with pytest.raises(PecletArgumentError, match="window"):
        pack_domain(pk, 6, window=(0.0, 1.0), container=cell)


def test_peclet_flow_runs_a_grown_pack_and_states_its_domain(grown, tmp_path):
    out = tmp_path / "f"
    p = subprocess.run([sys.executable, "-m", "peclet.cli", "flow", grown, "--resolution", "5",
                        "--axis", "x", "--out", str(out), "--quiet", "--tol", "1e-5"],
                       capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert p.returncode == 0, p.stderr
    assert "triply periodic cell" in p.stdout and "flow along x" in p.stdout
    r = json.loads((out / "results.json").read_text())["runs"][0]
    assert r["container"] == "periodic" and r["converged"]
    assert abs(r["solid_drag_balance"] - 1.0) < 1e-4
    assert r["dpdl_source"].startswith("body force (exact: the pack is triply periodic")
    # a random close packing of spheres: Carman-Kozeny's k to tens of percent even at D/5
    ck = cor.carman_kozeny(r["eps"], r["d_sauter"])
    assert 0.7 < r["k_D2"] / ck < 1.4, r["k_D2"] / ck
    p = subprocess.run([sys.executable, "-m", "peclet.cli", "flow", grown, "--window", "0,1",
                        "--out", str(tmp_path / "g")], capture_output=True, text=True, cwd=ROOT)
    assert p.returncode == 2 and "--window" in p.stderr


def test_the_curve_is_steady_at_low_re_and_stops_honestly_beyond_the_mach_bound(grown):
    from peclet.flow import pressure_drop_curve
    c = pressure_drop_curve(grown, [0.01, 1.0, 500.0], resolution=5, axis="x", tol=1e-6,
                            max_steps=20_000)
    p0, p1, p2 = c.points
    assert p0.status == p1.status == "steady", (p0.reason, p1.reason)
    assert p2.status == "mach" and "raise the resolution" in p2.reason and math.isnan(p2.dpdl)
    assert abs(p1.Re / p1.Re_target - 1.0) < 0.3 and p1.mach < c.mach_bound
    # creeping flow: f = D^2 / k; inertia raises f by Re 1 (a little)
    assert 1.0 <= p1.f / p0.f < 1.05
    assert c.fit is not None and c.fit["points"] == 2 and c.spheres
    # the references at the same Re: within tens of percent at D/5 (not converged in h)
    assert 0.7 < p0.dpdl / p0.ergun < 1.5 and 0.7 < p0.dpdl / p0.es < 1.5


def test_the_curve_command_writes_its_table_json_and_figure(grown, tmp_path):
    out = tmp_path / "c"
    p = subprocess.run([sys.executable, "-m", "peclet.cli", "flow", grown, "--reynolds",
                        "0.01,0.5", "--resolution", "5", "--axis", "z", "--out", str(out),
                        "--quiet"], capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert p.returncode == 0, p.stderr
    assert "Forchheimer fit" in p.stdout and "steady" in p.stdout
    c = json.loads((out / "curve.json").read_text())
    assert [q["status"] for q in c["points"]] == ["steady", "steady"]
    assert c["reynolds"].startswith("Re = rho U D / mu")
    assert (out / "curve.png").stat().st_size > 1000
    bad = subprocess.run([sys.executable, "-m", "peclet.cli", "flow", grown, "--reynolds",
                          "1:10", "--out", str(tmp_path / "d")], capture_output=True,
                         text=True, cwd=ROOT)
    assert bad.returncode == 2 and "--reynolds" in bad.stderr


def test_halfway_bounce_back_puts_every_wall_halfway_along_its_link():
    # scheme "bounce_back": the staircase reference (and the stability rung's control). In a
    # slit with walls q beyond the outer nodes it gives the exact parabola of walls at q = 1/2
    # (TRT, magic 3/16), whatever q is; the corrected linear rule gives the one at q
    from peclet.flow import Grid, build_geometry, solve
    from peclet.flow.wall_rule import fallback_counts
    n, g, nu = 6, 1e-6, 1.0 / 6.0

    def slit(q0):
        geo = build_geometry(Grid((0.0, 0.0, 0.0), 1.0, (2, n, 2), (True, False, True)),
                             lambda p: np.minimum(p[:, 1] + q0, (n - 1 + q0) - p[:, 1]))
        y = geo.ijk[:, 1]
        par = lambda q: g / (2 * nu) * (y + q) * (n - 1 + q - y)
        return geo, par
    geo, par = slit(0.2)
    bb = solve(geo, [g, 0, 0], nu=nu, tol=1e-12, scheme="bounce_back").u[:, 0]
    lin = solve(geo, [g, 0, 0], nu=nu, tol=1e-12).u[:, 0]
    assert np.abs(bb - par(0.5)).max() < 1e-9 * par(0.5).max()
    assert np.abs(bb - par(0.2)).max() > 0.1 * par(0.2).max()
    assert np.abs(lin - par(0.2)).max() < 1e-9 * par(0.2).max()
    assert fallback_counts(geo, "bounce_back")["bounce_back"] == len(geo.link_q)


def test_a_run_started_from_a_converged_field_needs_fewer_steps():
    from peclet.flow import Grid, build_geometry, solve
    L, a = 10, 3.6

    def phi(p):
        d = p - 4.5
        d -= L * np.round(d / L)
        return np.sqrt((d * d).sum(1)) - a
    geo = build_geometry(Grid((0.0, 0.0, 0.0), 1.0, (L, L, L), (True, True, True)), phi)
    r1 = solve(geo, [1e-6, 0, 0], tol=1e-8)
    r2 = solve(geo, [1e-6, 0, 0], tol=1e-8, init=(r1.rho, r1.u))
    assert r1.converged and r2.converged and r2.steps < r1.steps
    assert r2.U[0] == pytest.approx(r1.U[0], rel=1e-6)
    with pytest.raises(PecletArgumentError, match="init"):
        solve(geo, [1e-6, 0, 0], init=(r1.rho[:3], r1.u))


def test_the_grid_study_is_the_default_and_the_curve_runs_one_resolution():
    import argparse

    from peclet.cli import flow as cf
    from peclet.flow import curve
    ap = argparse.ArgumentParser()
    cf.add_parser(ap.add_subparsers())
    opts = lambda *a: cf._options(ap.parse_args(["flow", "p.npz", *a]))[0]
    assert opts() == list(cf.DEFAULT_STUDY) and len(cf.DEFAULT_STUDY) >= 2
    assert opts("--resolution", "D/12") == [12.0]
    assert opts("--reynolds", "0.1:1:2") == [8.0]
    with pytest.raises(PecletArgumentError, match="--resolutions"):
        opts("--reynolds", "0.1:1:2", "--resolutions", "8,12")
    # the command line's defaults are the library's
    assert cf.MACH == curve.MACH_DEFAULT and cf.NU_MIN == curve.NU_MIN_DEFAULT


@pytest.mark.xfail(strict=True, reason="not done: the TRT scheme is stable only to a cell "
                   "Reynolds number max|u| / nu of ~10-35 whatever the wall rule (halfway "
                   "bounce-back on every link, plain Bouzidi and the corrected rule all diverged "
                   "at Re 30 on the column:4 bed at D/8 and at Re 100 at D/12; the magic "
                   "product, a regularised symmetric part and a lower Mach number only delay "
                   "it: peclet.flow.curve). With max|u| / U ~ 11-14 in beds, Re 100 needs about "
                   "D/40 or another collision operator; the curve reports 'diverged' and stops")
def test_the_curve_reaches_re_100(grown):
    from peclet.flow import pressure_drop_curve
    c = pressure_drop_curve(grown, [0.01, 3.0, 10.0, 30.0, 100.0], resolution=5, axis="x",
                            tol=1e-6, max_steps=20_000)
    assert [p.status for p in c.points] == ["steady"] * 5, [p.reason for p in c.points]
