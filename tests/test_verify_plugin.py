"""The pytest plugin, exercised in throwaway downstream projects (subprocess pytest runs; the
plugin loads from its installed entry point, nothing new is installed)."""
import json
import subprocess
import sys
import textwrap

import pytest

DOWNSTREAM = textwrap.dedent('''
    import pytest
    from peclet_verify import search as S
    from peclet_verify.geometry import properties as GP
    from peclet_verify.geometry import strategies as GS

    @pytest.mark.peclet_certify
    def test_my_engine_signs(peclet_certificate, peclet_backend):
        peclet_certificate(S.search(lambda r: GP.sign_agreement(r, backend=peclet_backend, n=32),
                                    GS.trees(max_leaves=3), name="downstream sign agreement",
                                    # the profile's settings (ci: seeded by the name, a torus
                                    # by example 5), with more examples for margin
                                    settings=S.profile_settings(max_examples=30)))

    def test_ordinary():
        assert GS.TreeRecipe is not None
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


LONG = textwrap.dedent('''
    import pytest
    from hypothesis import settings, strategies as st
    from peclet_verify import search as S
    from peclet_verify.geometry import properties as GP
    from peclet_verify.geometry import strategies as GS

    @pytest.mark.peclet_certify
    def test_long(peclet_certificate):
        peclet_certificate(S.search(lambda x: S.PropertyResult("long", True, 1, float(x), "x"),
                                    st.integers(0, 10 ** 9), name="a long one",
                                    settings=settings(max_examples=100, deadline=None)))
''')


@pytest.mark.heavy
def test_long_certificate_reports_progress_past_capture(tmp_path):
    """A search of >= 100 examples prints a line at every tenth, through pytest's capture."""
    (tmp_path / "test_long.py").write_text(LONG)
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           "--peclet-certify"], cwd=tmp_path, capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    lines = [ln.strip() for ln in proc.stdout.splitlines() if ln.strip().startswith("a long one:")]
    assert [ln.split(" examples")[0] for ln in lines] == [
        f"a long one: {k} / 100" for k in range(10, 101, 10)], proc.stdout


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


# -------------------------------------------------------------- run-order independence (ci)
CERT_A = textwrap.dedent('''
    import pytest
    from peclet_verify import search as S
    from peclet_verify.geometry import properties as GP
    from peclet_verify.geometry import strategies as GS

    @pytest.mark.peclet_certify
    def test_a_equation1(peclet_certificate, peclet_backend):
        # no settings: the loaded profile (ci) decides examples and seed
        peclet_certificate(S.search(lambda r: GP.equation1(r, peclet_backend, n=32),
                                    GS.trees(certified_only=True, max_leaves=3),
                                    name="a: equation1"))
''')
CERT_B = textwrap.dedent('''
    import pytest
    from peclet_verify import search as S
    from peclet_verify.geometry import properties as GP
    from peclet_verify.geometry import strategies as GS

    @pytest.mark.peclet_certify
    def test_b_sign(peclet_certificate):
        # imports made while running (as the DEM certificates import peclet.dem) bring new
        # modules, and their source constants, into the process
        import peclet.dem  # noqa: F401
        import engine_b
        peclet_certificate(S.search(lambda r: GP.sign_agreement(r, n=16),
                                    GS.trees(max_leaves=2), name="b: sign " + engine_b.NAME))
''')
ENGINE_B = "NAME = 'b'\nCONSTANTS = (0.123456789, 0.3337, 0.77731, 1.2345e-3, 17, 4093)\n"


def _certify_files(tmp_path, tag, files):
    rep = tmp_path / f"report-{tag}.json"
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           "--peclet-certify", "--peclet-profile", "ci",
                           f"--peclet-report={rep}", *files], cwd=tmp_path,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return {c["name"]: c for c in json.loads(rep.read_text())["certificates"]}


@pytest.mark.heavy
def test_ci_certificate_is_run_order_independent(tmp_path):
    """The ci profile draws the same examples for a certificate whether its file runs alone,
    before or after another certificate file (which imports modules while it runs)."""
    (tmp_path / "test_cert_a.py").write_text(CERT_A)
    (tmp_path / "test_cert_b.py").write_text(CERT_B)
    (tmp_path / "engine_b.py").write_text(ENGINE_B)
    alone = _certify_files(tmp_path, "alone", ["test_cert_a.py"])["a: equation1"]
    a_first = _certify_files(tmp_path, "ab", ["test_cert_a.py", "test_cert_b.py"])
    b_first = _certify_files(tmp_path, "ba", ["test_cert_b.py", "test_cert_a.py"])
    assert alone["examples"] == 40 and alone["details"]["applicable"] == 40
    for run in (a_first, b_first):
        a = run["a: equation1"]
        assert (a["examples"], a["worst"], a["details"]) == \
            (alone["examples"], alone["worst"], alone["details"])
    assert a_first["b: sign b"] == b_first["b: sign b"]
