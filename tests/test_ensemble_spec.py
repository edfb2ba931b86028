"""peclet.ensemble without a cluster: specs and their ids, --seeds/--sweep parsing, the ledger
(atomic result directories, manifests), the summary statistics and the CLI's bad input."""
import json
import math
import os

import numpy as np
import pytest

from peclet.cli import main
from peclet.core.validation import PecletArgumentError
from peclet.ensemble import (Ledger, PackSpec, ensemble_manifest, make_specs, parse_seeds,
                             parse_sweep, summarize, write_csv, write_figure, write_json)
from peclet.ensemble.runner import _row, run
from peclet.packing.bed import elements as E
from peclet.packing.bed.freeze import Pack, load_pack


def tiny_pack(n=3, seed=0):
    """A (physically meaningless) pack of n page rings: only its bytes matter here."""
    el = E.pall_ring()
    ni, nr, _, _ = el.builder.encode()
    g = np.random.default_rng(seed)
    return Pack(g.uniform(0, 3, (n, 3)), g.normal(size=(n, 4)), [3.0, 3.0], 0.268, ni, nr,
                el.root, 0.72, g.uniform(-0.5, 0.5, (20, 3)), 0.268, [20.0, 20.0, 20.0],
                el.envelope_root, el.envelope_volume, [0.0, 1.0, 0.0])


def fake_result(spec, eps=0.8, f_env=0.55, z=4.0):
    return dict(spec=spec.as_dict(), id=spec.id, state_hash="0" * 64, eps=eps, eps_se=1e-3,
                f_env=f_env, f_env_se=1e-3, z_mean=z, rattlers=0)


# ---------------------------------------------------------------- specs and parsing
def test_seed_and_sweep_parsing():
    assert parse_seeds("1-4,10, 20-22") == [1, 2, 3, 4, 10, 20, 21, 22]
    assert parse_seeds("7") == [7]
    assert parse_sweep(["mu=0.3,0.5,0.8", "count=24,48"]) == {"mu": [0.3, 0.5, 0.8],
                                                             "count": [24, 48]}
    assert isinstance(parse_sweep("count=24")["count"][0], int)


def test_spec_ids_are_content_addressed():
    a, b = PackSpec(seed=3, mu=0.5), PackSpec(seed=3, mu=0.5)
    assert a.id == b.id and a.id.startswith("s3-")
    assert PackSpec(seed=3, mu=0.5000001).id != a.id
    assert PackSpec(seed=4, mu=0.5).id != a.id
    assert PackSpec.from_dict(json.loads(json.dumps(a.as_dict()))).id == a.id
    specs = make_specs([1, 2], {"mu": [0.3, 0.8], "count": [4, 8]}, container="box:3")
    assert len(specs) == 8 and len({s.id for s in specs}) == 8
    assert [(s.mu, s.count, s.seed) for s in specs[:3]] == [(0.3, 4, 1), (0.3, 4, 2),
                                                            (0.3, 8, 1)]


def test_manifest_is_kept_when_seeds_or_values_are_added():
    m1 = ensemble_manifest(make_specs([1, 2], {"mu": [0.3, 0.5]}, count=4))
    m2 = ensemble_manifest(make_specs([1, 2, 3], {"mu": [0.3, 0.5, 0.8]}, count=4))
    m3 = ensemble_manifest(make_specs([1, 2], {"mu": [0.3, 0.5]}, count=5))
    m4 = ensemble_manifest(make_specs([1, 2], {"e_n": [0.1, 0.5]}, count=4))
    assert m1 == m2 and m1 != m3 and m1 != m4 and m1["swept"] == ["mu"]


# ---------------------------------------------------------------- the ledger
def test_ledger_writes_complete_directories_and_skips_them(tmp_path):
    specs = make_specs([1, 2], count=4)
    led = Ledger(tmp_path / "out", ensemble_manifest(specs))
    pk = tiny_pack()
    d = led.write(specs[0], fake_result(specs[0]), pk)
    assert sorted(os.listdir(d)) == ["pack.npz", "results.json"]
    assert sorted(os.listdir(tmp_path / "out")) == ["ensemble.json", specs[0].id]
    back = load_pack(os.path.join(d, "pack.npz"))
    assert np.array_equal(back.positions, pk.positions)
    assert np.array_equal(back.quaternions, pk.quaternions)
    assert led.load(specs[0])["id"] == specs[0].id and led.load(specs[1]) is None
    # a second writer of the same spec keeps the first directory (results are equal)
    led.write(specs[0], fake_result(specs[0], eps=0.1), tiny_pack(seed=1))
    assert led.load(specs[0])["eps"] == 0.8
    assert sorted(os.listdir(tmp_path / "out")) == ["ensemble.json", specs[0].id]
    # every spec done: run() returns them without starting (or reaching) any cluster
    led.write(specs[1], fake_result(specs[1], eps=0.7), pk)
    rows = run(specs, tmp_path / "out", scheduler="tcp://127.0.0.1:9", progress=False)
    assert [r["reused"] for r in rows] == [True, True]
    assert [r["eps"] for r in rows] == [0.8, 0.7]


def test_interrupted_write_leaves_nothing_and_leftovers_are_cleared(tmp_path):
    specs = make_specs([1], count=4)
    led = Ledger(tmp_path, ensemble_manifest(specs))

    bad = fake_result(specs[0])
    bad["eps"] = object()          # not JSON-serialisable: results.json's write raises
    with pytest.raises(TypeError):
        led.write(specs[0], bad, tiny_pack())
    assert sorted(os.listdir(tmp_path)) == ["ensemble.json"]
    os.mkdir(tmp_path / ".peclet-part-s1-xyz")            # as a killed run would leave it
    Ledger(tmp_path, ensemble_manifest(specs)).prepare()
    assert sorted(os.listdir(tmp_path)) == ["ensemble.json"]


# ---------------------------------------------------------------- summary statistics
def test_summary_statistics_match_closed_forms():
    specs = make_specs([1, 2, 3, 4], {"mu": [0.3, 0.8]}, count=4)
    vals = {0.3: [0.80, 0.82, 0.81, 0.85], 0.8: [0.70, 0.74, 0.72, 0.78]}
    rows = []
    for s in specs:
        v = vals[s.mu][s.seed - 1]
        rows.append(_row(fake_result(s, eps=v, f_env=1 - v, z=10 * v), False))
    pts = summarize(rows, ["mu"])
    assert [p["mu"] for p in pts] == [0.3, 0.8] and all(p["n"] == 4 for p in pts)
    for p in pts:
        v = np.array(vals[p["mu"]])
        sd = math.sqrt(((v - v.mean()) ** 2).sum() / 3)
        assert p["eps_mean"] == pytest.approx(v.mean(), rel=1e-14)
        assert p["eps_se"] == pytest.approx(sd / 2, rel=1e-12)
        # t_{0.975, 3} = 3.182 (printed Student-t tables)
        assert p["eps_ci_hi"] - p["eps_mean"] == pytest.approx(3.182 * sd / 2, rel=2e-4)
        assert p["Z_mean"] == pytest.approx(10 * v.mean(), rel=1e-14)
        assert p["f_env_se"] == pytest.approx(p["eps_se"], rel=1e-9)
    one = summarize(rows[:1], ["mu"])[0]
    assert one["n"] == 1 and math.isnan(one["eps_se"]) and math.isnan(one["eps_ci_lo"])


def test_summary_files(tmp_path):
    import matplotlib
    import matplotlib.image as mpimg

    backend = matplotlib.get_backend()
    specs = make_specs([1, 2, 3], {"mu": [0.3, 0.8], "count": [4, 8]})
    rows = [_row(fake_result(s, eps=0.8 + 0.01 * s.seed + 0.1 * s.mu), False) for s in specs]
    pts = summarize(rows, ["mu", "count"])
    write_csv(tmp_path / "s.csv", pts)
    write_json(tmp_path / "s.json", pts, ["mu", "count"])
    write_figure(tmp_path / "s.png", pts, rows, ["mu", "count"])
    lines = (tmp_path / "s.csv").read_text().splitlines()
    assert len(lines) == 5 and lines[0].startswith("mu,count,n,")
    assert float(lines[1].split(",")[lines[0].split(",").index("eps_mean")]) \
        == pytest.approx(pts[0]["eps_mean"], rel=1e-15)
    doc = json.loads((tmp_path / "s.json").read_text())
    assert doc["confidence"] == 0.95 and len(doc["points"]) == 4
    img = mpimg.imread(tmp_path / "s.png")
    assert img.shape[0] > 200 and img.std() > 0.01
    assert matplotlib.get_backend() == backend          # no matplotlib.use()
    # no sweep: one point
    pts1 = summarize(rows[:3], [])
    assert len(pts1) == 1 and pts1[0]["n"] == 3
    write_figure(tmp_path / "s1.png", pts1, rows[:3], [])


# ---------------------------------------------------------------- bad input
BAD_API = [
    (lambda: parse_seeds(""), "seeds"),
    (lambda: parse_seeds("5-1"), "seeds"),
    (lambda: parse_seeds("1,,2"), "seeds"),
    (lambda: parse_seeds("-3"), "seeds"),
    (lambda: parse_seeds("1.5"), "seeds"),
    (lambda: parse_seeds("1-3,2"), "seeds"),
    (lambda: parse_seeds("0-99999999"), "seeds"),
    (lambda: parse_sweep("mu"), "sweep"),
    (lambda: parse_sweep("friction=0.3"), "sweep"),
    (lambda: parse_sweep("mu=0.3,abc"), "sweep"),
    (lambda: parse_sweep("mu=-0.1"), "sweep"),
    (lambda: parse_sweep("mu=0.3,0.3"), "sweep"),
    (lambda: parse_sweep(["mu=0.3", "mu=0.5"]), "sweep"),
    (lambda: parse_sweep("count=2.5"), "sweep"),
    (lambda: parse_sweep("e_n=1.5"), "sweep"),
    (lambda: parse_sweep("mu="), "sweep"),
    (lambda: make_specs([1], {"mu": [0.3]}, mu=0.5), "sweep"),
    (lambda: PackSpec(element="pall"), "element"),
    (lambda: PackSpec(container="sphere:3"), "container"),
    (lambda: PackSpec(count=0), "count"),
    (lambda: PackSpec(seed=-1), "seed"),
    (lambda: PackSpec(mu=float("nan")), "mu"),
    (lambda: PackSpec(count=True), "count"),
    (lambda: PackSpec(protocol="rain", steps_scale=0.5), "steps_scale"),
    (lambda: run([], "/tmp/never-written"), "specs"),
    (lambda: run([PackSpec(), PackSpec()], "/tmp/never-written"), "specs"),
    (lambda: run([PackSpec()], "/tmp/never-written", progress="False"), "progress"),
]


@pytest.mark.parametrize("call,name", BAD_API, ids=[str(i) for i in range(len(BAD_API))])
def test_bad_api_input_names_the_argument(call, name):
    with pytest.raises(PecletArgumentError) as e:
        call()
    assert str(e.value).startswith(name) and "\n" not in str(e.value)
    assert not os.path.exists("/tmp/never-written")


def _cli(tmp_path, capsys, *argv):
    rc = main(["ensemble", *argv])
    err = capsys.readouterr().err.strip()
    return rc, err


def _other_ensemble(tmp_path):
    out = tmp_path / "other"
    Ledger(out, ensemble_manifest(make_specs([1], count=4, mu=0.9))).prepare()
    return str(out)


def _foreign(tmp_path):
    out = tmp_path / "foreign"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    return str(out)


def _afile(tmp_path):
    (tmp_path / "afile").write_text("x")
    return str(tmp_path / "afile")


BAD_CLI = [
    (["--seeds", "3-1"], "--seeds"),
    (["--seeds", "a"], "--seeds"),
    (["--seeds", "1,1"], "--seeds"),
    (["--seeds", "1-2", "--sweep", "mu:0.3"], "--sweep"),
    (["--seeds", "1-2", "--sweep", "tau=0.3"], "--sweep"),
    (["--seeds", "1-2", "--sweep", "mu=0.3,x"], "--sweep"),
    (["--seeds", "1-2", "--sweep", "mu=0.3", "--mu", "0.4"], "--sweep"),
    (["--seeds", "1-2", "--count", "0"], "--count"),
    (["--seeds", "1-2", "--count", "4.5"], "--count"),
    (["--seeds", "1-2", "--steps-scale", "-1"], "--steps-scale"),
    (["--seeds", "1-2", "--mu", "x"], "--mu"),
    (["--seeds", "1-2", "--element", "nope"], "--element"),
    (["--seeds", "1-2", "--threads", "0"], "--threads"),
    (["--seeds", "1-2", "--scheduler", "tcp://127.0.0.1:9"], "--scheduler"),
    (["--seeds", "1-2", "--scheduler", "not-an-address"], "--scheduler"),
]


@pytest.mark.parametrize("argv,flag", BAD_CLI, ids=[str(i) for i in range(len(BAD_CLI))])
def test_bad_cli_input_is_one_line_exit_2(tmp_path, capsys, argv, flag):
    out = tmp_path / "out"
    rc, err = _cli(tmp_path, capsys, *argv, "--out", str(out), "--quiet")
    assert rc == 2, err
    assert err.startswith(f"peclet ensemble: error: {flag}") and "\n" not in err, err
    assert not out.exists()                       # nothing written


@pytest.mark.parametrize("make", [_other_ensemble, _foreign, _afile])
def test_cli_refuses_an_out_it_does_not_own(tmp_path, capsys, make):
    out = make(tmp_path)
    before = {n: os.path.getmtime(os.path.join(out, n)) for n in os.listdir(out)} \
        if os.path.isdir(out) else None
    rc, err = _cli(tmp_path, capsys, "--seeds", "1-2", "--count", "4", "--out", out, "--quiet")
    assert rc == 2 and err.startswith("peclet ensemble: error: --out") and "\n" not in err, err
    if before is not None:
        assert {n: os.path.getmtime(os.path.join(out, n)) for n in os.listdir(out)} == before


# ---------------------------------------------------------------- elements from files
def _mesh(path, radius=12.5):
    import trimesh

    trimesh.creation.icosphere(subdivisions=2, radius=radius).export(path)
    return path


def test_a_mesh_element_is_carried_by_its_absolute_path_and_contents(tmp_path, monkeypatch):
    _mesh(tmp_path / "pellet.stl")
    monkeypatch.chdir(tmp_path)
    spec = PackSpec(element="pellet.stl:scale=0.04", container="column:4", count=4,
                    protocol="rain")
    assert spec.element == f"{tmp_path / 'pellet.stl'}:scale=0.04"
    assert spec.element_params == {}
    first = spec.id
    assert PackSpec.from_dict(spec.as_dict()).id == first
    _mesh(tmp_path / "pellet.stl", radius=12.0)          # the user edits the file
    assert PackSpec.from_dict(spec.as_dict()).id != first
    with pytest.raises(PecletArgumentError, match="scale=0.04,2|KEY in"):
        PackSpec(element="pellet.stl:scale=0.04,2")
    with pytest.raises(PecletArgumentError, match="^element must be a path"):
        PackSpec(element="missing.stl")
    with pytest.raises(PecletArgumentError, match="sweep must be KEY"):
        parse_sweep(["thickness=0.03,0.06"], "sweep", element=spec.element)


def test_cli_names_element_for_a_missing_mesh(tmp_path, capsys):
    rc = main(["ensemble", "--element", str(tmp_path / "nope.stl"), "--seeds", "1-2",
               "--out", str(tmp_path / "o"), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and "--element must be a path to an existing mesh" in err, err
    assert not (tmp_path / "o").exists()
