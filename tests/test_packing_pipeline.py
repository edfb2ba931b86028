"""The whole page at reduced size (few rings, few steps) with the real DEM.

Step 3 uses a stand-in particle (``standin_particle`` below: Monte Carlo mass properties and a
thinned marching-cubes shell) because ``scene_particle.build`` on the Pall ring does not yet
finish in test time (measured: > 10 min at n=32 on 2 loaded cores while its quadrature is being
written). Everything downstream — pour, freeze, analysis, figures, results.json — is the real
pipeline. Switch ``particle=`` to None once the build takes seconds.
"""
import dataclasses
import json
import math
import os
from types import SimpleNamespace

import matplotlib.image as mpimg
import numpy as np
import pytest

from peclet.core.outputs import MANIFEST
from peclet.packing.bed.freeze import load_pack

FIGS = ("ring", "kinetic_energy", "pack", "orientation", "voidage_sweep")


def standin_particle(n_probes=500, seed=0):
    """A particle of the page's ring with scene_particle.build's attributes (see the module
    docstring): principal frame from a Monte Carlo inertia, probes Newton-projected onto the
    exact surface."""
    from peclet.core.geom import matrix_to_quat
    from peclet.core.geom.mesh import surface_mesh
    from peclet.packing.bed import elements as E

    el = E.pall_ring()
    b, r = el
    lo, hi = el.bounds
    g = np.random.default_rng(seed)
    k = 400_000
    p = g.uniform(lo, hi, (k, 3))
    q = p[b.eval_root(r, p) < 0]
    vol = np.prod(hi - lo) * len(q) / k
    com = q.mean(axis=0)
    d = q - com
    S = np.prod(hi - lo) / k * d.T @ d
    w, ax = np.linalg.eigh(np.trace(S) * np.eye(3) - S)
    if np.linalg.det(ax) < 0:
        ax[:, 2] *= -1
    home = b.add_reframed(r, translation=-(ax.T @ com),
                          rotation=matrix_to_quat(np.ascontiguousarray(ax.T)))
    v, _, _ = surface_mesh(b, home, [-0.66] * 3, [0.66] * 3, 80)
    shell = v[g.choice(len(v), n_probes, replace=False)]
    for _ in range(4):
        phi, grad = b.eval_root_grad(home, shell)
        shell = shell - phi[:, None] * grad
    c, rad, _ = b.node_bound(home)
    ni, nr, _, _ = b.encode()
    br = float(np.linalg.norm(c) + rad)
    return SimpleNamespace(
        volume=vol, volume_error=math.nan, mass=vol, com=com, principal=w,
        quat=matrix_to_quat(ax), home_root=home, shell=shell, bounding_radius=br,
        inv_inertia_unit=1.0 / w, node_ints=ni, node_reals=nr, moment_error=math.nan,
        register=lambda sim: sim.add_scene_shape(ni, nr, home, shell, br))


@pytest.fixture(scope="module")
def reduced_run(tmp_path_factory):
    from peclet.packing.page import pipeline

    out = tmp_path_factory.mktemp("pall")
    # an earlier run's figure that this run does not write (recorded in the manifest as an
    # earlier run records it), and a file that is not ours
    from peclet.core.outputs import recording
    with recording(out, ["pour.gif"]):
        (out / "pour.gif").write_bytes(b"GIF89a stale")
    (out / "notes.txt").write_text("mine")
    lines = []
    # 6 rings from y <= 2.85 land in 0.14 of the page's steps (check_run's landing rule)
    res = pipeline.run(out=str(out), rings=6, seed=2, threads=None, steps_scale=0.14,
                       box=3.5, mc_samples=20_000, sweep=(), mesh_n=60, progress=False,
                       particle=standin_particle(), log=lines.append, overwrite=True)
    return out, res, "\n".join(lines)


@pytest.mark.slow
def test_every_output_exists_and_is_sane(reduced_run):
    out, res, table = reduced_run
    names = set(os.listdir(out))
    assert {"pall_ring_pack.npz", "results.json"} | {f + ".png" for f in FIGS} <= names
    assert not [n for n in names if n.startswith(".") and n != MANIFEST]   # no temp file left
    # --overwrite cleared the earlier run's files (no stale pour.gif beside the new results)
    # and left the user's own file alone
    assert "pour.gif" not in names and (out / "notes.txt").read_text() == "mine"
    umask = os.umask(0)
    os.umask(umask)
    for n in names - {"notes.txt"}:                 # written files respect the umask
        assert os.stat(out / n).st_mode & 0o777 == 0o666 & ~umask, n
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
    assert 0.30 < p["volume_fraction"] < 0.37
    assert 6.0 < p["surface_area"] < 7.0
    assert 0.0 < k["eps"] < 1.0 and 0.0 < k["f_env"] < 1.0
    assert k["f_env"] > 1 - k["eps"]                      # the envelope holds the solid
    assert len(k["windows"]) == 3 and all(w["n_samples"] == 20_000 for w in k["windows"])
    assert 0.0 <= k["double"] < 0.05 and k["z_mean"] >= 0 and len(k["cos"]) == 6
    assert all(0.0 <= v <= 1.0 for v in k["cos"])
    assert s["steps"] == js["config"]["protocol"]["pour_steps"] + 2 * \
        js["config"]["protocol"]["tap_steps"] + js["config"]["protocol"]["relax_steps"] + \
        js["config"]["protocol"]["quench_steps"]
    assert k["all_in_box"] and k["lowest_probe"] > -0.12   # nothing through the floor
    assert js["sweep"] == []                 # the sweep's quadrature: test_wall_sweep below
    assert js["sweep_source"] == "computed"  # (nothing kept for an empty sweep)
    for needle in ("bed voidage eps", "envelope packing fraction", "mean coordination",
                   "the page"):
        assert needle in table


@pytest.mark.slow
def test_frozen_pack_rebuilds_the_simulation(reduced_run):
    from peclet.packing.bed.freeze import pack_to_simulation

    out, res, _ = reduced_run
    pk = load_pack(out / "pall_ring_pack.npz")
    assert pk.n == 6 and pk.shell.shape[1] == 3 and np.isfinite(pk.mass)
    sim, sid = pack_to_simulation(pk)
    assert sim.num_particles() == 6
    assert np.array_equal(np.asarray(sim.get_positions(), float), pk.positions)
    sim.step()                                           # a consumer can carry on from it
    assert np.all(np.isfinite(np.asarray(sim.get_positions())))


def test_analysis_kernels_compiled_on_one_ring_serve_the_whole_pack(reduced_run):
    # what a cold first run compiles beside the DEM children (analysis.compile_kernels, on a
    # one-ring pack) must be what the analysis of the poured pack calls: no new signature
    from peclet.packing.analysis import geometry as analysis

    out, _, _ = reduced_run
    pk = load_pack(out / "pall_ring_pack.npz")
    one = dataclasses.replace(pk, positions=pk.positions[:1], quaternions=pk.quaternions[:1])
    analysis.compile_kernels(one)
    kernels = (analysis._cover_kernel, analysis._probe_min_kernel)
    before = [list(k.signatures) for k in kernels]
    assert all(len(s) >= 1 for s in before)
    geo = analysis.PackGeometry(pk)
    analysis.cover_fractions(geo, analysis.bulk_windows(pk)[0][0], 2000, seed=0)
    analysis.probe_overlap(geo)
    assert [list(k.signatures) for k in kernels] == before


def test_wall_sweep_against_the_tube_closed_form():
    """eps = 1 - f_env s(t) with s(t) by quadrature, on Raschig rings where
    s = 1 - (1 - t/r_o)^2 exactly."""
    from peclet.packing.analysis import geometry as A
    from peclet.packing.bed import elements as E

    rows = A.wall_sweep([0.12], 0.58, 0.002, make=lambda t: E.raschig_ring(thickness=t), n=8)
    (r,) = rows
    exact = 1 - (1 - 0.12 / 0.5) ** 2
    assert r["t_over_d"] == pytest.approx(0.12)
    # measured: |s - exact| = 7.5e-12 against s_err = 3.2e-9
    assert r["s"] == pytest.approx(exact, rel=1e-8)
    assert abs(r["s"] - exact) <= r["s_err"]
    assert r["eps"] == pytest.approx(1 - 0.58 * r["s"], abs=1e-15)
    assert r["eps_err"] == pytest.approx(math.hypot(r["s"] * 0.002, 0.58 * r["s_err"]))
