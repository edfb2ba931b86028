"""peclet.core.shares: a nogil kernel's shares on Python threads, every item done once, the
same outputs at any thread count, errors raised in the caller."""
import contextlib
import threading

import numba
import numpy as np
import pytest
from numba import njit

from peclet.core.shares import run_shares, share_count

needs_two = pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2,
                               reason="needs NUMBA_NUM_THREADS >= 2")


@contextlib.contextmanager
def threads(n):
    # Numba's thread count (which sets the number of shares) at n, restored afterwards
    old = numba.get_num_threads()
    numba.set_num_threads(n)
    try:
        yield
    finally:
        numba.set_num_threads(old)


@njit(nogil=True)
def _mark(first, step, out, seen):
    # each item writes its own row: its value and which share did it
    for i in range(first, out.shape[0], step):
        out[i] = np.sqrt(i + 0.5) * 3.0
        seen[i] += first + 1


@njit(nogil=True)
def _fail_at(first, step, bad):
    for i in range(first, 10, step):
        if i == bad:
            raise ValueError("item out of range")


def _run(nthreads, n, dynamic=False):
    with threads(nthreads):
        out = np.zeros(n)
        seen = np.zeros(n, np.int64)
        run_shares(_mark, n, out, seen, dynamic=dynamic)
        return out, seen


@needs_two
def test_every_item_once_and_the_same_bits_at_one_and_two_threads():
    one, seen1 = _run(1, 1001)
    two, seen2 = _run(2, 1001)
    assert np.all(seen1 == 1)                   # one share did everything
    assert set(np.unique(seen2)) == {1, 2}      # both shares worked, each item exactly once
    assert np.array_equal(seen2[::2], np.ones(501, np.int64))
    assert one.tobytes() == two.tobytes()


def test_shares_never_exceed_the_items_or_the_threads():
    assert share_count(0) == 1
    assert share_count(1) == 1
    assert share_count(10 ** 6) == numba.get_num_threads()


@needs_two
def test_an_error_in_a_pool_share_reaches_the_caller():
    with threads(2):
        with pytest.raises(ValueError, match="item out of range"):
            run_shares(_fail_at, 10, 3)             # item 3: share 1, on a pool thread
        with pytest.raises(ValueError, match="item out of range"):
            run_shares(_fail_at, 10, 4)             # item 4: share 0, the calling thread
        run_shares(_fail_at, 10, 99)                # and the pool still works afterwards


@needs_two
def test_the_shares_overlap_in_time():
    # the pool's share runs while the calling thread's is still running: a share that waits
    # for the other to start would hang on one thread and finish on two
    started = [threading.Event(), threading.Event()]

    def kernel(first, step):
        started[first].set()
        assert started[1 - first].wait(timeout=30), "the other share never ran alongside"

    with threads(2):
        run_shares(kernel, 2)


@needs_two
def test_dynamic_deal_does_every_item_once_with_the_same_bits():
    one, seen1 = _run(1, 1001)
    two, seen2 = _run(2, 1001, dynamic=True)
    assert np.all(seen2 >= 1)
    # item k is called as kernel(k, n): the share id it records is k + 1, once
    assert np.array_equal(seen2, np.arange(1, 1002))
    assert one.tobytes() == two.tobytes()


@needs_two
def test_dynamic_deal_spreads_uneven_items_over_both_threads():
    # a fixed deal of 2 shares gives every costly (even) item to share 0; dealt one at a
    # time, the pool thread takes costly items too while the calling thread is busy. The
    # kernel is a Python function that sleeps (releasing the GIL) on the even items and
    # records which thread did each
    import time
    who = {}

    def kernel(first, step, n):
        for i in range(first, n, step):
            if i % 2 == 0:
                time.sleep(0.02)
            who.setdefault(i, []).append(threading.get_ident())

    with threads(2):
        run_shares(kernel, 12, 12)
        fixed = {i: t[0] for i, t in who.items()}
        who.clear()
        run_shares(kernel, 12, 12, dynamic=True)
    assert len({fixed[i] for i in range(0, 12, 2)}) == 1       # the fixed deal: one thread
    assert sorted(who) == list(range(12)) and all(len(t) == 1 for t in who.values())
    assert len({who[i][0] for i in range(0, 12, 2)}) == 2      # dealt: both threads


@needs_two
def test_an_error_in_a_dynamic_share_reaches_the_caller():
    with threads(2):
        for bad in (0, 3, 9):
            with pytest.raises(ValueError, match="item out of range"):
                run_shares(_fail_at, 10, bad, dynamic=True)
        run_shares(_fail_at, 10, 99, dynamic=True)
