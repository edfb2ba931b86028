"""``peclet pack``: bad arguments (one line naming them, exit 2, nothing written), a small run
end to end (files, table), and --resume finishing an interrupted run bit for bit."""
import json
import os

import pytest

from peclet.cli import main
from peclet.packing import Material, RainProtocol, pack

FAST = ["--element", "sphere", "--container", "column:2.5", "--count", "6", "--protocol",
        "rain", "--mu", "0.3", "--quiet", "--samples", "4000", "--drop", "3"]


def _run(capsys, args):
    code = main(args)
    out, err = capsys.readouterr()
    return code, out, err


BAD = [
    (["--element", "pall_rng"], "--element"),
    (["--element", "missing.npz"], "--element"),
    (["--container", "cylinder:5"], "--container"),
    (["--container", "column:1.2"], "--container"),
    (["--container", "walled:3"], "--container"),
    (["--count", "0"], "--count"),
    (["--count", "ten"], "--count"),
    (["--mu", "-0.1"], "--mu"),
    (["--wall-mu", "-1"], "--wall-mu"),
    (["--restitution", "1.5"], "--restitution"),
    (["--seed", "-1"], "--seed"),
    (["--protocol", "drop"], "--protocol"),
    (["--threads", "0"], "--threads"),
    (["--steps-scale", "0"], "--steps-scale"),
    (["--checkpoint-every", "0"], "--checkpoint-every"),
    (["--samples", "10"], "--samples"),
    (["--drop", "-1"], "--drop"),
    (["--batch", "0"], "--batch"),
    (["--element", "intalox_saddle", "--container", "column:1.5", "--protocol", "rain"],
     "--container"),
]


@pytest.mark.parametrize("args,flag", BAD, ids=[f"{b[1]}-{i}" for i, b in enumerate(BAD)])
def test_bad_argument_is_one_line_exit_2_nothing_written(tmp_path, capsys, args, flag):
    out = tmp_path / "o"
    code, _, err = _run(capsys, ["pack", "--out", str(out), "--quiet"] + args)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"peclet pack: error: {flag} must be")
    assert not out.exists()


def test_out_holding_another_run_and_resume_of_a_non_checkpoint(tmp_path, capsys):
    out = tmp_path / "o"
    out.mkdir()
    (out / "results.json").write_text('{"another": "run"}')
    code, _, err = _run(capsys, ["pack", "--out", str(out)] + FAST)
    assert code == 2 and err.startswith("peclet pack: error: --out must be")
    assert json.loads((out / "results.json").read_text()) == {"another": "run"}
    (tmp_path / "f").write_text("x")
    code, _, err = _run(capsys, ["pack", "--out", str(tmp_path / "f")] + FAST)
    assert code == 2 and err.startswith("peclet pack: error: --out must be")
    for d in (tmp_path / "none", out):
        code, _, err = _run(capsys, ["pack", "--resume", str(d)])
        assert code == 2 and err.startswith("peclet pack: error: --resume must be")
    assert sorted(os.listdir(out)) == ["results.json"]


def test_a_small_run_writes_its_files_and_table(tmp_path, capsys):
    out = tmp_path / "bed"
    code, text, _ = _run(capsys, ["pack", "--out", str(out)] + FAST)
    assert code == 0
    for f in ("pack.npz", "results.json", "radial_profile.png", "axial_profile.png", "bed.png",
              "bed.stl", "bed.vtu", "transforms.csv"):
        assert (out / f).is_file(), f
    assert not (out / "checkpoint").exists()
    res = json.loads((out / "results.json").read_text())
    assert res["spec"]["count"] == 6 and res["run"]["complete"]
    assert "bulk voidage eps" in text and res["run"]["state_sha256"][:16] in text
    # the same inputs through the API give the same bits
    api = pack("sphere", "column:2.5", count=6, protocol=RainProtocol(drop=3.0),
               material=Material(0.15, 0.0, 0.3), seed=5, progress=False)
    assert api.state_hash() == res["run"]["state_sha256"]
    # a rerun into the same --out needs --overwrite
    code, _, err = _run(capsys, ["pack", "--out", str(out), "--no-figures"] + FAST)
    assert code == 2 and "--out must be" in err
    # with --overwrite the old run's figures do not stay beside the new results
    code, _, _ = _run(capsys, ["pack", "--out", str(out), "--no-figures", "--overwrite",
                               "--seed", "6"] + FAST)
    assert code == 0 and not (out / "bed.png").exists() and not (out / "bed.stl").exists()
    assert json.loads((out / "results.json").read_text())["spec"]["seed"] == 6


def test_resume_finishes_an_interrupted_run_bit_for_bit(tmp_path, capsys):
    proto = RainProtocol(drop=3.0)
    kw = dict(count=6, protocol=proto, material=Material(0.15, 0.0, 0.3), seed=5,
              progress=False)
    full = pack("sphere", "column:2.5", **kw)
    out = tmp_path / "run"
    part = pack("sphere", "column:2.5", max_steps=150, checkpoint_dir=out / "checkpoint",
                checkpoint_every=60, **kw)
    assert not part.complete
    code, _, _ = _run(capsys, ["pack", "--resume", str(out), "--no-figures", "--quiet"])
    assert code == 0
    res = json.loads((out / "results.json").read_text())
    assert res["run"]["state_sha256"] == full.state_hash()
    assert not (out / "checkpoint").exists()
