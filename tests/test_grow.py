"""Growth to jamming (issue 23, item 4): ``peclet pack --protocol grow`` and
``peclet.packing.experiments.grow``, at a reduced size (validation/grow.py runs 100 to 1000 spheres)."""
import json
import math

import numba
import numpy as np
import pytest

from peclet.cli import main
from peclet.packing.experiments.grow import FINAL_OVERLAP, GrowSpec, grow, pair_correlation

CAP = int(numba.config.NUMBA_NUM_THREADS)


def test_frictionless_spheres_jam_near_random_close_packing(tmp_path, capsys):
    out = tmp_path / "grown"
    rc = main(["pack", "--protocol", "grow", "--element", "sphere", "--count", "120",
               "--mu", "0", "--seed", "3", "--out", str(out), "--quiet"])
    assert rc == 0
    assert "packing fraction phi" in capsys.readouterr().out
    res = json.loads((out / "results.json").read_text())
    assert res["jammed"]
    # 120 spheres: the band of random close packing, a little wider for the small cube
    assert 0.62 <= res["phi"] <= 0.65, res["phi"]
    assert res["z_mean_no_rattlers"] >= 5.6, res["z_mean_no_rattlers"]
    assert res["max_overlap"] <= FINAL_OVERLAP
    assert 0.98 <= res["g_peak_r"] <= 1.02 and res["g_peak"] > 10.0
    with np.load(out / "grown.npz") as z:
        P, L = z["positions"], float(z["box"][0])
        assert len(P) == 120 and np.all((P >= 0.0) & (P < L))
        # no two centres closer than a diameter less the overlap tolerance (minimum images)
        d = P[:, None, :] - P[None, :, :]
        d -= L * np.round(d / L)
        r = np.sqrt((d * d).sum(-1)) + np.eye(120) * 10.0
        assert r.min() >= 1.0 - 2.0 * FINAL_OVERLAP
        assert 120 * math.pi / 6.0 / L ** 3 == pytest.approx(res["phi"], rel=1e-12)
    assert (out / "grow.png").stat().st_size > 0


def test_pair_correlation_of_a_lattice_and_of_random_points():
    g0 = np.arange(6) * 1.0
    X, Y, Z = np.meshgrid(g0, g0, g0, indexing="ij")
    P = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()]) + 0.25
    r, g = pair_correlation(P, 6.0, 2.5, 0.05)
    rho, dr = 216 / 6.0 ** 3, 0.05
    shells = 4.0 * np.pi * r ** 2 * dr * rho                     # ideal-gas pairs per shell
    neighbours = np.cumsum(g * shells)
    assert np.all(g[r < 0.95] == 0.0)
    # the 6 nearest at 1, then the 12 at sqrt 2 (to the bins' shell-volume rounding)
    assert neighbours[r < 1.1][-1] == pytest.approx(6.0, rel=0.02)
    assert neighbours[r < 1.45][-1] == pytest.approx(18.0, rel=0.02)
    rng = np.random.default_rng(0)
    r, g = pair_correlation(rng.uniform(0, 10, (3000, 3)), 10.0, 4.0, 0.2)
    assert np.mean(g[r > 1.0]) == pytest.approx(1.0, abs=0.03)    # an ideal gas


@pytest.mark.skipif(CAP < 2, reason="needs 2 numba threads")
def test_a_growth_run_is_the_same_at_one_and_two_threads():
    spec = GrowSpec(count=80, max_steps=300, seed=4)
    try:
        a = grow(spec, progress=False, threads=1)
        b = grow(spec, progress=False, threads=2)
    finally:
        numba.set_num_threads(CAP)
    assert a["steps"] == 300 and not a["jammed"]
    assert a["state_hash"] == b["state_hash"]
    assert a["phi"] == b["phi"]


CASES = [
    (["--wall-mu", "0.3"], "--wall-mu", "a periodic cube has no walls"),
    (["--rate", "0"], "--rate", "(0, 10]"),
    (["--rate", "x"], "--rate", "a number"),
    (["--count", "1"], "--count", "[2, 100000]"),
    (["--element", "no_such"], "--element", ""),
    # closed containers (issue 41, item 5; their runs: tests/test_grow_walled.py)
    (["--container", "box:4"], "--container", "box:L is the periodic box"),
    (["--container", "walled:3,3"], "--container", "'column:N'"),
    (["--container", "box:2x2x2", "--count", "30"], "--container",
     "start fraction N V_env / V <= 0.4"),
    (["--container", "box:4x4x4", "--count", "30", "--target-phi", "0.2"], "--target-phi",
     "above the start fraction 0.2454"),
    (["--target-phi", "1.5"], "--target-phi", "in (0, 1)"),
    (["--container", "column:1"], "--container", "[1.5, 10000]"),
    (["--wall-restitution", "0.3"], "--wall-restitution", "a periodic cube has no walls"),
]


@pytest.mark.parametrize("argv,flag,phrase", CASES, ids=[" ".join(c[0]) for c in CASES])
def test_bad_grow_input_is_one_line_naming_the_flag(tmp_path, capsys, argv, flag, phrase):
    out = tmp_path / "run"
    rc = main(["pack", "--protocol", "grow", "--element", "sphere", "--out", str(out),
               "--quiet"] + argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1, err
    assert err[0].startswith(f"peclet pack: error: {flag} must"), err
    assert phrase in err[0], err
    assert not out.exists()


def test_rate_is_refused_with_the_page_protocol(tmp_path, capsys):
    rc = main(["pack", "--protocol", "page", "--rate", "0.5", "--out", str(tmp_path / "r"),
               "--quiet"])
    assert rc == 2
    assert "--rate must be given only with --protocol grow" in capsys.readouterr().err
