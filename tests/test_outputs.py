"""Nothing a user saved is lost: a run removes only the files its manifest says a peclet run
wrote (peclet.core.outputs), and refuses, naming the file, when anything else is in its way."""
import json
import os
import shutil
import subprocess
import sys
import textwrap

import pytest

from peclet.cli import main
from peclet.core.files import remove_parts
from peclet.core.outputs import (MANIFEST, check_output_dir, clear_outputs, owned_files,
                                 recording)
from peclet.core.validation import PecletArgumentError

NAMES = ("results.json", "frames", "checkpoint")
DIRS = ("frames", "checkpoint")
USER_FILES = {"checkpoint/model.ckpt": b"\x00weights\xff" * 100,
              "frames/IMG_0001.jpg": b"\xff\xd8\xff\xe0 a holiday photo"}


def _earlier_run(out):
    """What a finished run leaves: its outputs and the manifest listing them."""
    with recording(out, NAMES):
        (out / "frames").mkdir(parents=True)
        (out / "checkpoint").mkdir()
        (out / "results.json").write_text('{"run": 1}')
        (out / "frames" / "frame_0000.vtu").write_text("frame")
        (out / "checkpoint" / "checkpoint.json").write_text("{}")


def _put_user_files(out):
    for rel, data in USER_FILES.items():
        (out / rel).parent.mkdir(parents=True, exist_ok=True)
        (out / rel).write_bytes(data)


def _assert_user_files_intact(out):
    for rel, data in USER_FILES.items():
        assert (out / rel).read_bytes() == data, rel


def _tree(out):
    return {os.path.relpath(os.path.join(r, f), out): open(os.path.join(r, f), "rb").read()
            for r, _, fs in os.walk(out) for f in fs}


def test_the_manifest_lists_exactly_what_the_run_wrote(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    _earlier_run(out)
    m = json.loads((out / MANIFEST).read_text())
    assert sorted(m["files"]) == ["checkpoint/checkpoint.json", "frames/frame_0000.vtu",
                                  "results.json"]
    assert m["running"] is None
    e = m["files"]["results.json"]
    assert e["size"] == len('{"run": 1}') and len(e["sha256"]) == 64


def test_an_earlier_run_needs_overwrite_and_then_goes_whole(tmp_path):
    out = tmp_path / "run"
    _earlier_run(out)
    (out / "notes.txt").write_text("mine")
    with pytest.raises(PecletArgumentError, match="holds an earlier run's files"):
        check_output_dir(out, NAMES, False, dirs=DIRS)
    p, previous = check_output_dir(out, NAMES, True, dirs=DIRS)
    assert set(previous) == set(NAMES)
    clear_outputs(p, previous)
    assert sorted(os.listdir(out)) == [MANIFEST, "notes.txt"]
    assert json.loads((out / MANIFEST).read_text())["files"] == {}


@pytest.mark.parametrize("rel", sorted(USER_FILES))
def test_a_users_file_inside_an_output_directory_is_refused_by_name(tmp_path, rel):
    out = tmp_path / "run"
    _earlier_run(out)
    (out / rel).write_bytes(USER_FILES[rel])
    before = _tree(out)
    for overwrite in (False, True):
        with pytest.raises(PecletArgumentError, match="is not a file an earlier peclet run "
                                                      "wrote") as exc:
            check_output_dir(out, NAMES, overwrite, dirs=DIRS)
        assert rel in str(exc.value)
    assert _tree(out) == before


def test_an_output_the_user_edited_is_no_longer_ours(tmp_path):
    out = tmp_path / "run"
    _earlier_run(out)
    (out / "results.json").write_text('{"edited": "by hand"}')
    with pytest.raises(PecletArgumentError, match="results.json is not a file"):
        check_output_dir(out, NAMES, True, dirs=DIRS)
    assert (out / "results.json").read_text() == '{"edited": "by hand"}'


def test_a_directory_without_a_manifest_or_with_a_broken_one_owns_nothing(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / "results.json").write_text("written by an older peclet or by hand")
    for manifest in (None, "{not json", '{"kind": "something else", "files": {}}'):
        if manifest is not None:
            (out / MANIFEST).write_text(manifest)
        with pytest.raises(PecletArgumentError, match=f"no {MANIFEST} lists it"):
            check_output_dir(out, NAMES, True, dirs=DIRS)
        assert owned_files(out) == {}
    assert (out / "results.json").exists()


def test_a_copied_directory_keeps_its_ownership_by_content(tmp_path):
    """``cp -r`` gives new modification times: the SHA-256 still shows the files are ours."""
    src, dst = tmp_path / "run", tmp_path / "copy"
    _earlier_run(src)
    shutil.copytree(src, dst, copy_function=shutil.copyfile)
    os.utime(dst / "results.json", ns=(1, 1))
    p, previous = check_output_dir(dst, NAMES, True, dirs=DIRS)
    assert set(previous) == set(NAMES)


def test_a_killed_runs_files_are_recognised_from_its_snapshot(tmp_path):
    """A run ended by SIGKILL never finalises its manifest; the snapshot taken on entry still
    tells its files from the ones that were there before it (and a user's file kept beside
    the output names is not touched)."""
    out = tmp_path / "run"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    code = textwrap.dedent(f"""
        import os, pathlib
        from peclet.core.outputs import recording
        out = pathlib.Path({str(out)!r})
        with recording(out, {NAMES!r}):
            (out / "frames").mkdir()
            (out / "frames" / "frame_0000.vtu").write_text("half a run")
            (out / "results.json").write_text("partial")
            os._exit(9)
    """)
    rc = subprocess.run([sys.executable, "-c", code], timeout=120).returncode
    assert rc == 9
    assert json.loads((out / MANIFEST).read_text())["running"] is not None
    assert set(owned_files(out)) == {"frames/frame_0000.vtu", "results.json"}
    p, previous = check_output_dir(out, NAMES, True, dirs=DIRS)
    assert set(previous) == {"frames", "results.json"}
    with recording(p, NAMES):
        clear_outputs(p, previous)
    assert sorted(os.listdir(out)) == [MANIFEST, "notes.txt"]
    assert json.loads((out / MANIFEST).read_text()) == dict(kind="peclet-outputs", files={},
                                                              running=None)


def test_clear_outputs_never_removes_a_file_that_appeared_after_the_check(tmp_path):
    out = tmp_path / "run"
    _earlier_run(out)
    p, previous = check_output_dir(out, NAMES, True, dirs=DIRS)
    _put_user_files(out)                 # arrives between the check and the clearing
    clear_outputs(p, previous)
    _assert_user_files_intact(out)
    assert not (out / "results.json").exists()
    assert not (out / "frames" / "frame_0000.vtu").exists()
    assert not (out / "checkpoint" / "checkpoint.json").exists()


def test_remove_parts_removes_a_formats_own_entries_only(tmp_path):
    d = tmp_path / "checkpoint"
    (d / "ckpt-000000010").mkdir(parents=True)
    (d / "ckpt-000000010" / "sim.npz").write_bytes(b"x")
    (d / "checkpoint.json").write_text("{}")
    (d / "model.ckpt").write_bytes(b"user")
    remove_parts(d, names=("checkpoint.json",), prefixes=("ckpt-",))
    assert os.listdir(d) == ["model.ckpt"]
    (d / "model.ckpt").unlink()
    remove_parts(d, names=("checkpoint.json",), prefixes=("ckpt-",))
    assert not d.exists()
    remove_parts(d)                      # a missing directory is fine


def test_write_series_keeps_a_users_file_in_frames(tmp_path):
    import meshio
    import numpy as np

    from peclet.packing.experiments.series import write_series

    (tmp_path / "frames").mkdir()
    (tmp_path / "frames" / "IMG_0001.jpg").write_bytes(b"photo")
    (tmp_path / "frames" / "frame_0007.vtu").write_text("an earlier run's frame")
    mesh = meshio.Mesh(np.zeros((1, 3)), [("vertex", np.array([[0]]))])
    write_series(str(tmp_path), "s", [dict(t=0.0), dict(t=1.0)], lambda f: mesh)
    assert sorted(os.listdir(tmp_path / "frames")) == ["IMG_0001.jpg", "frame_0000.vtu",
                                                       "frame_0001.vtu"]
    assert (tmp_path / "frames" / "IMG_0001.jpg").read_bytes() == b"photo"


def test_write_stl_files_refuses_to_replace_a_directory_holding_other_files(tmp_path):
    from peclet.packing.bed import api
    from peclet.packing.output import export

    d = tmp_path / "bed_stl"
    d.mkdir()
    (d / "element_0.stl").write_bytes(b"old export")
    (d / "drawing.dxf").write_bytes(b"mine")
    with pytest.raises(PecletArgumentError, match="drawing.dxf in it is not such a file"):
        export.write_stl_files(d, api.pack("sphere", "column:2.5", count=3, seed=1,
                                           progress=False).pack)
    assert sorted(os.listdir(d)) == ["drawing.dxf", "element_0.stl"]


# ------------------------------------------------------------------ the command line, as users do
def _cli(capsys, argv):
    rc = main(argv)
    return rc, capsys.readouterr().err


@pytest.mark.parametrize("command,names", [
    (["stir", "--grain-radius", "1.0", "--revolutions", "0.25", "--settle", "0.5"],
     "peclet.packing.experiments.stir"),
    (["drum", "--froude", "0.01"], "peclet.packing.experiments.drum"),
    (["pack", "--element", "sphere", "--container", "column:2.5", "--count", "6",
      "--protocol", "rain"], "peclet.cli.pack"),
])
def test_a_users_checkpoint_and_photo_survive_overwrite_byte_for_byte(tmp_path, capsys,
                                                                      command, names):
    """The issue's case: ``--out`` holds an earlier run's outputs and, inside the run's own
    sub-folders, the user's ``checkpoint/model.ckpt`` and ``frames/IMG_0001.jpg``. With
    ``--overwrite`` the run is refused naming the file; nothing at all is removed."""
    import importlib

    outputs = importlib.import_module(names).OUTPUTS
    out = tmp_path / "out"
    with recording(out, outputs):
        (out / "results.json").write_text('{"earlier": true}')
    _put_user_files(out)
    before = _tree(out)
    rc, err = _cli(capsys, command + ["--out", str(out), "--overwrite", "--quiet"])
    assert rc == 2
    assert "--out" in err and "is not a file an earlier peclet run wrote" in err, err
    assert ("model.ckpt" in err) or ("IMG_0001.jpg" in err)
    assert _tree(out) == before


def test_a_real_rerun_with_overwrite_replaces_only_its_own_files(tmp_path, capsys):
    fast = ["pack", "--element", "sphere", "--container", "column:2.5", "--count", "6",
            "--protocol", "rain", "--mu", "0.3", "--quiet", "--samples", "4000", "--drop", "3",
            "--no-figures"]
    out = tmp_path / "out"
    assert _cli(capsys, fast + ["--out", str(out)])[0] == 0
    first = json.loads((out / MANIFEST).read_text())["files"]
    assert set(first) == set(os.listdir(out)) - {MANIFEST}     # every output is listed
    (out / "notes.txt").write_text("mine")
    (out / "IMG_0001.jpg").write_bytes(b"photo")
    assert _cli(capsys, fast + ["--out", str(out), "--overwrite", "--seed", "6"])[0] == 0
    assert (out / "notes.txt").read_text() == "mine"
    assert (out / "IMG_0001.jpg").read_bytes() == b"photo"
    second = json.loads((out / MANIFEST).read_text())["files"]
    assert set(second) == set(os.listdir(out)) - {MANIFEST, "notes.txt", "IMG_0001.jpg"}
    assert second["results.json"]["sha256"] != first["results.json"]["sha256"]


def test_resume_leaves_a_users_file_in_the_checkpoint_directory(tmp_path, capsys):
    from peclet.packing import Material, RainProtocol, pack

    out = tmp_path / "run"
    part = pack("sphere", "column:2.5", count=6, protocol=RainProtocol(drop=3.0),
                material=Material(0.15, 0.0, 0.3), seed=5, progress=False, max_steps=150,
                checkpoint_dir=out / "checkpoint", checkpoint_every=60)
    assert not part.complete
    (out / "checkpoint" / "model.ckpt").write_bytes(b"weights")
    rc, err = _cli(capsys, ["pack", "--resume", str(out), "--no-figures", "--quiet"])
    assert rc == 0, err
    assert os.listdir(out / "checkpoint") == ["model.ckpt"]
    assert (out / "checkpoint" / "model.ckpt").read_bytes() == b"weights"
