"""Argument checks of the strategy constructors of every family (a bad argument is a ``ValueError`` naming it)."""
from __future__ import annotations

import math

import numpy as np


def check_range(value, name, lo_min=0.0):
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a pair (lo, hi), got {value!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo_min < lo <= hi):
        raise ValueError(f"{name} must satisfy {lo_min} < lo <= hi (finite), got {value!r}")
    return lo, hi


def check_int(value, name, lo, hi=None):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an int, got {value!r}")
    if value < lo or (hi is not None and value > hi):
        rng = f"[{lo}, {hi}]" if hi is not None else f">= {lo}"
        raise ValueError(f"{name} must be in {rng}, got {value}")
    return int(value)
