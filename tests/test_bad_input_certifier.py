"""A certifier that can be fooled or stopped (issue 45, class 4), each trick played by an engine
of :mod:`peclet_verify.evasive` and caught:

- an in-process engine whose call never returns fails its certificate at the call's deadline
  (``--peclet-deadline``), naming the engine, the call and the deadline, instead of hanging
  the session;
- an engine seeded once per process (deterministic within it) fails the determinism
  certificate, which also runs each case in two fresh processes; peclet.dem passes it;
- a mass engine 5 % off on every volume that excuses itself with a declared floor of 0.1
  fails: a floor is at most ``MAX_FLOOR``, and the verdict and the report show the floor.

The real runs are ``pytest --peclet-certify`` in a subprocess (smoke profile); the ones that
start engines in child processes are in the heavy tier.
"""
import math
import os
import subprocess
import sys
import threading
import time

import pytest

from peclet_verify import evasive
from peclet_verify.dem import properties as DP
from peclet_verify.dem import strategies as DS
from peclet_verify.dem.backend import PecletDemBackend, factory_spec
from peclet_verify.geometry import strategies as GS
from peclet_verify.mass import properties as MP
from peclet_verify.mass.backend import MAX_FLOOR, PecletMassBackend, check_backend
from peclet_verify.processes import DeadlineBackend, with_deadline
from peclet_verify.report import load_report

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEM_FILE = os.path.join(ROOT, "properties", "test_certify_dem_backend.py")
MASS_FILE = os.path.join(ROOT, "properties", "test_certify_mass.py")
SPHERE = GS.TreeRecipe(GS.LeafCall("sphere", (0.7,), GS.Transform((0.1, -0.2, 0.3))))
POUR = DS.Pour(radii=(0.1, 0.05, 0.1, 0.1), jitter=((1, 0, -2),) * 4,
               velocities=((0.5, 0.0, 0.0),) * 4, e=0.3, mu=0.4, steps=30)


def certify(tmp_path, files, *options, timeout=600):
    """A real certification run (smoke profile): (completed, report dict or None, seconds)."""
    report = tmp_path / "report.json"
    cmd = [sys.executable, "-m", "pytest", *files, "--peclet-certify", "--peclet-profile",
           "smoke", "--peclet-report", str(report), "-p", "no:cacheprovider", "-q", *options]
    t = time.perf_counter()
    done = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=timeout)
    return done, (load_report(report) if report.exists() else None), time.perf_counter() - t


def by_name(report):
    return {c["name"]: c for c in report["certificates"]}


# ------------------------------------------------------------------ 1. every call has a deadline
class Slow:
    name = "slow engine"

    def __init__(self):
        self.release = threading.Event()

    def evaluate(self, *args):
        self.release.wait()
        return "late"

    def boom(self):
        raise KeyError("from the engine")


def test_a_call_that_misses_its_deadline_raises_naming_engine_call_and_seconds():
    engine = Slow()
    be = DeadlineBackend(engine, 0.3)
    t = time.perf_counter()
    with pytest.raises(TimeoutError) as exc:
        be.evaluate(1, 2, 3, 4)
    assert 0.3 <= time.perf_counter() - t < 5
    assert str(exc.value) == ("backend 'slow engine' did not return from evaluate() within "
                              "its deadline of 0.3 s (set with --peclet-deadline)")
    # the engine is not called again (it is still busy): the next call fails at once
    t = time.perf_counter()
    with pytest.raises(TimeoutError, match="an earlier call; the engine is not called again"):
        be.evaluate(1, 2, 3, 4)
    assert time.perf_counter() - t < 0.2
    engine.release.set()


def test_a_deadline_passes_answers_exceptions_and_attributes_through():
    engine = Slow()
    engine.release.set()
    be = with_deadline(engine, 5.0)
    assert isinstance(be, DeadlineBackend) and be.name == "slow engine"
    assert be.evaluate() == "late"
    with pytest.raises(KeyError, match="from the engine"):
        be.boom()
    assert not hasattr(be, "bound") and hasattr(be, "evaluate")  # hasattr stays truthful
    assert with_deadline(be, 1.0) is be                # never wrapped twice

    class OwnDeadline:
        own_deadline = True
    own = OwnDeadline()
    assert with_deadline(own, 1.0) is own              # a child process keeps its timeout
    for bad in (0, -1.0, math.nan, "2"):
        with pytest.raises(ValueError, match="deadline"):
            DeadlineBackend(engine, bad)


def test_a_bad_deadline_option_is_a_one_line_usage_error(tmp_path):
    done = subprocess.run([sys.executable, "-m", "pytest", MASS_FILE, "--peclet-certify",
                           "--peclet-deadline", "0", "-p", "no:cacheprovider", "-q"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert done.returncode == 4, done.stderr
    assert "--peclet-deadline 0: not a number of seconds > 0" in done.stderr


@pytest.mark.heavy
def test_a_never_returning_engine_fails_its_certificate_at_the_deadline(tmp_path):
    (tmp_path / "test_geometry.py").write_text(
        "from peclet_verify.geometry.suite import test_distance_agreement_backend  # noqa\n")
    done, report, seconds = certify(tmp_path, ["test_geometry.py"], "--peclet-backend",
                                    "peclet_verify.evasive:never_returning_backend",
                                    "--peclet-deadline", "2", timeout=300)
    assert done.returncode == 1, done.stdout[-3000:] + done.stderr[-2000:]
    cert = by_name(report)["distance agreement (backend vs reference)"]
    assert cert["status"] == "failed"
    said = ("backend 'planted: evaluate never returns' did not return from evaluate() within "
            "its deadline of 2 s (set with --peclet-deadline)")
    assert said in cert["counterexample"] and said in done.stdout
    # one deadline, not one per example: the session ends soon after it (start-up included)
    assert seconds < 120, seconds


# ------------------------------------------------------------------ 2. determinism across processes
def test_the_engine_to_remake_in_a_fresh_process_is_named_by_its_spec_or_class():
    assert factory_spec(PecletDemBackend()) == ("peclet_verify.dem.backend:PecletDemBackend",
                                                None)
    wrapped = with_deadline(evasive.process_seeded_dem_backend(), 5.0,
                            factory="peclet_verify.evasive:process_seeded_dem_backend")
    assert factory_spec(wrapped) == ("peclet_verify.evasive:process_seeded_dem_backend", None)
    spec, why = factory_spec(evasive.process_seeded_dem_backend())   # a PageApiBackend
    assert spec is None and "takes arguments (make_simulation)" in why


@pytest.mark.heavy
def test_a_per_process_seeded_engine_fails_determinism_and_peclet_passes():
    seeded = with_deadline(evasive.process_seeded_dem_backend(), 300.0,
                           factory="peclet_verify.evasive:process_seeded_dem_backend")
    alone = DP.determinism_one_thread(seeded, POUR, fresh=False)
    assert alone.status == "passed"        # within one process it is deterministic: fooled
    res = DP.determinism_one_thread(seeded, POUR)
    assert res.status == "failed" and res.worst == 3, res.counterexample   # 3 distinct hashes
    assert "fresh process 1" in res.counterexample and \
        res.details["cross_process"].startswith("checked: 2 fresh processes")
    good = DP.determinism_one_thread(with_deadline(PecletDemBackend(), 300.0), POUR)
    assert good.status == "passed" and good.worst == 1
    assert good.details["cross_process"].startswith("checked: 2 fresh processes")


@pytest.mark.heavy
def test_the_determinism_certificate_catches_the_seeded_engine_in_a_real_run(tmp_path):
    done, report, _ = certify(tmp_path, [DEM_FILE], "-k", "determinism_one_thread",
                              "--peclet-dem-backend",
                              "peclet_verify.evasive:process_seeded_dem_backend")
    assert done.returncode == 1, done.stdout[-3000:] + done.stderr[-2000:]
    cert = by_name(report)["determinism at one thread (DEM backend)"]
    assert cert["status"] == "failed" and "fresh process" in cert["counterexample"]
    done, report, _ = certify(tmp_path, [DEM_FILE], "-k", "determinism_one_thread")
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-2000:]
    cert = by_name(report)["determinism at one thread (DEM backend)"]
    assert cert["status"] == "passed"
    assert cert["details"]["cross_process"].startswith("checked: 2 fresh processes")
    assert "determinism at one thread (DEM backend) (peclet.dem): across processes: checked: " \
           "2 fresh processes" in done.stdout


# ------------------------------------------------------------------ 3. a floor is bounded and shown
def test_a_floor_that_excuses_a_five_percent_error_fails(monkeypatch):
    be = evasive.FloorExcusedMassBackend()
    res = MP.mass_properties_certificate(SPHERE, be)
    assert res.status == "failed" and res.details["declared_floor"] == 0.1
    assert f"declares floor 0.1 (the relative error it is excused below), more than the " \
           f"maximum {MAX_FLOOR:g}" in res.counterexample
    # the trick is real: were floors unbounded, the 5 % error would pass under its floor
    monkeypatch.setattr(MP, "MAX_FLOOR", math.inf)
    assert MP.mass_properties_certificate(SPHERE, be).status == "passed"


def test_peclet_passes_with_its_floor_reported():
    res = MP.mass_properties_certificate(SPHERE, PecletMassBackend())
    assert res.status == "passed" and res.details["declared_floor"] == 1e-12


def test_a_floor_that_is_no_positive_number_is_refused_by_name():
    for bad in (-1.0, 0, math.nan, "0.1", True):
        engine = PecletMassBackend()
        engine.floor = bad
        with pytest.raises(ValueError, match="floor must be a number > 0"):
            check_backend(engine)


@pytest.mark.heavy
def test_the_floor_excused_engine_fails_in_a_real_run_and_the_floor_is_shown(tmp_path):
    done, report, _ = certify(tmp_path, [MASS_FILE], "--peclet-mass-backend",
                              "peclet_verify.evasive:floor_excused_mass_backend")
    assert done.returncode == 1, done.stdout[-3000:] + done.stderr[-2000:]
    cert = by_name(report)["mass properties (closed forms)"]
    assert cert["status"] == "failed" and cert["details"]["declared_floor"] == 0.1
    assert "mass properties (closed forms) (planted: volume 5 % off, declares floor 0.1): " \
           "declared floor 0.1" in done.stdout
    done, report, _ = certify(tmp_path, [MASS_FILE])
    assert done.returncode == 0, done.stdout[-3000:]
    assert by_name(report)["mass properties (closed forms)"]["details"]["declared_floor"] \
        == 1e-12
    assert "mass properties (closed forms) (peclet quadrature (body_properties)): declared " \
           "floor 1e-12" in done.stdout


def test_an_engine_that_fails_then_passes_the_same_input_is_reported_failed():
    """A racy engine fails an input and passes it when Hypothesis runs it again: the search
    reports a failed certificate with that input (marked not reproducible), not a Hypothesis
    error (found with the upstream wheel's thread race under OMP_WAIT_POLICY=PASSIVE)."""
    from hypothesis import strategies as st

    from peclet_verify import search as S
    seen = set()

    def racy(x):
        first = x not in seen
        seen.add(x)
        return S.make_result("racy", not (first and x >= 3), float(first and x >= 3), "x",
                             "max", f"x = {x} failed on its first run")
    res = S.search(racy, st.integers(0, 10), name="racy engine",
                   settings=S.profile_settings(max_examples=20))
    assert res.status == "failed" and not res.passed
    assert res.details.get("flaky") is True
    assert "not reproducible" in res.counterexample and "failed on its first run" in \
        res.counterexample
