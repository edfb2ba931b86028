"""Serial or parallel: the one choice every per-row loop of the Hertz engine makes.

Each job's per-row function (a force, a rolling torque, a body's kick, a patch, a distributed
contact) writes only its own row, so a serial loop and a ``prange`` loop over it give the same
bits; the parallel one pays a launch (~0.6 ms on a loaded 2-core machine) and is taken from a
row count on. The thresholds are package settings of :mod:`peclet.dem.hertz`
(``PARALLEL_MIN``, ``PATCH_PARALLEL_MIN``, ``DIST_PARALLEL_MIN``), read at each call, so that a
test can force either path by setting them on the package.
"""
from __future__ import annotations

import sys


def threshold(name):
    """The package setting ``name`` (a row count) as it is now."""
    return getattr(sys.modules[__package__], name)


def run(serial, parallel, n, setting, *args):
    """``parallel(*args)`` when ``n`` rows reach the package setting ``setting``, else
    ``serial(*args)`` (both kernels loop the same per-row function)."""
    (parallel if n >= threshold(setting) else serial)(*args)
