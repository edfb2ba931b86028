"""The whole page at reduced size (few rings, few steps), through the command line."""
import json
import os

import matplotlib.image as mpimg
import numpy as np
import pytest

from peclet.packing.freeze import load_pack

FIGS = ("ring", "kinetic_energy", "pack", "orientation", "voidage_sweep")


@pytest.fixture(scope="module")
def reduced_run(tmp_path_factory):
    from peclet.packing import pipeline

    out = tmp_path_factory.mktemp("pall")
    lines = []
    res = pipeline.run(out=str(out), rings=8, seed=3, threads=None, steps_scale=0.08,
                       box=3.0, mc_samples=20_000, shell_points=500, sweep=(0.04, 0.12),
                       mesh_n=60, quad_n=8, shell_resolution=64, sweep_n=8, progress=False,
                       log=lines.append)
    return out, res, "\n".join(lines)


@pytest.mark.slow
def test_every_output_exists_and_is_sane(reduced_run):
    out, res, table = reduced_run
    names = set(os.listdir(out))
    assert {"pall_ring_pack.npz", "results.json"} | {f + ".png" for f in FIGS} <= names
    assert not [n for n in names if n.startswith(".tmp")]
    for f in FIGS:
        img = mpimg.imread(out / (f + ".png"))
        assert img.shape[0] > 100 and img[..., :3].std() > 0.02, f

    with open(out / "results.json") as fh:
        js = json.load(fh)
    assert set(js) >= {"config", "certificate", "particle", "pour", "pack", "sweep", "timing",
                       "figures", "pack_file"}
    c, p, k, s = js["certificate"], js["particle"], js["pack"], js["pour"]
    assert c["certified"]["violating"] == 0.0 and c["sign_exact"]["violating"] > 0.1
    assert c["same_sign"] == 1.0
    assert 0.30 < p["volume_fraction"] < 0.37 and p["volume_error"] < 1e-6
    assert 6.0 < p["surface_area"] < 7.0
    assert 0.0 < k["eps"] < 1.0 and 0.0 < k["f_env"] < 1.0
    assert k["f_env"] > 1 - k["eps"]                      # the envelope holds the solid
    assert len(k["windows"]) == 3 and all(w["n_samples"] == 20_000 for w in k["windows"])
    assert 0.0 <= k["double"] < 0.05 and k["z_mean"] >= 0 and len(k["cos"]) == 8
    assert all(0.0 <= v <= 1.0 for v in k["cos"])
    assert s["steps"] == js["config"]["protocol"]["pour_steps"] + 2 * \
        js["config"]["protocol"]["tap_steps"] + js["config"]["protocol"]["relax_steps"] + \
        js["config"]["protocol"]["quench_steps"]
    assert k["all_in_box"] and k["lowest_probe"] > -0.12   # nothing through the floor
    rows = js["sweep"]
    assert [r["t"] for r in rows] == [0.04, 0.12]
    assert rows[0]["s"] < rows[1]["s"] and rows[0]["eps"] > rows[1]["eps"]
    assert all(r["s_err"] < 1e-6 for r in rows)
    for needle in ("bed voidage eps", "envelope packing fraction", "mean coordination",
                   "the page"):
        assert needle in table


@pytest.mark.slow
def test_frozen_pack_rebuilds_the_simulation(reduced_run):
    from peclet.packing.freeze import pack_to_simulation

    out, res, _ = reduced_run
    pk = load_pack(out / "pall_ring_pack.npz")
    assert pk.n == 8 and pk.shell.shape[1] == 3 and np.isfinite(pk.mass)
    sim, sid = pack_to_simulation(pk)
    assert sim.num_particles() == 8
    assert np.array_equal(np.asarray(sim.get_positions(), float), pk.positions)
    sim.step()                                           # a consumer can carry on from it
    assert np.all(np.isfinite(np.asarray(sim.get_positions())))
