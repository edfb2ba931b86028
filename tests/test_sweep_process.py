"""peclet.packing.page.sweep_process: the wall-thickness sweep in a low-priority child gives the
rows of the same sweep in this process, bit for bit; a child that fails leaves the error to the
in-process sweep; the child runs in the idle scheduling class; a run that stops kills it."""
import os
import time

import pytest

from peclet.packing.analysis import geometry as analysis
from peclet.packing.page.sweep_process import SweepProcess

THICK = [0.06, 0.12]
# a coarse sweep (2 top cells a side, tol 1e-3: 1.8 s against 3.0 s at the page's n = 32,
# tol 1e-4): the rows' bits, not their accuracy, are under test
N, TOL = 8, 1e-3


def test_rows_from_the_child_equal_the_sweep_here_bit_for_bit():
    child = SweepProcess(THICK, n=N, tol=TOL, use_cache=False)
    here = analysis.sweep_fractions(THICK, n=N, tol=TOL)
    rows = child.rows()
    assert child.child.returncode == 0
    assert [sorted(r) for r in rows] == [sorted(r) for r in here]
    for a, b in zip(rows, here):
        for k in a:
            assert float(a[k]).hex() == float(b[k]).hex(), k


def test_an_empty_sweep_starts_no_child():
    s = SweepProcess([], n=8, tol=1e-4)
    assert s.child is None and s.rows() == []


def test_a_failing_child_leaves_the_error_to_the_sweep_here():
    # n = 1 is refused by the quadrature (n in [2, 4096]): the child exits with an error and
    # rows() runs the sweep here, which raises it
    s = SweepProcess([0.06], n=1, tol=1e-4, use_cache=False)
    with pytest.raises(Exception, match="n"):
        s.rows()
    assert s.child.returncode != 0


@pytest.mark.skipif(not hasattr(os, "SCHED_IDLE"), reason="Linux's idle scheduling class")
def test_the_child_runs_in_the_idle_class_and_stop_kills_it():
    s = SweepProcess([0.16] * 20, n=32, tol=1e-4, threads=1, use_cache=False)
    try:
        deadline = time.monotonic() + 60.0
        policy = None
        while time.monotonic() < deadline and s.child.poll() is None:
            policy = os.sched_getscheduler(s.child.pid)
            if policy == os.SCHED_IDLE:
                break
            time.sleep(0.05)
        assert policy == os.SCHED_IDLE
    finally:
        s.stop()
    assert s.child.poll() is not None


def test_no_child_started_means_the_sweep_here(monkeypatch, tmp_path):
    # a machine where the child cannot be started (its interpreter is not there: Popen raises
    # FileNotFoundError): the rows are still the sweep's, computed in this process, never an
    # empty list
    import sys

    monkeypatch.setattr(sys, "executable", str(tmp_path / "no-such-python"))
    s = SweepProcess([0.12], n=N, tol=TOL, use_cache=False)
    assert s.child is None
    assert s.rows() == analysis.sweep_fractions([0.12], n=N, tol=TOL)


def test_a_later_sweep_reads_the_rows_kept_by_an_earlier_one(monkeypatch, tmp_path):
    # the rows depend on the thicknesses, n and tol alone: a second run reads them from the
    # results cache, bit for bit, and starts no child; another tol is another entry
    monkeypatch.setenv("PECLET_CACHE_DIR", str(tmp_path / "cache"))
    first = SweepProcess([0.12], n=N, tol=TOL)
    assert not first.from_cache and first.child is not None
    rows = first.rows()
    again = SweepProcess([0.12], n=N, tol=TOL, threads=1)
    assert again.from_cache and again.child is None
    got = again.rows()
    assert [float(r["s"]).hex() for r in got] == [float(r["s"]).hex() for r in rows]
    assert got == rows
    other = SweepProcess([0.12], n=N, tol=TOL / 2)
    assert not other.from_cache
    other.stop()
    # off: computed every time
    monkeypatch.setenv("PECLET_CACHE_DIR", "off")
    off = SweepProcess([0.12], n=N, tol=TOL)
    assert not off.from_cache and off.child is not None
    off.stop()
