"""The plugin's options and what they promise: the report file, profiles that mean the same
everywhere, comparison with a previous report, declared waivers, the backend hook, xdist, and
the Hypothesis internals the search relies on. Downstream projects are throwaway directories
run in a subprocess (the plugin loads from its installed entry point)."""
import json
import os
import subprocess
import sys
import textwrap

import pytest

from peclet_verify import report as R
from peclet_verify import search as S
from peclet_verify.profiles import PROFILES, SHARDS

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

FIXED = textwrap.dedent('''
    import os
    import pytest
    from peclet_verify import search as S

    @pytest.mark.peclet_certify
    def test_fixed_figure(peclet_certificate):
        # a certificate whose figure is set by the environment (planted regressions)
        figure = float(os.environ.get("FIGURE", "0.5"))
        ok = os.environ.get("FAIL") is None
        peclet_certificate(S.PropertyResult("planted figure", ok, 1, figure,
                                            "rel error (volume)", "" if ok else "planted",
                                            "passed" if ok else "failed"))
''')


def _pytest(cwd, *args, env=None, timeout=600):
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *args],
                          cwd=cwd, capture_output=True, text=True, timeout=timeout,
                          env=dict(os.environ, **(env or {})))


def _usage_line(proc):
    """The one line pytest prints for a UsageError (exit code 4)."""
    assert proc.returncode == 4, proc.stdout + proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.startswith("ERROR:")]
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    return lines[0]


# ---------------------------------------------------------------------- the report file
def test_report_path_refusals_name_the_option_and_touch_nothing(tmp_path):
    (tmp_path / "test_fixed.py").write_text(FIXED)
    precious = tmp_path / "notes.txt"
    precious.write_text("not a report")
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    cases = {"a directory": tmp_path, "under a file": precious / "r.json",
             "a non-report file": precious, "read-only location": ro / "r.json"}
    for what, path in cases.items():
        line = _usage_line(_pytest(tmp_path, "--peclet-certify", f"--peclet-report={path}"))
        assert "--peclet-report" in line, (what, line)
    assert precious.read_text() == "not a report"


def test_options_without_certify_are_a_usage_error(tmp_path):
    (tmp_path / "test_fixed.py").write_text(FIXED)
    line = _usage_line(_pytest(tmp_path, "--peclet-profile", "ci"))
    assert "--peclet-profile has no effect without --peclet-certify" in line


# ---------------------------------------------------------------------- profiles
PROFILE_PROBE = textwrap.dedent('''
    import json, sys
    from hypothesis import settings
    from hypothesis.database import DirectoryBasedExampleDatabase
    # a project's own profile, loaded before ours are made: it must not leak into them
    settings.register_profile("mine", max_examples=7, derandomize=True, database=None)
    settings.load_profile("mine")
    from peclet_verify.profiles import make_settings
    out = {}
    for name in ("dev", "ci", "nightly", "smoke"):
        s = make_settings(name, sys.argv[1])
        out[name] = [s.derandomize, type(s.database).__name__, s.deadline, s.print_blob,
                     s.max_examples]
    out["default_after"] = settings.default.max_examples
    print(json.dumps(out))
''')


@pytest.mark.parametrize("ci", [True, False])
def test_profiles_mean_the_same_with_and_without_ci(tmp_path, ci):
    env = {k: v for k, v in os.environ.items() if k != "CI"}
    if ci:
        env["CI"] = "true"
    proc = subprocess.run([sys.executable, "-c", PROFILE_PROBE, str(tmp_path)], env=env,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["nightly"] == [False, "DirectoryBasedExampleDatabase", None, True, 2000]
    assert out["ci"] == [True, "NoneType", None, True, 40]
    assert out["dev"][:3] == [False, "DirectoryBasedExampleDatabase", None]
    assert out["smoke"][:3] == [True, "NoneType", None]
    assert out["default_after"] == 7  # the project's loaded profile is untouched


OWN_HYPOTHESIS = textwrap.dedent('''
    import pytest
    from hypothesis import given, settings, strategies as st
    from peclet_verify import search as S

    settings.register_profile("downstream", max_examples=7)
    settings.load_profile("downstream")
    RUNS = []

    @given(st.integers())
    def test_own_property(x):
        RUNS.append(x)

    def test_own_settings_kept():
        assert len(RUNS) == 7 and settings.default.max_examples == 7
        assert settings.get_current_profile_name() == "downstream"

    @pytest.mark.peclet_certify
    def test_cert(peclet_certificate):
        s = S.active_settings()
        assert (s.max_examples, s.derandomize, s.database) == (40, True, None)
        peclet_certificate(S.PropertyResult("c", True))
''')


@pytest.mark.heavy
def test_certification_never_changes_a_projects_own_hypothesis_settings(tmp_path):
    (tmp_path / "test_own.py").write_text(OWN_HYPOTHESIS)
    proc = _pytest(tmp_path, "--peclet-certify", "--peclet-profile", "ci", "-p", "no:randomly")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "3 passed" in proc.stdout


def test_plugin_choices_are_the_profiles():
    from peclet_verify import plugin
    assert tuple(plugin.PROFILES) == tuple(PROFILES)


def test_plugin_module_imports_nothing_heavy():
    code = ("import sys, peclet_verify.plugin; "
            "print(sorted(m for m in ('numpy', 'numba', 'hypothesis', 'peclet', 'scipy') "
            "if m in sys.modules))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0 and proc.stdout.strip() == "[]", proc.stdout + proc.stderr


# ---------------------------------------------------------------------- Hypothesis internals
def test_the_patched_hypothesis_internals_exist_and_the_patch_takes_effect(tmp_path):
    """search relies on two Hypothesis internals; this fails loudly when either goes away:
    providers._get_local_constants / CONSTANTS_CACHE / Constants (the constant pool that
    _fixed_constant_pool empties) and reflection.function_digest reading
    _hypothesis_internal_add_digest (each certificate's own database key)."""
    from hypothesis.internal import reflection
    from hypothesis.internal.conjecture import providers
    mod = tmp_path / "h3_engine_constants.py"
    mod.write_text("CONSTANTS = (0.123456789, 0.3337, 40939)\n")
    sys.path.insert(0, str(tmp_path))
    try:
        import h3_engine_constants  # noqa: F401  (a local module: its literals join the pool)
        original = providers._get_local_constants
        assert isinstance(providers.CONSTANTS_CACHE.cache, dict)
        assert 0.123456789 in providers._get_local_constants().floats
        with S.fixed_constant_pool():
            assert providers._get_local_constants is not original
            inside = providers._get_local_constants()
            assert isinstance(inside, providers.Constants)
            assert not (inside.floats or inside.integers or inside.strings or inside.bytes)
        assert providers._get_local_constants is original
    finally:
        sys.path.remove(str(tmp_path))
        sys.modules.pop("h3_engine_constants", None)

    def f():
        pass
    before = reflection.function_digest(f)
    f._hypothesis_internal_add_digest = b"a certificate"
    assert reflection.function_digest(f) != before


# ---------------------------------------------------------------------- compare
def _report_of(figure, status="passed"):
    return {"profile": "peclet-dev", "backend": "reference", "certificates": [
        {"name": "planted figure", "status": status, "worst": figure,
         "worst_name": "rel error (volume)", "worse": "max", "examples": 1}]}


def test_compare_fails_a_planted_regression_with_a_readable_table(tmp_path):
    """The nightly way: last night's report is the baseline and is replaced (atomically) by
    tonight's; a figure 100x worse fails the run with a side-by-side table."""
    (tmp_path / "test_fixed.py").write_text(FIXED)
    base = tmp_path / "base.json"
    R.write_report(base, _report_of(0.005))
    worse = _pytest(tmp_path, "--peclet-certify", f"--peclet-compare={base}",
                    f"--peclet-report={base}", env={"FIGURE": "0.5"})
    assert worse.returncode == 1, worse.stdout + worse.stderr
    table = worse.stdout.split("peclet compare with", 1)[1].splitlines()
    row = next(ln for ln in table if ln.startswith("planted figure"))
    assert row.split()[2:] == ["passed", "0.005", "passed", "0.5", "x10", "(floor",
                               "1e-12)", "REGRESSED", "(figure", "x100)"], row
    assert "1 regression(s)" in worse.stdout
    now = R.load_report(base)
    assert now["compare"]["regressions"] == ["planted figure"]
    assert now["certificates"][0]["worst"] == 0.5 and now["format"] == R.FORMAT
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".peclet-tmp")] == []


def test_compare_tolerances_and_status_changes():
    now = _report_of(0.04)["certificates"]
    assert R.compare(_report_of(0.005), now)[0] == []  # x8: within x10
    assert R.compare(_report_of(0.003), now)[0] == ["planted figure"]
    failed = [dict(now[0], status="failed")]
    regressions, lines = R.compare(_report_of(0.04), failed)
    assert regressions == ["planted figure"] and "REGRESSED (passed, now fails)" in lines[-1]
    waived = [dict(failed[0], waived="known")]
    assert R.compare(_report_of(0.04), waived)[0] == []
    slack = [{"name": "e", "status": "passed", "worst": -1e-10, "worst_name": "min slack",
              "worse": "min"}]
    assert R.compare({"certificates": [dict(slack[0], worst=0.0)]}, slack)[0] == ["e"]
    assert R.compare({"certificates": [dict(slack[0], worst=-2e-11)]}, slack)[0] == []


def test_compare_refuses_a_missing_or_malformed_baseline(tmp_path):
    (tmp_path / "test_fixed.py").write_text(FIXED)
    bad = tmp_path / "bad.json"
    bad.write_text('{"certificates": "none"}')
    for path in (tmp_path / "missing.json", bad):
        line = _usage_line(_pytest(tmp_path, "--peclet-certify", f"--peclet-compare={path}"))
        assert "--peclet-compare" in line and str(path) in line, line


def test_every_figure_has_a_documented_tolerance():
    for figure in ("rel error (volume, tol=1e-05)", "max |phi_a - phi_b|", "min slack",
                   "sign disagreement rate", "distinct state hashes", "differing contact sets"):
        assert any(figure.startswith(k) for k in R.TOLERANCES), figure


# ---------------------------------------------------------------------- hook and waivers
HOOKED = textwrap.dedent('''
    from peclet_verify.geometry.suite import *  # noqa: F401,F403
''')
HOOK_CONFTEST = textwrap.dedent('''
    def pytest_peclet_make_backend(config):
        from peclet_verify.planted import TreeWalkBackend
        return TreeWalkBackend(flip="torus")
''')


@pytest.mark.heavy
def test_downstream_engine_by_hook_is_certified_and_its_deviation_waived(tmp_path):
    """One line in a test module and a hook in conftest certify a downstream engine (the
    tree walk with torus signs flipped: it fails, test_verify_plugin shows the same engine
    failing without a waiver); an xfails file waives that known deviation, the report lists
    the waiver, and the run passes."""
    (tmp_path / "test_my_engine.py").write_text(HOOKED)
    (tmp_path / "conftest.py").write_text(HOOK_CONFTEST)
    (tmp_path / "xfails.toml").write_text(
        '["sign agreement (evaluation paths)"]\nreason = "torus signs flipped, issue 1"\n'
        'kinds = ["torus"]\n')
    rep = tmp_path / "r.json"
    proc = _pytest(tmp_path, "--peclet-certify", "--peclet-profile", "ci", "-k",
                   "sign_agreement_all_paths", "--peclet-xfails=xfails.toml",
                   f"--peclet-report={rep}")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "1 xfailed" in proc.stdout and "WAIVED" in proc.stdout
    assert "tree-walk(sign flip: torus)" in proc.stdout  # the hook's engine was certified
    data = json.loads(rep.read_text())
    assert data["backend"] == "pytest_peclet_make_backend hook"
    assert data["waivers"] == [{"certificate": "sign agreement (evaluation paths)",
                                "reason": "torus signs flipped, issue 1", "kinds": ["torus"],
                                "applied": 1}]
    assert data["certificates"][0]["waived"] == "torus signs flipped, issue 1"


def test_xfails_naming_an_unknown_certificate_is_refused(tmp_path):
    (tmp_path / "test_fixed.py").write_text(FIXED)
    (tmp_path / "x.json").write_text('{"no such certificate": "because"}')
    line = _usage_line(_pytest(tmp_path, "--peclet-certify", "--peclet-xfails=x.json"))
    assert "x.json" in line and "unknown certificate 'no such certificate'" in line


# ---------------------------------------------------------------------- xdist
@pytest.mark.heavy
def test_xdist_report_holds_every_certificate(tmp_path):
    """`pytest --peclet-certify -n 2 properties --peclet-report r.json`: the controller's
    report has every certificate of this repository (the quadrature one in SHARDS shards),
    written once. Run with the planted NaN engine as the backend (issue 18: it used to pass
    Equation 1 and sign agreement): each certificate that asks it fails, showing the answer,
    and the others pass. Test-only profile ``smoke`` (2 examples) instead of ci, for time."""
    rep = tmp_path / "r.json"
    proc = _pytest(ROOT, "--peclet-certify", "-n", "2", "properties", "--peclet-profile",
                   "smoke", f"--peclet-report={rep}",
                   "--peclet-backend", "peclet_verify.planted:nan_backend")
    assert proc.returncode == 1, proc.stdout[-3000:] + proc.stderr[-3000:]
    certs = {c["name"]: c for c in json.loads(rep.read_text())["certificates"]}
    expected = set(R.SUITE_CERTIFICATES + R.REPO_CERTIFICATES) - {"quadrature convergence"}
    expected |= {f"quadrature convergence [shard {k}/{SHARDS}]" for k in range(1, SHARDS + 1)}
    # the DEM, mass-property and impact families (their backends: peclet's own here)
    expected |= set(R.DEM_CERTIFICATES + R.MASS_CERTIFICATES + R.IMPACT_CERTIFICATES)
    assert sorted(certs) == sorted(expected) and len(certs) == 31
    for name, c in certs.items():
        if name in R.SUITE_CERTIFICATES:
            assert c["status"] == "failed", name
            assert "bad-answer(nan).evaluate returned" in c["counterexample"], name
            assert "non-finite value(s)" in c["counterexample"], name
        else:
            assert c["status"] == "passed", (name, c["counterexample"])
    summary = proc.stdout.split("peclet certificates", 1)[1]
    assert summary.count("FAILED") >= 5 and summary.count("PASSED") == 26
    assert "5 failed, 26 passed" in proc.stdout


# ---------------------------------------------------------------------- replay
SAVED = textwrap.dedent('''
    import pytest
    from hypothesis import strategies as st
    from peclet_verify import search as S

    @pytest.mark.peclet_certify
    def test_big_numbers(peclet_certificate):
        peclet_certificate(S.search(
            lambda x: S.PropertyResult("small", x < 1000, 1, float(x), "x",
                                       f"x = {x}", "passed" if x < 1000 else "failed"),
            st.integers(0, 10 ** 6), name="small numbers"))
''')


@pytest.mark.heavy
def test_replay_reruns_the_saved_failure_from_a_read_only_database(tmp_path):
    """A randomised run (dev profile: database under .hypothesis/examples) saves its failing
    example; --peclet-replay of a read-only copy re-runs it (nothing generated, nothing
    written) and fails with the same shrunk input; an empty database replays nothing."""
    import shutil
    (tmp_path / "test_saved.py").write_text(SAVED)
    first = _pytest(tmp_path, "--peclet-certify")
    assert first.returncode == 1 and "x = 1000" in first.stdout, first.stdout
    copy = tmp_path / "nightly-db"
    shutil.copytree(tmp_path / ".hypothesis" / "examples", copy)
    shutil.rmtree(tmp_path / ".hypothesis")
    for p in [copy, *copy.rglob("*")]:
        p.chmod(0o555 if p.is_dir() else 0o444)
    rep = tmp_path / "r.json"
    again = _pytest(tmp_path, "--peclet-certify", f"--peclet-replay={copy}",
                    f"--peclet-report={rep}")
    assert again.returncode == 1 and "x = 1000" in again.stdout, again.stdout
    data = R.load_report(rep)
    assert data["profile"] == "peclet-dev (replay)"
    assert data["certificates"][0]["examples"] == 1  # the saved example, no generation
    assert not (tmp_path / ".hypothesis").exists()
    line = _usage_line(_pytest(tmp_path, "--peclet-certify", "--peclet-replay=missing-db"))
    assert "--peclet-replay missing-db: not a directory" in line


def test_every_family_record_names_what_the_plugin_and_a_downstream_project_use():
    """Each Family of the registry: its option is the plugin's, its hook is specified, its
    fixture is the plugin's, its backend module offers load/check/default and its suite
    module exports certificate tests only (what ``from ... import *`` gives)."""
    import importlib

    from peclet_verify import hooks, plugin, registry
    options = {flag for flag, _, _ in plugin._OPTIONS}
    assert registry.FAMILY_NAMES == ("geometry", "mass", "dem", "mechanics", "impact")
    for fam in registry.FAMILIES:
        assert fam.package == f"peclet_verify.{fam.name}"
        assert fam.option in options and callable(getattr(hooks, fam.hook))
        assert getattr(plugin, fam.fixture)  # the session fixture, registered with the plugin
        backend = importlib.import_module(fam.backend)
        for name in ("load_backend", "check_backend", "default_backend"):
            assert callable(getattr(backend, name)), (fam.name, name)
        suite = importlib.import_module(fam.suite)
        assert suite.__all__ and all(
            n.startswith("test_") and getattr(suite, n).pytestmark[0].name == "peclet_certify"
            for n in suite.__all__), fam.suite
        assert set(registry.titles(family=fam.name)), fam.name
