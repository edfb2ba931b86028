"""Repository-wide pytest configuration (the peclet_verify plugin loads via its entry point).

Two tiers. The README's test command (``python -m pytest -n auto``) runs the fast tier: every
test not marked ``heavy``. The heavy tier (``python -m pytest --tier heavy -n auto``) holds the
tests that take seconds each (long beds, planted-engine certifications, full grid studies,
validation at reduced size); each subject keeps a cheaper test in the fast tier. ``.ci/run``
runs both, the nightly runs the certificates. Naming files or test ids on the command line runs
every tier of what was named unless ``--tier`` says otherwise.
"""
import os
import subprocess
import sys

import pytest

# Numba's OpenMP layer lets idle threads spin by default: with two test workers, each with a
# two-thread pool, on two cores, a spinning pool holds a core the other worker needs and a
# parallel region waits a scheduler slice (measured: 13 s of DEM tests took 32 s under -n 2).
# Passive waiting changes which thread sleeps, never what any kernel computes (the bits are
# the same). Set before any OpenMP runtime starts; the xdist workers and the tests' child
# processes inherit it. A value the user set wins.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

pytest_plugins = ["pytester"]

TIERS = ("fast", "heavy", "all")


def pytest_addoption(parser):
    parser.addoption("--tier", choices=TIERS, default=None,
                     help="which tests run: fast (no 'heavy' mark; the default without test "
                     "paths), heavy (only those), all (the default when paths are named)")


def pytest_configure(config):
    config.addinivalue_line("markers", "heavy: the heavy tier, run by --tier heavy or all "
                            "(and by .ci/run), not by the README's test command")
    # the results cache (peclet.core.results_cache) of this run only, shared by its xdist
    # workers and child processes (they inherit the environment): no test reads what an
    # earlier run or the user left, none writes into the user's cache
    if not hasattr(config, "workerinput"):
        import tempfile

        config._peclet_cache = (tempfile.mkdtemp(prefix="peclet-test-cache-"),
                                os.environ.get("PECLET_CACHE_DIR"))
        os.environ["PECLET_CACHE_DIR"] = config._peclet_cache[0]
    # `-n` alone schedules in fixed batches; worksteal lets an idle worker take tests queued
    # for a busy one, so a run does not end on one worker. Not in addopts: a --dist there
    # would also switch pytest-benchmark off in benchmarks/tracked (it sees xdist as active).
    if (getattr(config.option, "numprocesses", None) and config.option.dist == "load"
            and not any(a.startswith("--dist") or a == "-d"
                        for a in config.invocation_params.args)):
        config.option.dist = "worksteal"


def _tier(config):
    tier = config.getoption("--tier")
    if tier is None:
        tier = "fast" if config.args_source == pytest.Config.ArgsSource.TESTPATHS else "all"
    return tier


def pytest_collection_modifyitems(config, items):
    tier = _tier(config)
    if tier == "all":
        return
    keep, drop = [], []
    for item in items:
        heavy = item.get_closest_marker("heavy") is not None
        (keep if heavy == (tier == "heavy") else drop).append(item)
    if drop:
        config.hook.pytest_deselected(items=drop)
        items[:] = keep


def pytest_sessionstart(session):
    """A whole-suite run (no test paths named) on a cold Numba cache compiles the page's
    kernels first, the DEM step in two child processes while this one compiles the quadrature's
    and the shell's on a small solid (what ``peclet warm`` does), before any xdist worker
    starts. Otherwise both workers compile the same kernels at once, each a core's worth of
    minutes (cold test command: 281 s with two workers compiling side by side). Nothing is
    compiled that a warm cache holds."""
    config = session.config
    if hasattr(config, "workerinput") or config.args_source != pytest.Config.ArgsSource.TESTPATHS:
        return
    import time

    from peclet.core.geom.quadrature.refine import kernels_cached
    from peclet.dem import warm

    t = time.perf_counter()
    children = warm.start_background()
    quadrature = kernels_cached() is False
    if quadrature:
        from peclet.dem import scene_particle

        scene_particle.compile_kernels()
    ok = warm.finish(children)
    if children is not None or quadrature:
        tr = config.pluginmanager.get_plugin("terminalreporter")
        if tr is not None:
            tr.write_line(f"cold Numba cache: the page's kernels compiled first in "
                          f"{time.perf_counter() - t:.0f} s (DEM step children "
                          f"{'ok' if ok else 'failed: the tests compile it'})")


def pytest_unconfigure(config):
    # the run's results cache removed and the caller's setting put back (a pytest.main() call
    # in a longer-lived process must not leave it pointing at a deleted directory)
    kept = getattr(config, "_peclet_cache", None)
    if kept is not None:
        import shutil

        d, before = kept
        shutil.rmtree(d, ignore_errors=True)
        if before is None:
            os.environ.pop("PECLET_CACHE_DIR", None)
        else:
            os.environ["PECLET_CACHE_DIR"] = before


def pytest_report_header(config):
    return f"peclet test tier: {_tier(config)} (conftest.py; --tier fast|heavy|all)"


@pytest.fixture(scope="session")
def peclet_geom_python(tmp_path_factory):
    """The interpreter of a fresh venv holding the upstream ``peclet-geom`` wheel (it ships a
    ``peclet`` namespace that must not meet ours); built once per session, skipped with the
    installer's reason when the wheel cannot be installed from the package index. Under
    pytest-xdist the workers share one venv (built by the first, under a file lock, in the
    run's common temporary directory)."""
    import fcntl

    base = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        base = base.parent                   # the directory every worker's basetemp lies in
    venv = base / "peclet-geom-venv"
    py = str(venv / "bin" / "python")
    with open(base / "peclet-geom-venv.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)     # released when the file closes
        failed = base / "peclet-geom-venv.failed"
        if not (venv / "ready").exists() and not failed.exists():
            subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=300)
            proc = subprocess.run([py, "-m", "pip", "install", "-q", "peclet-geom"],
                                  capture_output=True, text=True, timeout=600)
            if proc.returncode == 0:
                (venv / "ready").write_text("")
            else:
                failed.write_text(proc.stderr.strip()[-300:])
        if failed.exists():
            pytest.skip(f"peclet-geom could not be installed from the package index: "
                        f"{failed.read_text()}")
    return py
