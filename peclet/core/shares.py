"""Parallel work on Python threads over a fixed decomposition, without a Numba parallel region.

A kernel compiled with ``nogil=True`` that takes ``(first, step, ...)`` and does the items
``first, first + step, ...`` of its work (each item writing only its own outputs) is run by
:func:`run_shares`: share 0 in the calling thread, the others on a small pool of Python threads,
one share per thread of Numba's current thread count. The items and what each writes do not
depend on how they are dealt, so the results are the same bits at any thread count.

Why not ``@njit(parallel=True)`` with a ``prange`` over the items: Numba links a callee's code
into every function that calls it and optimises and emits it again there, and a parallel region
is two such functions (the region's kernel and its launcher). Around the narrow phase's worker
that cost 8.5 s of a cold first run's compilation (a serial wrapper 2.3 s, none at all here),
around the quadrature's cell integration 4 s. The price is the launch: handing a share to a
pool thread and waiting for it took 0.2-0.25 ms on the 2-core machine this was measured on
(Numba's own workers spin between regions and launch in ~12 us), so it pays where a call holds
milliseconds of work: the narrow phase goes parallel only above ``contacts.SERIAL_WORK`` (the
page's pour at 2 threads: 2.1-2.2 ms/step with the shares, 2.1-2.6 serial), a quadrature pass
integrates cells of about 0.1-1 ms each.
"""
from __future__ import annotations

import itertools
import os
import threading
from concurrent.futures import ThreadPoolExecutor

import numba

__all__ = ["share_count", "run_shares"]

_lock = threading.Lock()
_pool: ThreadPoolExecutor | None = None
_pool_size = 0


def _forget_pool():
    # a forked child inherits the pool object but not its threads: it starts its own
    global _pool, _pool_size
    _pool, _pool_size = None, 0


os.register_at_fork(after_in_child=_forget_pool)


def share_count(n):
    """How many shares :func:`run_shares` deals ``n`` items into: Numba's current thread count
    (``numba.get_num_threads()``, which ``NUMBA_NUM_THREADS`` and ``numba.set_num_threads``
    set), at most ``n``, at least 1."""
    return max(1, min(int(numba.get_num_threads()), int(n)))


def _executor(workers):
    global _pool, _pool_size
    with _lock:
        if _pool is None or _pool_size < workers:
            old = _pool
            _pool, _pool_size = ThreadPoolExecutor(workers, "peclet-share"), workers
            if old is not None:
                old.shutdown(wait=False)
        return _pool


def run_shares(kernel, n, *args, dynamic=False):
    """Call ``kernel(first, step, *args)`` for ``first`` = 0 .. step - 1 with ``step`` =
    :func:`share_count` (``n``), share 0 in the calling thread and the others at once on
    pool threads; return when all are done. ``kernel`` must release the GIL
    (``@njit(nogil=True)``) for the shares to overlap, and each item must write only its own
    outputs. An exception in any share is raised here (the first share's first).

    ``dynamic=True`` deals the items one at a time instead: each thread calls
    ``kernel(k, n, *args)`` (item k alone) for the next item k not yet taken, until none is
    left. For items of very uneven cost (a quadrature's cells: a few take hundreds of times
    the median), where a fixed deal can leave one thread with most of the work; each call
    costs a dispatch (tens of microseconds), so the items must be far costlier than that.
    Which thread does an item never changes what it writes."""
    step = share_count(n)
    if step == 1:
        kernel(0, 1, *args)
        return
    pool = _executor(step - 1)
    if dynamic:
        taken = itertools.count()
        failed = []

        def share(_first, _step, *args):
            # the next free item, until none is left or a share has failed
            for k in taken:
                if k >= n or failed:
                    return
                try:
                    kernel(k, n, *args)
                except BaseException:
                    failed.append(True)
                    raise
        body = share
    else:
        body = kernel
    others = [pool.submit(body, first, step, *args) for first in range(1, step)]
    try:
        body(0, step, *args)
    finally:
        # every share finishes before the outputs are read (or an error is raised)
        errors = [f.exception() for f in others]
    for e in errors:
        if e is not None:
            raise e
