"""pytest plugin (entry point ``pytest11``): peclet certification for any test suite.

Options (group "peclet"):
  --peclet-certify          run tests marked ``peclet_certify`` (skipped with a reason otherwise)
  --peclet-profile NAME     Hypothesis profile: dev (default), ci (derandomised), nightly
  --peclet-report PATH      write every certificate as JSON (atomically)
  --peclet-backend SPEC     "module:factory" engine to certify (default: the reference engine)

Fixtures: ``peclet_backend`` (the engine under certification, session scope) and
``peclet_certificate`` (call it with a :class:`~peclet_verify.properties.PropertyResult`: it
records the certificate for the summary table / report, skips an "unavailable" one and fails
the test, showing the shrunk counterexample, on a failed one).
"""
from __future__ import annotations

import json
import os
import sys
import tempfile

import pytest

PROFILES = ("dev", "ci", "nightly")
_RESULTS = pytest.StashKey[list]()


def pytest_addoption(parser):
    group = parser.getgroup("peclet", "peclet certification")
    group.addoption("--peclet-certify", action="store_true", default=False,
                    help="run the peclet certification properties (marker peclet_certify)")
    group.addoption("--peclet-profile", choices=PROFILES, default=None,
                    help="Hypothesis profile for certification: dev (default; few examples), "
                         "ci (derandomised), nightly (thousands of examples, example database)")
    group.addoption("--peclet-report", metavar="PATH", default=None,
                    help="write the certificates as JSON to PATH (atomic)")
    group.addoption("--peclet-backend", metavar="MODULE:FACTORY", default=None,
                    help="engine to certify: factory() returns an object with evaluate(...) "
                         "(default: the peclet reference engine)")


def register_profiles():
    """Register the dev / ci / nightly Hypothesis profiles (deadline off: JIT warm-up and
    subprocess engines make per-example timing meaningless)."""
    from hypothesis import HealthCheck, settings
    common = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                        HealthCheck.data_too_large])
    settings.register_profile("peclet-dev", max_examples=25, **common)
    settings.register_profile("peclet-ci", max_examples=40, derandomize=True, database=None,
                              print_blob=True, **common)
    settings.register_profile("peclet-nightly", max_examples=2000, **common)


def pytest_configure(config):
    config.addinivalue_line("markers", "peclet_certify: a certification property; runs only "
                                       "with --peclet-certify")
    config.stash[_RESULTS] = []
    profile = config.getoption("--peclet-profile")
    if config.getoption("--peclet-certify") or profile:
        from hypothesis import settings
        register_profiles()
        # loaded only when asked, so plain runs keep the project's own Hypothesis settings
        settings.load_profile("peclet-" + (profile or "dev"))
        from .properties import set_progress
        set_progress(lambda *a: _report_progress(config, *a))


def pytest_unconfigure(config):
    props = sys.modules.get("peclet_verify.properties")   # not imported: nothing to undo
    if props is not None:
        props.set_progress(None)


def _report_progress(config, name, examples, max_examples, seconds):
    """One line on the terminal, past output capture, for a long certificate (nightly)."""
    tr = config.pluginmanager.get_plugin("terminalreporter")
    capman = config.pluginmanager.get_plugin("capturemanager")
    if tr is None or capman is None:
        return
    with capman.global_and_fixture_disabled():
        left = seconds / examples * (max_examples - examples)
        tr.write_line(f"  {name}: {examples} / {max_examples} examples, "
                      f"{seconds / 60:.1f} min, about {left / 60:.0f} min left")


def pytest_collection_modifyitems(config, items):
    certify = config.getoption("--peclet-certify")
    skip = pytest.mark.skip(reason="certification property: run with --peclet-certify")
    for item in items:
        if "peclet_certify" in item.keywords:
            if certify:
                item.fixturenames.insert(0, "_peclet_jit_warm")
            else:
                item.add_marker(skip)


@pytest.fixture(scope="session")
def _peclet_jit_warm():
    """Compile (or load from cache) the evaluation kernels once per session."""
    from peclet.core.geom import SceneBuilder
    b = SceneBuilder()
    a = b.add_leaf("sphere", [1.0])
    c = b.add_difference(b.add_union(a, b.add_leaf("box", [0.5, 0.5, 0.5])), a)
    pts = [[0.1, 0.2, 0.3], [2.0, 0.0, 0.0]]
    b.eval_root(c, pts)
    b.eval_root_grad(c, pts)
    b.bake(c, [0, 0, 0], [0.1, 0.1, 0.1], [2, 2, 2])
    b.add_instance(c)
    b.eval_scene(pts, method="pruned")
    b.eval_scene(pts, method="brute")


@pytest.fixture(scope="session")
def peclet_backend(pytestconfig):
    """The engine under certification (``--peclet-backend``, default the reference)."""
    from .backends import load_backend
    spec = pytestconfig.getoption("--peclet-backend")
    try:
        backend = load_backend(spec or "reference")
    except ValueError as exc:
        raise pytest.UsageError(f"--peclet-backend: {exc}") from exc
    yield backend
    close = getattr(backend, "close", None)
    if callable(close):
        close()


@pytest.fixture
def peclet_certificate(request):
    """Record a PropertyResult; skip if unavailable, fail (with the counterexample) if failed."""
    def record(result):
        request.config.stash[_RESULTS].append((request.node.nodeid, result))
        if result.status == "unavailable":
            pytest.skip(f"{result.name} unavailable: {result.counterexample}")
        if not result.passed and result.status != "n/a":
            pytest.fail(f"certificate {result.name} FAILED after {result.examples} examples "
                        f"(worst {result.worst_name} = {result.worst!r})\n"
                        f"{result.counterexample}", pytrace=False)
        return result
    return record


def _rows(config):
    return config.stash.get(_RESULTS, [])


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    rows = _rows(config)
    if not rows:
        return
    tr = terminalreporter
    tr.write_sep("=", "peclet certificates")
    head = f"{'property':<44} {'examples':>8}  {'worst figure':<44} {'verdict':<11}"
    tr.write_line(head)
    tr.write_line("-" * len(head))
    for nodeid, r in rows:
        label = nodeid.split("::")[-1] if r.name in nodeid else f"{r.name} ({nodeid.split('::')[-1]})"
        fig = f"{r.worst_name} = {r.worst:.3g}" if r.worst_name else "-"
        tr.write_line(f"{label[:44]:<44} {r.examples:>8}  {fig[:44]:<44} {r.status.upper():<11}",
                      red=r.status == "failed", green=r.status == "passed",
                      yellow=r.status in ("unavailable", "n/a"))
    for nodeid, r in rows:
        if r.status == "failed":
            tr.write_sep("-", f"counterexample: {r.name}")
            tr.write_line(r.counterexample)


def write_json_atomic(path, data):
    """Write ``data`` as JSON to ``path`` through a temp file in the same directory."""
    path = os.path.abspath(path)
    d = os.path.dirname(path)
    os.makedirs(d, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=d, prefix=".peclet-report-", suffix=".json")
    try:
        with os.fdopen(fd, "w") as f:
            json.dump(data, f, indent=2)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def pytest_sessionfinish(session, exitstatus):
    config = session.config
    rows = _rows(config)
    if any(r.status == "failed" for _, r in rows) and session.exitstatus == 0:
        session.exitstatus = pytest.ExitCode.TESTS_FAILED
    path = config.getoption("--peclet-report")
    if path:
        from hypothesis import settings
        write_json_atomic(path, {
            "profile": settings.get_current_profile_name() if rows else None,
            "backend": config.getoption("--peclet-backend") or "reference",
            "certificates": [dict(test=n, **r.to_dict()) for n, r in rows]})
