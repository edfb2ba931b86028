"""scripts/nightly, run the way the workflow runs it, at a tiny size.

The script works in the repository it lives in (it ``cd``s to its parent's parent and keeps the
example database in ``.hypothesis/`` there), so each test runs a byte-identical copy of it in a
sandbox repository (the script, ``pyproject.toml`` for the pytest configuration, and a copy of
``properties/``): its database, baseline and Hypothesis files stay in the sandbox, and what it
leaves there was made by this run. ``PECLET_EXTRA -k`` cuts the night down to one certificate:

- the backend distance certificate for the mesh engine of ``examples/downstream/mesh_engine``
  (``--peclet-backend``, its xfails file as ``PECLET_XFAILS``) under ``smoke``: one
  derandomised example whose figure (the mesh's distance error, ~1e-3) is the same in two runs
  and far above the comparison's floor, unlike the reference engine's round-off figures, and
  cheaper than a quadrature example;
- the sign certificate for a planted always-zero engine under ``dev``, a profile with a
  database, so that the failure is saved and copied out.
"""
import json
import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET

import pytest

from peclet_verify.report import load_report

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MESH = os.path.join(ROOT, "examples", "downstream", "mesh_engine")
CERT = "test_distance_agreement_backend"


@pytest.fixture
def sandbox(tmp_path):
    repo = tmp_path / "repo"
    (repo / "scripts").mkdir(parents=True)
    shutil.copy2(os.path.join(ROOT, "scripts", "nightly"), repo / "scripts" / "nightly")
    shutil.copy2(os.path.join(ROOT, "pyproject.toml"), repo / "pyproject.toml")
    shutil.copytree(os.path.join(ROOT, "properties"), repo / "properties",
                    ignore=shutil.ignore_patterns("__pycache__", ".hypothesis"))
    return repo


def nightly(repo, out, profile, extra, **more_env):
    env = {k: v for k, v in os.environ.items() if not k.startswith("PECLET_")}
    env.update(PECLET_PROFILE=profile, PECLET_WORKERS="0",
               PECLET_EXTRA=f"{extra} -p no:cacheprovider",
               PATH=os.path.dirname(sys.executable) + os.pathsep + env.get("PATH", ""),
               **more_env)
    return subprocess.run(["bash", str(repo / "scripts" / "nightly"), str(out)], cwd=repo,
                          env=env, capture_output=True, text=True, timeout=600)


@pytest.mark.heavy
def test_night_writes_report_junit_baseline_and_a_planted_regression_fails(sandbox, tmp_path):
    out = tmp_path / "night"
    mesh = dict(PYTHONPATH=MESH + os.pathsep + os.environ.get("PYTHONPATH", ""),
                PECLET_XFAILS=os.path.join(MESH, "xfails.toml"))
    args = f"--peclet-backend meshsdf:MeshEngine -k {CERT}"
    first = nightly(sandbox, out, "smoke", args, **mesh)
    assert first.returncode == 0, first.stdout[-3000:] + first.stderr[-2000:]
    report = load_report(out / "report.json")
    (cert,) = report["certificates"]
    assert cert["waived"] and cert["worst_name"] == "max |phi_a - phi_b|"
    (waiver,) = [w for w in report["waivers"] if w["certificate"] == cert["name"]]
    assert waiver["applied"] == 1 and waiver["reason"] == cert["waived"]
    assert 1e-9 < cert["worst"] < 0.1  # the mesh error: a figure a regression can scale
    suite = ET.parse(out / "junit.xml").getroot()
    cases = suite.findall(".//testcase")
    assert [c.get("name") for c in cases] == [CERT]
    assert not any(c.find("failure") is not None or c.find("error") is not None for c in cases)
    # a passing night is the next night's baseline
    assert (out / "baseline.json").read_bytes() == (out / "report.json").read_bytes()

    # planted regression: the baseline claims a figure 100x better than tonight's
    planted = json.loads((out / "report.json").read_text())
    planted["certificates"][0]["worst"] = cert["worst"] / 100.0
    (out / "baseline.json").write_text(json.dumps(planted))
    baseline_before = (out / "baseline.json").read_bytes()
    second = nightly(sandbox, out, "smoke", args, **mesh)
    text = second.stdout
    assert second.returncode == 1, text[-3000:]
    lines = text.splitlines()
    head = next(i for i, line in enumerate(lines) if "peclet compare with" in line)
    assert "1 regression(s)" in lines[head]
    table = lines[head + 1:head + 4]
    assert table[0].split()[:6] == ["certificate", "before", "figure", "now", "figure",
                                    "allowed"]
    row = table[2]
    assert row.startswith(cert["name"][:40]) and "REGRESSED (figure x100)" in row
    # side by side: the planted figure and tonight's, both as printed with 3 digits
    assert f"{cert['worst'] / 100:.3g}" in row and f"{cert['worst']:.3g}" in row
    again = load_report(out / "report.json")
    assert again["compare"]["regressions"] == [cert["name"]]
    # a failing night leaves the baseline alone, so the regression keeps failing
    assert (out / "baseline.json").read_bytes() == baseline_before


def test_failing_night_saves_its_example_database(sandbox, tmp_path):
    out = tmp_path / "night"
    run = nightly(sandbox, out, "dev", "--peclet-backend peclet_verify.planted:zero_backend "
                                       "-k test_sign_agreement_all_paths")
    assert run.returncode == 1, run.stdout[-3000:] + run.stderr[-2000:]
    (cert,) = load_report(out / "report.json")["certificates"]
    assert cert["status"] == "failed" and "bad-answer(zero)" in cert["counterexample"]
    saved = [f for _, _, files in os.walk(out / "hypothesis" / "examples") for f in files]
    assert saved, "the failing example was not copied out of the database"
    assert not (out / "baseline.json").exists()  # a failing night is nobody's baseline
    failures = ET.parse(out / "junit.xml").getroot().findall(".//testcase/failure")
    assert len(failures) == 1


def test_downstream_nightly_lists_every_project_with_its_venv():
    """scripts/nightly-downstream --list: one run per foreign engine and law, each with its
    side venv, its environment and its xfails file, nothing made or run."""
    proc = subprocess.run([os.path.join(ROOT, "scripts", "nightly-downstream"), "--list",
                           "out"], capture_output=True, text=True, timeout=60,
                          env=dict(os.environ, PECLET_VENVS="/nowhere"))
    assert proc.returncode == 0, proc.stderr
    lines = {ln.split(":")[0]: ln for ln in proc.stdout.splitlines() if ":" in ln}
    for name, var in (("upstream_dem", "PECLET_UPSTREAM_VENV=/nowhere/upstream"),
                      ("mujoco_dem", "PECLET_MUJOCO_VENV=/nowhere/mujoco"),
                      ("lammps_hertz", "PECLET_LAMMPS_VENV=/nowhere/lammps"),
                      ("lammps_hooke", "PECLET_LAMMPS_LAW=hooke")):
        assert var in lines[name], lines
        assert "--peclet-xfails" in lines[name] and "--peclet-profile ci" in lines[name]
    assert not os.path.exists("/nowhere")
