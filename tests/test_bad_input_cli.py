"""Bad input to ``peclet pall-ring``: every refusal happens before the ring is built, is one
``peclet pall-ring: error:`` line naming the option, exit code 2, and writes nothing
(issue 18 item 5, issue 14's ``--rings 400 --box 10``). Most cases run ``peclet.cli.main``
in-process; a few go through a real interpreter to see what a user sees."""
import math
import os
import subprocess
import sys
import time

import numba
import pytest

from peclet.cli import main
from peclet.core.outputs import MANIFEST, recording
from peclet.packing.page import checks as C

CAP = int(numba.config.NUMBA_NUM_THREADS)

CASES = [
    # (argv after the output option, the option the error must name, a phrase it must hold)
    (["--box", "0.5"], "--box", "D for 48 rings"),
    (["--box", "0"], "--box", "(0, 100]"),
    (["--box", "-1"], "--box", "(0, 100]"),
    (["--box", "nan"], "--box", "finite"),
    (["--box", "inf"], "--box", "finite"),
    (["--box", "-inf"], "--box", "finite"),          # a negative value after its option
    (["--box", "-1e3"], "--box", "(0, 100]"),
    (["--box", "abc"], "--box", "a number"),
    (["--box", "1000"], "--box", "(0, 100]"),
    (["--box", "3.0"], "--box", "contact cutoff"),
    (["--rings", "1000", "--box", "10"], "--box", "land before the quench"),
    (["--steps-scale", "0.1"], "--box", "--steps-scale"),
    (["--seed", "-1"], "--seed", ">= 0"),
    (["--seed", "1.5"], "--seed", "an integer"),
    (["--seed", "five"], "--seed", "an integer"),
    (["--rings", "0"], "--rings", "[1, 10000]"),
    (["--rings", "-3"], "--rings", "[1, 10000]"),
    (["--rings", "2000"], "--box", "D for 2000 rings"),
    (["--rings", "1000000"], "--rings", "[1, 10000]"),
    (["--rings", "10001"], "--rings", "[1, 10000]"),
    (["--rings", "2.5"], "--rings", "an integer"),
    (["--rings", "1e3"], "--rings", "an integer"),
    (["--shell-points", "1"], "--shell-points", "[600, 20000]"),
    (["--shell-points", "599"], "--shell-points", "wall thickness"),
    (["--shell-points", "100000"], "--shell-points", "[600, 20000]"),
    (["--mc-samples", "1"], "--mc-samples", "standard error"),
    (["--mc-samples", "999"], "--mc-samples", "[1000, 1e+07]"),
    (["--mc-samples", "100000000"], "--mc-samples", "[1000, 1e+07]"),
    (["--threads", "0"], "--threads", "NUMBA_NUM_THREADS"),
    (["--threads", str(CAP + 1)], "--threads", f"[1, {CAP}]"),
    (["--threads", "two"], "--threads", "an integer"),
    (["--steps-scale", "0"], "--steps-scale", "(0, 20]"),
    (["--steps-scale", "-2"], "--steps-scale", "(0, 20]"),
    (["--steps-scale", "nan"], "--steps-scale", "finite"),
    (["--steps-scale", "25"], "--steps-scale", "(0, 20]"),
]


def _call(argv, capsys):
    rc = main(["pall-ring"] + argv)
    err = capsys.readouterr().err
    return rc, err


def _assert_one_line(err, option, phrase=""):
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"peclet pall-ring: error: {option} must"), err
    assert phrase in lines[0], err
    assert "Traceback" not in err


@pytest.mark.parametrize("argv,option,phrase", CASES, ids=[" ".join(c[0]) for c in CASES])
def test_a_bad_option_is_one_line_exit_2_and_nothing_written(tmp_path, capsys, argv, option,
                                                             phrase):
    out = tmp_path / "run"
    t = time.perf_counter()
    rc, err = _call(["--out", str(out)] + argv, capsys)
    assert rc == 2
    _assert_one_line(err, option, phrase)
    assert not out.exists() and os.listdir(tmp_path) == []
    assert time.perf_counter() - t < 20          # refused before the build (minutes)


@pytest.mark.parametrize("argv,phrase", [
    (["--no-such-option"], "unrecognized arguments: --no-such-option"),
    (["--rings"], "argument --rings: expected one argument"),
    (["--overwrite", "-1"], "argument --overwrite: ignored explicit argument '-1'"),
])
def test_what_argparse_refuses_is_one_line_too(tmp_path, capsys, argv, phrase):
    out = tmp_path / "run"
    with pytest.raises(SystemExit) as exc:
        main(["pall-ring", "--out", str(out)] + argv)
    err = capsys.readouterr().err
    assert exc.value.code == 2
    # an unknown option is the top-level parser's (``peclet: error:``), the rest the command's
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("peclet") and f"error: {phrase}" in lines[0]
    assert not out.exists()


def test_out_that_is_a_file_or_lies_under_one(tmp_path, capsys):
    f = tmp_path / "f"
    f.write_text("mine")
    for out, phrase in [(f, "it is a file"), (f / "sub", "is a file, not a directory")]:
        rc, err = _call(["--out", str(out)], capsys)
        assert rc == 2
        _assert_one_line(err, "--out", phrase)
    assert f.read_text() == "mine" and os.listdir(tmp_path) == ["f"]


def test_read_only_out_is_refused_before_the_run(tmp_path, capsys):
    out = tmp_path / "ro"
    out.mkdir()
    out.chmod(0o555)
    try:
        rc, err = _call(["--out", str(out)], capsys)
    finally:
        out.chmod(0o755)
    assert rc == 2
    _assert_one_line(err, "--out", "read-only")
    assert os.listdir(out) == []


@pytest.mark.parametrize("name", ["results.json", "pall_ring_pack.npz", "pour.gif"])
def test_out_holding_an_earlier_run_needs_overwrite(tmp_path, capsys, name):
    out = tmp_path / "run"
    with recording(out, C.OUTPUTS):            # as an earlier run records what it wrote
        (out / name).write_text("earlier run")
    rc, err = _call(["--out", str(out)], capsys)
    assert rc == 2
    _assert_one_line(err, "--out", "--overwrite")
    assert (out / name).read_text() == "earlier run"
    assert sorted(os.listdir(out)) == sorted([MANIFEST, name])


@pytest.mark.parametrize("overwrite", [[], ["--overwrite"]])
def test_a_file_no_run_wrote_is_refused_by_name_and_kept(tmp_path, capsys, overwrite):
    """A file at one of the run's names that no manifest lists is the user's: refused with its
    name, with or without --overwrite, and left byte for byte."""
    out = tmp_path / "run"
    out.mkdir()
    (out / "results.json").write_bytes(b"my own results")
    rc, err = _call(["--out", str(out)] + overwrite, capsys)
    assert rc == 2
    _assert_one_line(err, "--out", "results.json is not a file an earlier peclet run wrote")
    assert (out / "results.json").read_bytes() == b"my own results"
    assert os.listdir(out) == ["results.json"]


def test_out_where_an_output_name_is_a_directory(tmp_path, capsys):
    out = tmp_path / "run"
    (out / "results.json").mkdir(parents=True)
    rc, err = _call(["--out", str(out), "--overwrite"], capsys)
    assert rc == 2
    _assert_one_line(err, "--out", "results.json in it is a directory")


def test_overwrite_clears_exactly_the_earlier_runs_files(tmp_path):
    out = tmp_path / "run"
    with recording(out, C.OUTPUTS):
        for n in C.OUTPUTS:
            (out / n).write_text("old")
    (out / "notes.txt").write_text("mine")
    plan = C.check_run(out=str(out), overwrite=True, cli=True)
    assert set(plan.previous) == set(C.OUTPUTS)
    C.clear_outputs(plan.out, plan.previous)
    assert sorted(os.listdir(out)) == [MANIFEST, "notes.txt"]


def test_issue_14_rings_400_box_10_passes_every_check_and_sizes_the_domain(tmp_path):
    """``peclet pall-ring --rings 400 --box 10`` died in the pour with ``y_top=60.0 is below
    the start cloud's top 63.45``: the domain's height now follows from the count."""
    from peclet.packing.bed.pour import start_cloud

    plan = C.check_run(out=str(tmp_path / "r"), rings=400, box=10.0, cli=True)
    top = start_cloud(400, 10.0, 5)[0][:, 1].max()
    assert plan.y_cloud == top and plan.y_top >= top + 2.0      # the pour's own requirement
    # the rules' numbers: landing time and the engine's cell bound, recomputed here
    assert math.sqrt(2 * top / 9.81) <= 2800 * 2e-3
    assert plan.box_min < 10.0
    assert not (tmp_path / "r").exists()                         # checks write nothing


def test_the_page_run_passes_and_keeps_the_pages_domain(tmp_path):
    plan = C.check_run(out=str(tmp_path / "r"), cli=True)
    assert plan.y_top == 60.0 and plan.rings == 48 and plan.box == 3.5


def test_the_radius_bound_holds_against_the_quadrature_centre_of_mass():
    """The box rule's r_b (before any build) bounds r + |c - com| with com by quadrature."""
    import numpy as np

    from peclet.packing.bed import elements as E

    ring = E.pall_ring()
    c, r, _ = ring.builder.node_bound(ring.root)
    p = ring.builder.body_properties(ring.root, *ring.bounds, n=8, tol=1e-3)
    exact = r + float(np.linalg.norm(p.com - c))
    bound = C.ring_radius_bound()
    assert exact <= bound <= exact + 0.03


def test_the_shell_points_minimum_spreads_probes_at_most_a_wall_apart():
    """SHELL_POINTS_MIN from the ring's area measured here (marching cubes) and its wall."""
    from peclet.core.geom.mesh import surface_mesh
    from peclet.core.geom.shell import count_for_spacing, even_spacing
    from peclet.packing.bed import elements as E

    ring = E.pall_ring()
    area = surface_mesh(ring.builder, ring.root, [-0.62] * 3, [0.62] * 3, 80)[2]
    t = ring.params["thickness"]
    assert count_for_spacing(area, t) <= C.SHELL_POINTS_MIN
    assert even_spacing(area, C.SHELL_POINTS_MIN) <= t


def test_the_engine_refuses_what_rule_1_refuses():
    """Rule 1 is at least the engine's own check (L > 2 (2 r_b + margin)) at the fall speed."""
    from peclet.dem.simulation import DEFAULT_MARGIN_FRACTION

    r_b, y, dt = 0.72, 26.0, 2e-3
    engine = 2 * (2 * r_b + DEFAULT_MARGIN_FRACTION * r_b + 2 * dt * math.sqrt(2 * 9.81 * y))
    assert C.box_bound(r_b, y, dt) >= engine


@pytest.mark.parametrize("argv,option", [(["--seed", "-1"], "--seed"),
                                         (["--rings", "1000000"], "--rings"),
                                         (["--mc-samples", "1"], "--mc-samples")])
def test_through_a_real_interpreter(tmp_path, argv, option):
    out = tmp_path / "run"
    r = subprocess.run([sys.executable, "-m", "peclet.cli", "pall-ring", "--out", str(out)]
                       + argv, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2
    _assert_one_line(r.stderr, option)
    assert r.stdout == "" and not out.exists()
