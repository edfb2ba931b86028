"""Issue 26 item 2, one front door: ``pack``, ``resume``, ``peclet pack``, ``peclet ensemble``,
the bulk analysis, the Dask connection and ``--peclet-replay`` check their input before work
with the rules of ``peclet pall-ring``. Each case asserts the exception type (or exit code 2
and one line) and that the message names the argument."""
import json
import os
import shutil
import socket
import subprocess
import sys
import textwrap
import threading
import time
import warnings

import numpy as np
import pytest

from peclet.cli import main
from peclet.core import geom
from peclet.core.validation import PecletArgumentError
from peclet.packing import Material, PageProtocol, RainProtocol, pack, resume
from peclet.packing.bed import api
from peclet.packing.analysis import geometry as analysis
from peclet.packing.analysis import profiles
from peclet.packing.bed import checkpoint as ckpt
from peclet.packing.bed.elements import sphere
from peclet.packing.bed.freeze import Pack
from peclet.packing.bed.protocols import LAND_SPEED, LandingWarning

SMALL_RAIN = RainProtocol(drop=3.0, settle_steps=3000, calm_steps=20, quench_steps=20)
GLASS = Material(e_n=0.3, e_t=0.0, mu=0.3)


def _no_build(monkeypatch):
    def fail(*a, **k):
        raise AssertionError("the element was measured before the arguments were checked")
    monkeypatch.setattr(api, "element_model", fail)


def _refused(name, call, *phrases):
    with pytest.raises(PecletArgumentError) as e:
        call()
    msg = str(e.value)
    assert msg.startswith(f"{name} must be") and "\n" not in msg, msg
    for p in phrases:
        assert p in msg, msg
    return msg


def _closed_box(half_w, height):
    """A tree container: a closed box (fluid region) standing on y = 0."""
    b = geom.SceneBuilder()
    return b, b.add_leaf("box", [half_w, 0.5 * height, half_w], translation=[0.0, 0.5 * height,
                                                                            0.0])


# ---------------------------------------------------------------- pack(): caps and fits
API_CASES = {
    "count above the cap": (dict(count=api.COUNT_MAX + 1), "count", "KiB per element"),
    "count far above the cap": (dict(count=10 ** 9), "count", f"[1, {api.count_cap()[0]}]"),
    "page: saddle wider than the column": (
        dict(element="intalox_saddle", container="column:1.5", protocol="page"), "container",
        "fits in"),
    "page: saddle wider than the walled box": (
        dict(element="intalox_saddle", container="walled:1.5,4", protocol="page"),
        "container", "clear width"),
    "page: closed container lower than the start cloud": (
        dict(container=_closed_box(1.5, 1.0), protocol="page"), "container", "room"),
    "page: start cloud above a closed container's ceiling": (
        dict(container=_closed_box(1.5, 4.0), count=300, protocol="page"), "count",
        "ceiling"),
    "element file that does not exist": (dict(element="/nonexistent/tree.npz"), "element",
                                         "does not exist"),
}


@pytest.mark.parametrize("case", sorted(API_CASES))
def test_pack_refuses_before_any_work(monkeypatch, case):
    kw, name, phrase = API_CASES[case]
    _no_build(monkeypatch)
    args = dict(element="sphere", container="column:3", count=5, progress=False)
    args.update(kw)
    _refused(name, lambda: pack(**args), phrase)      # _no_build: before any measurement


def test_the_start_cloud_stops_at_the_ceiling_instead_of_climbing():
    from peclet.packing.bed.containers import parse_container
    from peclet.packing.bed.protocols import start_cloud

    cont = parse_container(_closed_box(1.5, 4.0))
    _refused("count", lambda: start_cloud(300, cont, np.random.default_rng(0), y0=1.2,
                                          clearance=0.5, y_max=cont.ceiling(0.5)), "ceiling")


def test_resume_of_a_missing_directory_says_it_does_not_exist(tmp_path):
    _refused("checkpoint_dir", lambda: resume(tmp_path / "nope", progress=False),
             "does not exist")


# ---------------------------------------------------------------- checkpoints: one run id
@pytest.fixture(scope="module")
def two_checkpoints(tmp_path_factory):
    root = tmp_path_factory.mktemp("ckpts")
    kw = dict(count=6, protocol=SMALL_RAIN, material=GLASS, progress=False, max_steps=60,
              checkpoint_every=50)
    pack("sphere", "column:3", seed=1, checkpoint_dir=root / "a", **kw)
    pack("sphere", "column:3", seed=2, checkpoint_dir=root / "b", **kw)
    return root


def _copy_run(two_checkpoints, tmp_path, name="a"):
    dst = tmp_path / name
    shutil.copytree(two_checkpoints / name, dst)
    return dst


def _step_dir(path):
    return next(p for p in os.listdir(path) if p.startswith("ckpt-"))


def test_checkpoint_parts_carry_one_run_id(two_checkpoints):
    a = two_checkpoints / "a"
    run = ckpt.run_id(a)
    assert isinstance(run, str) and len(run) == 32 and run != ckpt.run_id(two_checkpoints / "b")
    assert json.loads((a / ckpt.POINTER).read_text())["run"] == run
    assert json.loads((a / _step_dir(a) / "run.json").read_text())["run"] == run
    with np.load(a / "element.npz") as z:
        assert str(z["run_id"]) == run
    spec, element, sim, state, _ = ckpt.read(a)          # the parts agree: read as before
    assert "run_id" not in element and sim is not None and state["step"] == 50


def _swap_step(a, b):
    name = _step_dir(a)
    shutil.rmtree(a / name)
    shutil.copytree(b / _step_dir(b), a / name)


MIXES = {
    "step directory of another run": lambda a, b: _swap_step(a, b),
    "element of another run": lambda a, b: shutil.copy(b / "element.npz", a / "element.npz"),
    "spec of another run": lambda a, b: shutil.copy(b / "spec.json", a / "spec.json"),
    "sim.npz of another run": lambda a, b: shutil.copy(b / _step_dir(b) / "sim.npz",
                                                       a / _step_dir(a) / "sim.npz"),
    "state.json of another run": lambda a, b: shutil.copy(b / _step_dir(b) / "state.json",
                                                          a / _step_dir(a) / "state.json"),
    "run.json removed": lambda a, b: os.remove(a / _step_dir(a) / "run.json"),
}


@pytest.mark.parametrize("mix", sorted(MIXES))
def test_mixed_checkpoint_parts_are_refused(two_checkpoints, tmp_path, monkeypatch, mix):
    a = _copy_run(two_checkpoints, tmp_path, "a")
    b = two_checkpoints / "b"
    MIXES[mix](a, b)
    _no_build(monkeypatch)
    _refused("checkpoint_dir", lambda: resume(a, progress=False),
             "a checkpoint whose parts all come from one run")


def test_cli_resume_of_mixed_parts_is_one_line(two_checkpoints, tmp_path, capsys):
    a = _copy_run(two_checkpoints, tmp_path, "a")
    shutil.copy(two_checkpoints / "b" / "element.npz", a / "element.npz")
    rc = main(["pack", "--resume", str(a), "--quiet", "--no-figures"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "\n" not in err and err.startswith("peclet pack: error: --resume must")
    assert "mixed parts" in err


# ---------------------------------------------------------------- the landing rule
def test_a_quench_on_falling_elements_is_flagged_and_a_landed_bed_is_not():
    # the quench starts 0.22 time units in: mid-air, the taps' kicks having slowed the fall
    # below LAND_SPEED, so the page's predicted fall time is what flags it
    proto = PageProtocol().scaled(0.04)
    with pytest.warns(LandingWarning, match="free fall"):
        res = pack("sphere", "box:3.5", count=10, protocol=proto, seed=3, progress=False)
    rec = res.state.landing
    assert res.landed is False and rec["fall_time"] > rec["landing_time"]
    assert rec["step"] == proto.total_steps - proto.quench_steps
    # 13 spheres at 0.23 of the steps: the fall fits, but they bounce: the speed flags it
    with pytest.warns(LandingWarning, match="faster than 1 D/time"):
        res = pack("sphere", "box:3.5", count=13, protocol=PageProtocol().scaled(0.23),
                   seed=5, progress=False)
    rec = res.state.landing
    assert res.landed is False and rec["moving"] > 0 and rec["max_speed"] > LAND_SPEED
    assert rec["fall_time"] < rec["landing_time"]
    with warnings.catch_warnings():
        warnings.simplefilter("error", LandingWarning)
        ok = pack("sphere", "column:3", count=8, protocol=SMALL_RAIN, material=GLASS, seed=2,
                  progress=False)
    assert ok.landed is True and ok.state.landing["moving"] == 0


def test_the_page_rule_predicts_the_landing_before_any_work():
    from peclet.packing.bed.containers import parse_container
    from peclet.packing.bed.protocols import Body

    cont = parse_container("box:3.5")
    ctx = dict(container=cont, body=Body(-1, 1.0, np.ones(3), 0.72, 1.0), count=48)
    PageProtocol().check_landing(ctx, 26.0)                  # the page's own run lands
    _refused("count", lambda: PageProtocol().scaled(0.04).check_landing(ctx, 26.0),
             "land before the quench")


# ---------------------------------------------------------------- bulk: no 1.0000 +- 0
def _spheres(pos, box=(50.0, 50.0)):
    el = sphere(0.5)
    ni, nr, _, _ = el.builder.encode()
    pos = np.asarray(pos, float)
    q = np.tile([0.0, 0.0, 0.0, 1.0], (len(pos), 1))
    probes = 0.5 * np.vstack([np.eye(3), -np.eye(3)])
    return Pack(pos, q, box, el.envelope_volume, ni, nr, el.root, 0.5, probes, 1.0,
                [1.0, 1.0, 1.0], el.envelope_root, el.envelope_volume)


def test_bulk_windows_refuse_a_bed_with_no_element_in_a_window():
    gap = _spheres([[1.0, 0.5, 1.0], [3.0, 0.5, 3.0], [2.0, 12.0, 2.0]])
    _refused("pack", lambda: analysis.bulk_windows(gap), "reaches its bulk window")
    sunk = _spheres([[1.0, -0.5, 1.0]])
    _refused("pack", lambda: analysis.bulk_windows(sunk), "above the floor")


def test_profiles_bulk_refuses_an_empty_window_and_a_window_no_sample_hit():
    p = _spheres([[1.0, 0.5, 1.0], [2.0, 9.5, 2.0]])
    sec = profiles.periodic_section(p)
    _refused("pack", lambda: profiles.bulk(p, sec, top_y=9.5, crop=0.5,
                                           samples_per_window=1000), "film")
    film = _spheres([[1.0, 0.5, 1.0]], box=(1000.0, 1000.0))
    _refused("samples_per_window",
             lambda: profiles.bulk(film, profiles.periodic_section(film), top_y=1.0,
                                   crop=0.4, samples_per_window=2000), "1 +- 0")


# ---------------------------------------------------------------- peclet pack
SPHERE = ["--element", "sphere", "--quiet"]
CLI_CASES = [
    (["--protocol", "page", "--batch", "3"], "--batch", "--protocol rain"),
    (["--protocol", "page", "--insert-every", "2"], "--insert-every", "--protocol rain"),
    (["--protocol", "page", "--drop", "5"], "--drop", "--protocol rain"),
    (["--protocol", "rain", "--steps-scale", "0.5"], "--steps-scale", "--protocol page"),
    (["--count", "10000000"], "--count", "KiB per element"),
    (["--samples", "100000000"], "--samples", "bytes per sample"),
    (["--element", "missing.npz"], "--element", "does not exist"),
    (["--container", "box:50", "--count", "48"], "--count", "one element per D^2"),
    (["--container", "box:3.5", "--count", "10", "--steps-scale", "0.04"], "--count",
     "land before the quench"),
    (["--element", "intalox_saddle", "--container", "column:1.5"], "--container", "fits in"),
    (["--steps-scale", "1000"], "--steps-scale", "(0, 100]"),
]


@pytest.mark.parametrize("argv,flag,phrase", CLI_CASES,
                         ids=[" ".join(c[0]) for c in CLI_CASES])
def test_peclet_pack_refuses_in_one_line(tmp_path, capsys, argv, flag, phrase):
    out = tmp_path / "o"
    rc = main(["pack", "--out", str(out)] + SPHERE + argv)
    err = capsys.readouterr().err.strip()
    assert rc == 2, err
    assert "\n" not in err and err.startswith(f"peclet pack: error: {flag} must be"), err
    assert phrase in err, err
    assert not out.exists()


def test_peclet_pack_resume_of_a_missing_directory(tmp_path, capsys):
    rc = main(["pack", "--resume", str(tmp_path / "gone")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "\n" not in err and err.startswith("peclet pack: error: --resume must")
    assert "does not exist" in err


def test_peclet_pack_does_not_report_a_bed_that_did_not_land(tmp_path, capsys):
    """The landing rule after the run: 13 spheres at 0.23 of the page's steps pass the
    predicted rule (the cloud's top falls in 1.22 < 1.29 time units) but collide and bounce:
    at the quench's start 5 still move faster than 1 D/time. Saved, not analysed, exit 1."""
    out = tmp_path / "o"
    with pytest.warns(LandingWarning):
        rc = main(["pack", "--out", str(out), "--element", "sphere", "--container", "box:3.5",
                   "--count", "13", "--steps-scale", "0.23", "--quiet", "--samples", "4000"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1 and err[-1].startswith("peclet pack: error: the bed did not land"), err
    assert "faster than 1 D/time" in err[-1]
    assert (out / "pack.npz").is_file() and not (out / "results.json").exists()


# ---------------------------------------------------------------- peclet ensemble
def _silent_server(garbage=False):
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen(8)
    held = []

    def serve():
        while True:
            try:
                c, _ = s.accept()
            except OSError:
                return
            held.append(c)
            if garbage:
                c.sendall(b"HTTP/1.0 200 OK\r\n\r\nnot dask at all\n" * 8)
    threading.Thread(target=serve, daemon=True).start()
    return s, f"tcp://127.0.0.1:{s.getsockname()[1]}"


ENSEMBLE_CASES = [
    (["--protocol", "rain", "--steps-scale", "0.5"], "--steps-scale", "unless protocol"),
    (["--count", "10000000"], "--count", "KiB per element"),
    (["--mc-samples", "100000000"], "--mc-samples", "bytes per sample"),
]


@pytest.mark.parametrize("argv,flag,phrase", ENSEMBLE_CASES,
                         ids=[" ".join(c[0]) for c in ENSEMBLE_CASES])
def test_peclet_ensemble_refuses_in_one_line(tmp_path, capsys, argv, flag, phrase):
    out = tmp_path / "o"
    rc = main(["ensemble", "--seeds", "1-2", "--element", "sphere", "--out", str(out),
               "--quiet"] + argv)
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "\n" not in err, err
    assert err.startswith(f"peclet ensemble: error: {flag} must be") and phrase in err, err
    assert not out.exists()


@pytest.mark.parametrize("garbage", [False, True], ids=["silent", "garbage"])
def test_a_live_non_dask_port_fails_within_the_timeout(tmp_path, capsys, garbage):
    s, addr = _silent_server(garbage)
    out = tmp_path / "o"
    try:
        t = time.perf_counter()
        rc = main(["ensemble", "--seeds", "1-2", "--element", "sphere", "--count", "4",
                   "--out", str(out), "--quiet", "--scheduler", addr])
        took = time.perf_counter() - t
    finally:
        s.close()
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "\n" not in err, err
    assert err.startswith("peclet ensemble: error: --scheduler must be") and "3 s" in err, err
    # bounded by the 3 s timeout (the old handshake blocked for minutes); the bound leaves
    # room for a loaded 2-core machine
    assert took < 60.0 and not out.exists()


def test_an_address_from_the_environment_is_named_as_such(tmp_path, capsys, monkeypatch):
    s, addr = _silent_server()
    monkeypatch.setenv("DASK_SCHEDULER_ADDRESS", addr)
    try:
        rc = main(["ensemble", "--seeds", "1", "--element", "sphere", "--count", "4",
                   "--out", str(tmp_path / "o"), "--quiet"])
    finally:
        s.close()
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "\n" not in err, err
    assert err.startswith("peclet ensemble: error: DASK_SCHEDULER_ADDRESS (environment "
                          "variable) must be"), err
    assert "--scheduler" not in err


def test_connect_api_bounds_the_handshake():
    from peclet.ensemble.runner import connect

    s, addr = _silent_server()
    try:
        t = time.perf_counter()
        with pytest.raises(PecletArgumentError) as e:
            with connect(addr, connect_timeout=1.0):
                pass
        assert time.perf_counter() - t < 30.0          # 1 s timeout; minutes before
    finally:
        s.close()
    assert str(e.value).startswith("scheduler must be") and "within 1 s" in str(e.value)


# ---------------------------------------------------------------- --peclet-replay
CERT = textwrap.dedent('''
    import pytest
    from hypothesis import strategies as st
    from peclet_verify import search as S

    @pytest.mark.peclet_certify
    def test_small(peclet_certificate):
        peclet_certificate(S.search(
            lambda x: S.PropertyResult("small", x < 10 ** 7, 1, float(x), "x", f"x = {x}",
                                       "passed"),
            st.integers(0, 10 ** 6), name="small numbers"))
''')


def _pytest(cwd, *args):
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           *args], cwd=cwd, capture_output=True, text=True, timeout=600)


def test_replay_of_a_database_with_no_examples_is_a_usage_error(tmp_path):
    (tmp_path / "test_c.py").write_text(CERT)
    (tmp_path / "db").mkdir()
    (tmp_path / "db" / "somekey").mkdir()
    proc = _pytest(tmp_path, "--peclet-certify", "--peclet-replay=db")
    assert proc.returncode == 4, proc.stdout + proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.startswith("ERROR:")]
    assert len(lines) == 1 and "--peclet-replay db" in lines[0]
    assert "holds no examples" in lines[0]


def test_replay_that_re_runs_no_example_fails_the_run(tmp_path):
    (tmp_path / "test_c.py").write_text(CERT)
    (tmp_path / "db" / "0123456789abcdef").mkdir(parents=True)
    (tmp_path / "db" / "0123456789abcdef" / "fedcba9876543210").write_bytes(b"\x00\x01")
    proc = _pytest(tmp_path, "--peclet-certify", "--peclet-replay=db")
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "--peclet-replay db: no certificate re-ran a saved example" in proc.stdout
    assert "nothing was certified" in proc.stdout
