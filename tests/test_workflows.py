"""The CI and nightly workflows: valid against GitHub's workflow schema, and wired to the one
script (scripts/nightly) and the README's test command (.ci/run) that also run on a laptop."""
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
WORKFLOWS = sorted((ROOT / ".github" / "workflows").glob("*.yml"))


def test_both_workflows_exist():
    assert {p.name for p in WORKFLOWS} >= {"ci.yml", "nightly.yml"}


@pytest.mark.parametrize("path", WORKFLOWS, ids=lambda p: p.name)
def test_workflow_validates_against_the_github_schema(path):
    exe = shutil.which("check-jsonschema")
    cmd = ([exe] if exe else [sys.executable, "-m", "check_jsonschema"])
    proc = subprocess.run(cmd + ["--builtin-schema", "vendor.github-workflows", str(path)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_schema_check_rejects_a_broken_workflow(tmp_path):
    """The validator is live: a workflow with a job missing runs-on fails it."""
    bad = tmp_path / "bad.yml"
    bad.write_text("on: push\njobs:\n  x:\n    steps:\n      - run: echo\n")
    exe = shutil.which("check-jsonschema")
    cmd = ([exe] if exe else [sys.executable, "-m", "check_jsonschema"])
    proc = subprocess.run(cmd + ["--builtin-schema", "vendor.github-workflows", str(bad)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode != 0


def test_workflows_call_the_scripts_a_laptop_runs():
    ci = (ROOT / ".github/workflows/ci.yml").read_text()
    nightly = (ROOT / ".github/workflows/nightly.yml").read_text()
    assert "bash .ci/run" in ci and "--peclet-profile ci" in ci and "--peclet-replay" in ci
    assert "scripts/nightly" in nightly and "schedule:" in nightly
    assert "workflow_dispatch" in nightly and "nightly-failure" in nightly


def test_nightly_script_parses():
    proc = subprocess.run(["bash", "-n", str(ROOT / "scripts" / "nightly")],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
