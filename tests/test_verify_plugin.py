"""The pytest plugin, exercised in throwaway downstream projects (subprocess pytest runs; the
plugin loads from its installed entry point, nothing new is installed)."""
import json
import subprocess
import sys
import textwrap

DOWNSTREAM = textwrap.dedent('''
    import pytest
    from hypothesis import settings
    from peclet_verify import properties as P
    from peclet_verify import strategies as pst

    @pytest.mark.peclet_certify
    def test_my_engine_signs(peclet_certificate, peclet_backend):
        peclet_certificate(P.search(lambda r: P.sign_agreement(r, backend=peclet_backend, n=32),
                                    pst.trees(max_leaves=3), name="downstream sign agreement",
                                    settings=settings(max_examples=8, deadline=None)))

    def test_ordinary():
        assert pst.TreeRecipe is not None
''')


def _run(tmp_path, *args):
    (tmp_path / "test_downstream.py").write_text(DOWNSTREAM)
    (tmp_path / "pytest.ini").write_text("[pytest]\naddopts = --strict-markers -p no:cacheprovider\n")
    return subprocess.run([sys.executable, "-m", "pytest", "-rs", *args], cwd=tmp_path,
                          capture_output=True, text=True, timeout=600)


def test_downstream_certify_passes_and_reports(tmp_path):
    rep = tmp_path / "out" / "report.json"
    proc = _run(tmp_path, "--peclet-certify", "--peclet-profile", "ci", f"--peclet-report={rep}")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "peclet certificates" in proc.stdout and "PASSED" in proc.stdout
    data = json.loads(rep.read_text())
    assert data["profile"] == "peclet-ci"
    assert [c["status"] for c in data["certificates"]] == ["passed"]
    assert data["certificates"][0]["examples"] >= 1


def test_downstream_without_flag_skips_with_reason(tmp_path):
    proc = _run(tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "1 passed, 1 skipped" in proc.stdout
    assert "run with --peclet-certify" in proc.stdout


def test_failing_certificate_exits_nonzero_with_snippet(tmp_path):
    proc = _run(tmp_path, "--peclet-certify", "--peclet-profile", "ci",
                "--peclet-backend", "peclet_verify.planted:sign_flip_torus_backend")
    out = proc.stdout
    assert proc.returncode == 1, out + proc.stderr
    assert "FAILED" in out and "b.add_leaf('torus'" in out
    assert "from peclet.core.geom import SceneBuilder" in out


def test_bad_backend_spec_is_a_usage_error(tmp_path):
    proc = _run(tmp_path, "--peclet-certify", "--peclet-backend", "nope")
    assert proc.returncode != 0
    assert "module:factory" in proc.stdout + proc.stderr


def test_this_repo_properties_skip_without_flag():
    import os
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    proc = subprocess.run([sys.executable, "-m", "pytest", "properties", "-q", "-rs",
                           "-p", "no:cacheprovider"], cwd=root, capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert " passed" not in proc.stdout and "skipped" in proc.stdout
    assert proc.stdout.count("run with --peclet-certify") >= 1
