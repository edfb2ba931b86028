"""Serial or parallel: the one choice every per-row loop of the explicit engine makes.

Each job's per-row function (a force, a rolling torque, a body's kick, a patch, a distributed
contact) writes only its own row, so a serial loop and a ``prange`` loop over it give the same
bits; the parallel one pays a launch (~0.6 ms on a loaded 2-core machine) and is taken from a
row count on. The thresholds are package settings of :mod:`peclet.dem.hertz`
(``PARALLEL_MIN``, ``PATCH_PARALLEL_MIN``, ``DIST_PARALLEL_MIN``), read at each call, so that a
test can force either path by setting them on the package.

The loop over a row function is written once (:data:`_LOOP`) and compiled twice per job by
:func:`row_loops`. Why it is a template and not a wrapper:

- Numba keys its on-disk cache by the function's file, qualified name and bytecode, not by its
  flags, so the serial and the parallel compilation of one function would overwrite each
  other's entries: each compilation gets its own name;
- a closure over the row function, or a loop taking it as an argument, compiles but is never
  served from the cache (measured, Numba 0.68.1), so the row function is a global of the loop;
- a ``prange`` loop cannot pass on ``*args`` holding NamedTuples (the parallel region refuses
  them), so the loop spells out the row function's own parameter names;
- each loop is filed under the row function's source file, so its cache entry goes stale with
  that file (and :func:`peclet.core.jitcache.purge_stale` clears it with any change).
"""
from __future__ import annotations

import inspect
import sys
from typing import NamedTuple

import numpy as np
from numba import njit, prange


class RowLoops(NamedTuple):
    """One job's two compiled loops, each called as ``loop(n, *args)`` and running
    ``row(i, *args)`` for i in 0..n-1: ``serial`` with ``range``, ``parallel`` with ``prange``."""
    serial: object
    parallel: object


# the one loop over a row function ROW: {params} are the row's own parameters after i
# (a prange loop in a function compiled without parallel=True runs as a plain range)
_LOOP = """def {name}(n, {params}):
    for i in prange(n):
        ROW(np.int64(i), {params})
"""


def row_loops(row):
    """The serial and the parallel loop over the ``@njit`` row function ``row(i, ...)``
    (which must write only row i's slots), named ``<row>_serial`` / ``<row>_parallel`` and
    cached beside ``row``'s module."""
    func = row.py_func
    params = ", ".join(list(inspect.signature(func).parameters)[1:])
    loops = []
    for suffix, parallel in (("serial", False), ("parallel", True)):
        name = f"{func.__name__}_{suffix}"
        names = {"ROW": row, "np": np, "prange": prange, "__name__": func.__module__}
        exec(compile(_LOOP.format(name=name, params=params), func.__code__.co_filename, "exec"),
             names)
        loops.append(njit(cache=True, parallel=parallel)(names[name]))
    return RowLoops(*loops)


def threshold(name):
    """The package setting ``name`` (a row count) as it is now."""
    return getattr(sys.modules[__package__], name)


def run(loops, n, setting, *args):
    """``loops.parallel(n, *args)`` when the ``n`` rows reach the package setting ``setting``,
    else ``loops.serial(n, *args)`` (:class:`RowLoops`)."""
    (loops.parallel if n >= threshold(setting) else loops.serial)(np.int64(n), *args)
