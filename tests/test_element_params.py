"""Element parameters (issue 26, item 3): ``--element pall_ring:thickness=0.024,n_windows=5`` on
the command line, in ``pack()``, in PackSpec (canonical form, ids), in results.json, in the
ensemble's ``--sweep`` (any numeric element parameter), and the thin-wall probe rule."""
import hashlib
import json

import numpy as np
import pytest

from peclet.cli import main
from peclet.core.validation import PecletArgumentError
from peclet.ensemble import (Ledger, PackSpec, ensemble_manifest, make_specs, parse_sweep,
                             realize, summarize)
from peclet.ensemble.runner import run
from peclet.packing import pack
from peclet.packing.bed import api
from peclet.packing.bed import elements as E
from peclet.cli.options import ELEMENT_HELP


# ---------------------------------------------------------------- parsing
@pytest.mark.parametrize("value,kind,params", [
    ("pall_ring", "pall_ring", {}),
    ("pall_ring:thickness=0.024,n_windows=5", "pall_ring", dict(thickness=0.024, n_windows=5)),
    (" pall_ring : thickness = 2.4e-2 , n_windows = 5.0 ", "pall_ring",
     dict(thickness=0.024, n_windows=5)),
    ("pall_ring:window_half=0.2/0.17/0.13,thickness=0.18", "pall_ring",
     dict(thickness=0.18, window_half=(0.2, 0.17, 0.13))),
    (("raschig_ring", {"thickness": 0.3}), "raschig_ring", dict(thickness=0.3)),
    ("berl_saddle:R=0.6,r=0.1", "berl_saddle", dict(R=0.6, r=0.1)),
    ("intalox_saddle:thickness=0.03", "intalox_saddle", dict(thickness=0.03)),
    ("sphere:radius=0.25", "sphere", dict(radius=0.25)),
    ("solid_cylinder:radius=0.5,height=0.5", "solid_cylinder", dict(radius=0.5, height=0.5)),
])
def test_parse_element_forms(value, kind, params):
    k, p = E.parse_element(value)
    assert (k, p) == (kind, params)
    assert isinstance(p.get("n_windows", 0), int)
    # the canonical text parses back to the same thing, and is stable
    text = E.element_text(k, p)
    assert E.parse_element(text) == (k, p) and E.element_text(*E.parse_element(text)) == text
    el = api.resolve_element(value)
    assert el.name == kind and all(el.params[n] == v for n, v in p.items())


def test_canonical_text():
    assert E.element_text(*E.parse_element("pall_ring:n_windows=5.0,thickness=2.4e-2")) == \
        "pall_ring:thickness=0.024,n_windows=5"
    assert E.element_text("pall_ring", {}) == "pall_ring"


BAD = [
    ("pall_ring:thickness=0.5", ["thickness", "(0, 0.16]", "< r_outer"]),
    ("pall_ring:thickness=0.6", ["thickness", "(0, 0.16]"]),
    ("pall_ring:thickness=0.2", ["thickness", "<= window_half radial = 0.16"]),
    ("pall_ring:thickness=0", ["thickness", "(0, 0.16]"]),
    ("pall_ring:thickness=-0.01", ["thickness"]),
    ("pall_ring:thickness=nan", ["thickness"]),
    ("pall_ring:thickness=abc", ["thickness", "not a number"]),
    ("pall_ring:n_windows=0", ["n_windows", "an integer in [1, 16]"]),
    ("pall_ring:n_windows=2.5", ["n_windows", "not an integer"]),
    ("pall_ring:n_windows=17", ["n_windows", "[1, 16]"]),
    ("pall_ring:window_y=0.5", ["window_y", "[0, 0.5)"]),
    ("pall_ring:foo=1", ["unknown parameter 'foo'", "thickness"]),
    ("pall_ring:radius=1", ["unknown parameter 'radius'"]),
    ("pall_ring:thickness", ["KEY=VALUE"]),
    ("pall_ring:", ["no parameters"]),
    ("pall_ring:thickness=0.1,thickness=0.2", ["given twice"]),
    ("pall_ring:window_half=1/2", ["window_half", "a/b/c"]),
    ("pall_ring:window_half=0.1/0.17/0.13", ["window_half[0]", "thickness"]),
    ("raschig_ring:thickness=0.5", ["thickness", "(0, 0.5)"]),
    ("berl_saddle:r=0.5", ["r ", "(0, 0.5)"]),
    ("intalox_saddle:thickness=0.3", ["thickness", "(0, 0.3)"]),
    ("sphere:radius=-1", ["radius", "(0, inf)"]),
    ("solid_cylinder:height=0", ["height"]),
    ("cube:radius=1", ["unknown element 'cube'"]),
    (("pall_ring", {"thickness": True}), ["thickness", "not a number"]),
    (("pall_ring", {"thickness": "x"}), ["thickness", "not a number"]),
]


@pytest.mark.parametrize("value,words", BAD, ids=[str(i) for i in range(len(BAD))])
def test_bad_parameters_name_the_parameter_and_range(value, words):
    with pytest.raises(PecletArgumentError) as ei:
        E.parse_element(value)
    msg = str(ei.value)
    assert ei.value.argument == "element" and msg.startswith("element must be")
    for w in words:
        assert w in msg, (w, msg)
    # the API refuses it the same way, before any work
    with pytest.raises(PecletArgumentError, match="^element must be"):
        pack(value, "box:3", count=9, progress=False)


def test_every_parameter_is_documented_in_help(capsys):
    for kind, ps in E.PARAMS.items():
        assert kind in ELEMENT_HELP
        defaults = E.element_defaults(kind)
        seg = ELEMENT_HELP[ELEMENT_HELP.index(kind + ":"):]
        for p in ps:
            assert p.name in seg, (kind, p.name)
            d = defaults[p.name]
            shown = "/".join(f"{x:g}" for x in d) if p.kind == "triple" else f"{d:g}"
            assert f"[{shown}]" in seg, (kind, p.name, shown)
    with pytest.raises(SystemExit):
        main(["pack", "-h"])
    out = capsys.readouterr().out
    assert "pall_ring:thickness=0.024,n_windows=5" in out and "n_windows" in out


@pytest.mark.parametrize("value,words", [
    ("pall_ring:thickness=0.6", ["thickness", "(0, 0.16]"]),
    ("pall_ring:n_windows=0", ["n_windows", "[1, 16]"]),
    ("pall_ring:bogus=3", ["unknown parameter 'bogus'"]),
    ("sphere:radius=x", ["radius", "not a number"]),
])
def test_cli_pack_refuses_bad_parameters_in_one_line(tmp_path, capsys, value, words):
    out = tmp_path / "o"
    code = main(["pack", "--element", value, "--out", str(out), "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err
    assert err.startswith("peclet pack: error: --element must be"), err
    for w in words:
        assert w in err
    assert not out.exists()


# ---------------------------------------------------------------- a small run
@pytest.mark.heavy
def test_cli_pack_with_a_thin_ring_writes_its_parameters(tmp_path, capsys):
    out = tmp_path / "bed"
    code = main(["pack", "--element", "pall_ring:thickness=0.024", "--count", "9",
                 "--container", "box:3", "--protocol", "rain", "--drop", "2", "--quiet",
                 "--samples", "4000", "--no-figures", "--out", str(out)])
    text = capsys.readouterr().out
    assert code == 0 and "bulk voidage eps" in text
    res = json.loads((out / "results.json").read_text())
    assert res["spec"]["element"] == "pall_ring"
    assert res["spec"]["element_params"]["thickness"] == 0.024
    assert res["spec"]["element_params"]["n_windows"] == 4          # resolved defaults too
    assert res["element"]["params"]["thickness"] == 0.024
    assert E.parse_element(res["element"]["text"])[1]["thickness"] == 0.024
    # the probe density followed the thin wall: more than the page's 1200 probes
    assert res["element"]["shell_probes"] > 1200
    assert res["run"]["complete"]


def test_probe_spacing_follows_the_thinnest_wall():
    from scipy.spatial import cKDTree

    thin = api.element_model(E.pall_ring(thickness=0.024))     # cached by the run above
    nn = cKDTree(thin.shell).query(thin.shell, k=2)[0][:, 1]
    assert len(thin.shell) > 1200 and np.median(nn) <= 0.024
    page = api.element_model(E.pall_ring())
    assert len(page.shell) == api.BUILD["target_shell_points"]     # the page's unchanged


# ---------------------------------------------------------------- specs, ids, sweeps
def test_spec_ids_carry_the_parameters():
    a = PackSpec(element="pall_ring:thickness=0.024")
    b = PackSpec(element="pall_ring:thickness=0.06")
    c = PackSpec(element="pall_ring : thickness=2.4e-2")
    assert a.element == c.element == "pall_ring:thickness=0.024"
    assert a.id == c.id and a.id != b.id and a.id != PackSpec().id
    assert a.element_params == {"thickness": 0.024}
    assert PackSpec.from_dict(a.as_dict()) == a
    # a spec without parameters keeps the id it had before parameters existed
    legacy = json.dumps(dict(PackSpec().as_dict(), format="peclet-ensemble/1"),
                        sort_keys=True, separators=(",", ":"))
    assert PackSpec().id == "s5-" + hashlib.sha256(legacy.encode()).hexdigest()[:16]
    with pytest.raises(PecletArgumentError, match="^element must be.*thickness"):
        PackSpec(element="pall_ring:thickness=0.3")


def test_sweep_of_an_element_parameter():
    sw = parse_sweep(["thickness=0.03,0.06,0.12", "mu=0.3,0.5"], "--sweep")
    assert sw == {"thickness": [0.03, 0.06, 0.12], "mu": [0.3, 0.5]}
    specs = make_specs([1, 2], sw, element="pall_ring:n_windows=5", container="box:4")
    assert len(specs) == 12 and len({s.id for s in specs}) == 12
    assert specs[0].element == "pall_ring:thickness=0.03,n_windows=5"
    assert [s.element_params["thickness"] for s in specs[::4]] == [0.03, 0.06, 0.12]
    # the ids are stable: the same sweep again gives the same ids
    assert [s.id for s in specs] == [s.id for s in make_specs([1, 2], sw,
                                                              element="pall_ring:n_windows=5",
                                                              container="box:4")]
    assert parse_sweep("n_windows=3,6", element="pall_ring") == {"n_windows": [3, 6]}
    assert parse_sweep("radius=0.25,0.5", element="sphere") == {"radius": [0.25, 0.5]}
    m = ensemble_manifest(specs, ["thickness", "mu"])
    assert "thickness" in m["swept"] and "element" in m["swept"]


@pytest.mark.parametrize("items,element,words", [
    ("thickness=0.05", "sphere", ["unknown parameter 'thickness'", "parameter of pall_ring"]),
    ("radius=0.3", "pall_ring", ["unknown parameter 'radius'", "not of pall_ring"]),
    ("window_half=0.2", "pall_ring", ["triple"]),
    ("thickness=0.03,0.2", "pall_ring", ["thickness", "(0, 0.16]"]),
    ("thickness=0.03,0.03", "pall_ring", ["given twice"]),
    ("n_windows=2.5", "pall_ring", ["not an integer"]),
    ("thickness=0.05", "pall_ring:thickness=0.1", ["not also fixed"]),
])
def test_bad_sweeps_are_refused(items, element, words):
    with pytest.raises(PecletArgumentError) as ei:
        parse_sweep(items, "--sweep", element=element)
    assert str(ei.value).startswith("--sweep must be")
    for w in words:
        assert w in str(ei.value), (w, str(ei.value))


def test_make_specs_refuses_a_parameter_the_element_lacks():
    with pytest.raises(PecletArgumentError, match="^sweep must be.*unknown parameter"):
        make_specs([1], {"thickness": [0.05]}, element="sphere")
    with pytest.raises(PecletArgumentError, match="^sweep must be.*not also fixed"):
        make_specs([1], {"thickness": [0.05]}, element="pall_ring:thickness=0.1")


@pytest.mark.parametrize("argv,flag,word", [
    (["--sweep", "radius=0.3"], "--sweep", "radius"),
    (["--element", "sphere", "--sweep", "thickness=0.03,0.06"], "--sweep", "thickness"),
    (["--sweep", "thickness=0.03,0.3"], "--sweep", "(0, 0.16]"),
    (["--element", "pall_ring:thickness=0.3"], "--element", "thickness"),
    (["--element", "pall_ring:nope=1"], "--element", "nope"),
])
def test_cli_ensemble_refuses_bad_element_parameters(tmp_path, capsys, argv, flag, word):
    out = tmp_path / "out"
    rc = main(["ensemble", "--seeds", "1-2", *argv, "--out", str(out), "--quiet"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and err.startswith(f"peclet ensemble: error: {flag} must be"), err
    assert "\n" not in err and word in err and not out.exists()


@pytest.mark.heavy
def test_a_tiny_thickness_sweep_realized(tmp_path):
    """Two thicknesses x one seed, 13 rings rained into the page's 3.5 D box, realized
    serially into the ledger; run() then reads them back (no cluster) and the summary groups
    by thickness."""
    specs = make_specs([1], parse_sweep("thickness=0.1,0.12"), container="box:3.5", count=13,
                       protocol="rain", mc_samples=20_000)
    led = Ledger(tmp_path / "out", ensemble_manifest(specs, ["thickness"]))
    results = {}
    for s in specs:
        res, pk = realize(s)
        assert res["spec"]["element"] == s.element
        led.write(s, res, pk)
        results[s.id] = res
    assert len({r["state_hash"] for r in results.values()}) == 2
    rows = run(specs, tmp_path / "out", scheduler="tcp://127.0.0.1:9", progress=False,
               swept=["thickness"])
    assert [r["thickness"] for r in rows] == [0.1, 0.12] and all(r["reused"] for r in rows)
    points = summarize(rows, ["thickness"])
    assert [p["thickness"] for p in points] == [0.1, 0.12] and [p["n"] for p in points] == \
        [1, 1]


def test_cli_ensemble_sweep_of_thickness_makes_one_spec_per_point_and_seed():
    from peclet.cli import build_parser
    from peclet.cli.ensemble import _specs

    args = build_parser().parse_args(["ensemble", "--element", "pall_ring:n_windows=5",
                                      "--seeds", "1-2", "--sweep", "thickness=0.03,0.06,0.12",
                                      "--out", "never-written", "--container", "box:4"])
    specs, sweep = _specs(args)
    assert sweep == {"thickness": [0.03, 0.06, 0.12]} and len(specs) == 6
    assert [s.element for s in specs[::2]] == [f"pall_ring:thickness={t},n_windows=5"
                                               for t in ("0.03", "0.06", "0.12")]
    assert len({s.id for s in specs}) == 6
