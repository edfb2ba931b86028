"""pytest plugin (entry point ``pytest11``): peclet certification for any test suite.

Options (group "peclet"):
  --peclet-certify          run tests marked ``peclet_certify`` (skipped with a reason otherwise)
  --peclet-profile NAME     certification profile: dev (default), ci, nightly, smoke (see
                            :mod:`peclet_verify.profiles`; applies to certificates only)
  --peclet-report PATH      write every certificate as JSON (atomically; refuses a path that is
                            a directory, unwritable, or a file that is not a peclet report)
  --peclet-backend SPEC     "module:factory" engine to certify (default: the
                            ``pytest_peclet_make_backend`` hook, else the reference engine)
  --peclet-compare PATH     fail when a certificate regressed against that previous report
  --peclet-xfails PATH      declared known deviations (TOML or JSON: certificate -> reason)
  --peclet-replay DIR       re-run only the examples saved in that example database
                            (read-only; e.g. the last nightly's .hypothesis/examples); a
                            database with no examples is a usage error, and a replay whose
                            certificates re-ran no example fails the run (it certified
                            nothing)
  --peclet-dem-backend SPEC   "module:factory" DEM engine to certify (default: the
                            ``pytest_peclet_make_dem_backend`` hook, else peclet.dem)
  --peclet-mass-backend SPEC  "module:factory" mass-property engine to certify (default: the
                            ``pytest_peclet_make_mass_backend`` hook, else peclet's quadrature)
  --peclet-deadline SECONDS   the deadline of each call of an engine running in this process
                            (default 300: :data:`peclet_verify.processes.DEFAULT_DEADLINE`); a
                            call that misses it fails its certificate, naming the engine, the
                            call and the deadline (a child process has its own ``timeout``)

The engine options, hooks and fixtures come from the family records
(:data:`peclet_verify.registry.FAMILIES`): one option, hook and session fixture per engine
(``peclet_backend``, ``peclet_mass_backend``, ``peclet_dem_backend``; the mechanics family
certifies the DEM engine), made by :mod:`peclet_verify.fixtures`.

Every option is checked when pytest starts (a one-line usage error naming the option and the
file), before any certificate runs. Fixture ``peclet_certificate``: call it with a
:class:`~peclet_verify.search.PropertyResult`: it records the certificate, skips an
"unavailable" one, xfails a waived failure and fails the test, showing the shrunk
counterexample, on any other failure.

Results travel on each test's report (``user_properties``), so under pytest-xdist (``-n``) the
controller's summary, comparison and report hold every certificate; only the controller
writes the report. Importing this module imports pytest and the standard library only: the
engine, numpy and Hypothesis load when ``--peclet-certify`` is given.
"""
from __future__ import annotations

import os

import pytest

from . import fixtures as F
from . import registry as REG

PROFILES = ("dev", "ci", "nightly", "smoke")  # = peclet_verify.profiles.PROFILES (a test checks)
USER_PROPERTY = "peclet_certificate"
#: What a verdict depends on beyond its figure (a certificate's detail key -> its label),
#: printed under the summary table (the report has it in each certificate's details): the
#: error floor an engine declared, whether determinism was compared across processes.
VERDICT_NOTES = {"declared_floor": "declared floor", "cross_process": "across processes"}
_STATE = pytest.StashKey[dict]()


def pytest_addhooks(pluginmanager):
    from . import hooks
    pluginmanager.add_hookspecs(hooks)


#: The option group: (flag, metavar or None for a switch, help). Every option but the first
#: needs --peclet-certify.
_OPTIONS = (
    ("--peclet-certify", None,
     "run the peclet certification properties (marker peclet_certify)"),
    ("--peclet-profile", "NAME",
     "certification profile: dev (default; 25 examples, random), ci (40, derandomised, no "
     "database), nightly (2000, random, example database), smoke (2; for testing the plugin "
     "itself)"),
    ("--peclet-report", "PATH",
     "write the certificates as JSON to PATH (atomic; never replaces a file that is not a "
     "peclet report)"),
    ("--peclet-compare", "PREVIOUS.json",
     "fail if a certificate that passed in PREVIOUS.json fails now, or its figure got worse "
     "beyond the documented tolerance"),
    ("--peclet-xfails", "FILE",
     "known deviations (TOML or JSON: certificate -> reason [, kinds]); a matching failure "
     "is reported as waived, not failed"),
    ("--peclet-replay", "DIR",
     "re-run only the examples saved in the example database DIR (read-only, nothing "
     "generated), e.g. the last nightly's"),
) + tuple((fam.option, "MODULE:FACTORY", f"{fam.name} engine to certify: factory() returns "
                 f"{fam.engine}; else the {fam.hook} hook") for fam in F.ENGINES) + (
    (F.DEADLINE_OPTION, "SECONDS",
     "deadline of each call of an engine running in this process (default 300); a call that "
     "misses it fails its certificate"),
)

# the engines' session fixtures, one per family record (peclet_backend, peclet_mass_backend,
# peclet_dem_backend): module attributes, so that pytest registers them with this plugin
for _fam in F.ENGINES:
    globals()[_fam.fixture] = F.session_fixture(_fam)

_NEEDS_CERTIFY = tuple(flag for flag, _, _ in _OPTIONS[1:])


def pytest_addoption(parser):
    group = parser.getgroup("peclet", "peclet certification")
    for flag, metavar, text in _OPTIONS:
        if metavar is None:
            group.addoption(flag, action="store_true", default=False, help=text)
        elif flag == "--peclet-profile":
            group.addoption(flag, choices=PROFILES, default=None, help=text)
        else:
            group.addoption(flag, metavar=metavar, default=None, help=text)


def _is_worker(config) -> bool:
    return hasattr(config, "workerinput")  # pytest-xdist worker


def _check_options(config):
    """Validate every peclet option (cheap: no engine import); returns the session state."""
    from . import report as R
    certify = config.getoption("--peclet-certify")
    given = [opt for opt in _NEEDS_CERTIFY if config.getoption(opt) is not None]
    if given and not certify:
        raise pytest.UsageError(f"{given[0]} has no effect without --peclet-certify")
    state = {"rows": [], "waivers": [], "baseline": None, "compare": None, "report": None,
             "profile": None}
    try:
        path = config.getoption("--peclet-report")
        if path is not None:
            state["report"] = R.check_report_path(path)
        path = config.getoption("--peclet-compare")
        if path is not None:
            state["baseline"] = R.load_report(path, "--peclet-compare")
        path = config.getoption("--peclet-xfails")
        if path is not None:
            state["waivers"] = R.load_xfails(path, R.KNOWN_CERTIFICATES)
        F.check_backend_options(config)  # every family's engine option, the deadline
        replay = config.getoption("--peclet-replay")
        if replay is not None:
            from .profiles import check_replay_dir
            check_replay_dir(replay)
            if _count_examples(replay) == 0:
                raise ValueError(f"--peclet-replay {replay}: the example database holds no "
                                 "examples (a replay of it would certify nothing)")
    except ValueError as exc:
        raise pytest.UsageError(str(exc).splitlines()[0]) from None
    return state


def _count_examples(path) -> int:
    """Saved examples in a directory-based Hypothesis database (files under its key
    directories; hidden files such as metadata are not examples)."""
    n = 0
    for root, dirs, files in os.walk(path):
        dirs[:] = [d for d in dirs if not d.startswith(".")]
        if os.path.abspath(root) != os.path.abspath(path):
            n += sum(1 for f in files if not f.startswith("."))
    return n


def pytest_configure(config):
    config.addinivalue_line("markers", "peclet_certify: a certification property; runs only "
                                       "with --peclet-certify")
    state = _check_options(config)
    config.stash[_STATE] = state
    config.pluginmanager.register(_Collector(state["rows"]), "peclet-certificates")
    if config.getoption("--peclet-certify"):
        from . import search as P
        from .profiles import make_settings
        name = config.getoption("--peclet-profile") or "dev"
        replay = config.getoption("--peclet-replay")
        state["profile"] = "peclet-" + name + (" (replay)" if replay else "")
        P.set_profile(make_settings(name, str(config.rootpath), replay), state["profile"])
        P.set_progress(lambda *a: _report_progress(config, *a))


def pytest_unconfigure(config):
    import sys
    props = sys.modules.get("peclet_verify.search")  # not imported: nothing to undo
    if props is not None:
        props.set_progress(None)
        props.set_profile(None)


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


@pytest.fixture
def peclet_certificate(request):
    """Record a PropertyResult; skip if unavailable, xfail if waived, fail (with the
    counterexample) if failed."""
    from .report import find_waiver
    state = request.config.stash[_STATE]

    def record(result):
        cert = dict(test=request.node.nodeid, **result.to_dict())
        if not result.passed and result.status not in ("n/a", "unavailable", "not claimed"):
            cert["status"] = "failed"  # passed=False decides, whatever status was left at
        waiver = find_waiver(state["waivers"], cert)
        cert["waived"] = waiver.reason if waiver else None
        # on the report, so that the xdist controller receives it (its stash is not shared)
        request.node.user_properties.append((USER_PROPERTY, cert))
        if result.status == "unavailable":
            pytest.skip(f"{result.name} unavailable: {result.counterexample}")
        if cert["status"] == "failed":
            if waiver:
                pytest.xfail(f"certificate {result.name} failed, waived ({waiver.name}): "
                             f"{waiver.reason}")
            pytest.fail(f"certificate {result.name} FAILED after {result.examples} examples "
                        f"(worst {result.worst_name} = {result.worst!r})\n"
                        f"{result.counterexample}", pytrace=False)
        return result
    return record


class _Collector:
    """Gathers the certificates from every test report: in this process, or (under xdist, on
    the controller) from the workers' reports."""

    def __init__(self, rows):
        self.rows = rows

    def pytest_runtest_logreport(self, report):
        if report.when == "call":
            self.rows.extend(v for k, v in report.user_properties if k == USER_PROPERTY)


def _verdict(c) -> str:
    if c["status"] == "failed" and c.get("waived"):
        return "WAIVED"
    return c["status"].upper()


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    state = config.stash.get(_STATE, None)
    if state and state.get("replay_empty"):
        terminalreporter.write_sep("=", state["replay_empty"], red=True)
    if not state or not state["rows"]:
        return
    tr = terminalreporter
    tr.write_sep("=", "peclet certificates")
    head = f"{'property':<44} {'examples':>8}  {'worst figure':<44} {'verdict':<11}"
    tr.write_line(head)
    tr.write_line("-" * len(head))
    for c in state["rows"]:
        label = c["test"].split("::")[-1] if c["name"] in c["test"] else \
            f"{c['name']} ({c['test'].split('::')[-1]})"
        fig = f"{c['worst_name']} = {c['worst']:.3g}" if c["worst_name"] and \
            c["worst"] is not None else (f"{c['worst_name']} = -" if c["worst_name"] else "-")
        v = _verdict(c)
        tr.write_line(f"{label[:44]:<44} {c['examples']:>8}  {fig[:44]:<44} {v:<11}",
                      red=v == "FAILED", green=v == "PASSED",
                      yellow=v in ("UNAVAILABLE", "N/A", "WAIVED", "NOT CLAIMED"))
    for c in state["rows"]:
        details = c.get("details") or {}
        notes = [f"{label} {details[key]:g}" if isinstance(details[key], float) else
                 f"{label}: {details[key]}" for key, label in VERDICT_NOTES.items()
                 if key in details]
        if notes:
            tr.write_line(f"{c['name']} ({details.get('backend', '-')}): " + "; ".join(notes))
    for c in state["rows"]:
        if c["status"] == "failed":
            tr.write_sep("-", f"counterexample: {c['name']}" +
                         (f" (waived: {c['waived']})" if c.get("waived") else ""))
            tr.write_line(c["counterexample"])
    for w in state["waivers"]:
        used = sum(1 for c in state["rows"] if c.get("waived") and w.matches(c))
        tr.write_line(f"waiver {w.name!r}{' kinds ' + ','.join(w.kinds) if w.kinds else ''}: "
                      f"{w.reason} (applied to {used} certificate(s))", yellow=True)
    if state["compare"] is not None:
        regressions, lines = state["compare"]
        tr.write_sep("=", "peclet compare with "
                     f"{config.getoption('--peclet-compare')}: "
                     f"{len(regressions)} regression(s)", red=bool(regressions))
        for line in lines:
            tr.write_line(line, red="REGRESSED" in line)




def pytest_sessionfinish(session, exitstatus):
    config = session.config
    state = config.stash.get(_STATE, None)
    if state is None or _is_worker(config):
        return  # workers send their certificates on the reports; the controller writes
    rows = state["rows"]
    if any(c["status"] == "failed" and not c.get("waived") for c in rows) \
            and session.exitstatus == 0:
        session.exitstatus = pytest.ExitCode.TESTS_FAILED
    replay = config.getoption("--peclet-replay")
    if replay is not None and config.getoption("--peclet-certify") \
            and sum(int(c.get("examples") or 0) for c in rows) == 0:
        # a replay that re-ran no example certified nothing: it must not pass
        state["replay_empty"] = (f"--peclet-replay {replay}: no certificate re-ran a saved "
                                 f"example ({len(rows)} certificate(s) ran): nothing was "
                                 "certified")
        if session.exitstatus in (0, pytest.ExitCode.NO_TESTS_COLLECTED):
            session.exitstatus = pytest.ExitCode.TESTS_FAILED
    if state["baseline"] is not None:
        from .report import compare
        state["compare"] = compare(state["baseline"], rows)
        if state["compare"][0] and session.exitstatus == 0:
            session.exitstatus = pytest.ExitCode.TESTS_FAILED
    if state["report"]:
        from .report import write_report
        regressions = state["compare"][0] if state["compare"] else None
        write_report(state["report"], {
            "profile": state["profile"],
            "backend": F.backend_label(config, REG.family("geometry")),
            "backends": {fam.name: F.backend_label(config, fam) for fam in REG.FAMILIES},
            "certificates": rows,
            "waivers": [dict(w.to_dict(), applied=sum(1 for c in rows if c.get("waived")
                                                      and w.matches(c)))
                        for w in state["waivers"]],
            "compare": None if regressions is None else {
                "baseline": os.path.abspath(config.getoption("--peclet-compare")),
                "regressions": regressions}})
