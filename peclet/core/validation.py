"""One validation layer for every public entry point (API, loaders, CLI, plugin options).

Every check raises :class:`PecletArgumentError` (a ``ValueError``) whose message names the
argument and the accepted range, in one style::

    <name> must be <what is accepted>, got <repr of the value>

Checks are exact about types: a flag is a ``bool`` (or ``numpy.bool_``), never the string
``"False"`` nor the integer 1; an integer is an ``int``/``numpy.integer`` or an integral float,
never a bool. Range checks happen before any expensive work, so a bad call costs nothing.
"""
from __future__ import annotations

import math
import numbers

import numpy as np

__all__ = ["PecletArgumentError", "check_bool", "check_int", "check_float", "check_array",
           "check_choice", "describe_range", "as_points"]


class PecletArgumentError(ValueError):
    """A public entry point was given an argument outside its accepted range.

    ``argument`` names the offending argument (as the caller wrote it, e.g. ``"--seed"`` for
    the command line), ``value`` is what was given.
    """

    def __init__(self, argument, accepted, value, detail=""):
        self.argument = argument
        self.value = value
        shown = _short_repr(value)
        msg = f"{argument} must be {accepted}, got {shown}"
        if detail:
            msg += f" ({detail})"
        super().__init__(msg)


def _short_repr(value, limit=80):
    try:
        if isinstance(value, np.ndarray) and value.size > 8:
            return f"array of shape {value.shape}"
        r = repr(value)
    except Exception:  # a value whose repr raises must not hide the real error
        r = f"<{type(value).__name__}>"
    return r if len(r) <= limit else r[:limit - 3] + "..."


def describe_range(lo=-math.inf, hi=math.inf, lo_open=False, hi_open=False):
    """Human text for an interval, e.g. ``in (0, 1]`` or ``>= 1``."""
    if math.isinf(lo) and math.isinf(hi):
        return "finite"
    if math.isinf(hi):
        return f"{'>' if lo_open else '>='} {lo:g}"
    if math.isinf(lo):
        return f"{'<' if hi_open else '<='} {hi:g}"
    return f"in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"


def check_bool(name, value):
    """``value`` as a Python bool; only ``True``/``False`` (or numpy bools) are accepted."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    raise PecletArgumentError(name, "True or False (a bool)", value)


def check_int(name, value, lo=-math.inf, hi=math.inf):
    """``value`` as an int in [lo, hi]; integral floats are accepted, bools and strings not."""
    if isinstance(value, (bool, np.bool_)) or isinstance(value, str):
        raise PecletArgumentError(name, f"an integer {describe_range(lo, hi)}", value)
    if isinstance(value, numbers.Integral):
        v = int(value)
    elif isinstance(value, numbers.Real) and math.isfinite(float(value)) \
            and float(value).is_integer():
        v = int(value)
    else:
        raise PecletArgumentError(name, f"an integer {describe_range(lo, hi)}", value)
    if not lo <= v <= hi:
        raise PecletArgumentError(name, f"an integer {describe_range(lo, hi)}", value)
    return v


def check_float(name, value, lo=-math.inf, hi=math.inf, lo_open=False, hi_open=False):
    """``value`` as a finite float in the interval; bools and strings are refused."""
    if not isinstance(value, (bool, np.bool_, str)) and isinstance(value, numbers.Real):
        v = float(value)
        ok_lo = v > lo if lo_open else v >= lo
        ok_hi = v < hi if hi_open else v <= hi
        if math.isfinite(v) and ok_lo and ok_hi:
            return v
    # the message only when it is needed (a step checks its dt every time)
    rng = describe_range(lo, hi, lo_open, hi_open)
    raise PecletArgumentError(name, "a finite number" + ("" if rng == "finite" else f" {rng}"),
                              value)


def check_choice(name, value, choices):
    """``value`` if it is one of ``choices`` (compared with ==), else an error listing them."""
    if isinstance(value, str) or not isinstance(value, (bool, np.bool_)):
        for c in choices:
            if value == c:
                return c
    listed = ", ".join(repr(c) for c in choices)
    raise PecletArgumentError(name, f"one of {listed}", value)


def check_array(name, value, shape, dtype=np.float64, finite=True):
    """``value`` as a C-contiguous array of ``shape``; ``None`` in ``shape`` matches any length.

    Strings, ragged sequences and non-numeric objects are refused; with ``finite`` (the
    default) NaN and inf are refused too.
    """
    dims = ", ".join("N" if s is None else str(s) for s in shape)
    what = f"an array of shape ({dims}{',' if len(shape) == 1 else ''})"
    if isinstance(value, (str, bytes)):
        raise PecletArgumentError(name, what, value)
    try:
        a = np.asarray(value)
    except (ValueError, TypeError):
        raise PecletArgumentError(name, what, value, "not a rectangular array") from None
    if a.dtype == object or a.dtype.kind not in "biuf" \
            or (a.dtype.kind == "b" and np.dtype(dtype).kind != "b"):
        raise PecletArgumentError(name, what + " of numbers", value)
    if a.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, a.shape)):
        raise PecletArgumentError(name, what, value, f"shape {a.shape}")
    a = np.ascontiguousarray(a, dtype=dtype)
    if finite and np.dtype(dtype).kind == "f" and not np.all(np.isfinite(a)):
        raise PecletArgumentError(name, what + " of finite numbers (no NaN or inf)", value)
    return a


def as_points(points, name="points") -> np.ndarray:
    """``points`` as a finite (N, 3) float64 C-contiguous array, else a PecletArgumentError."""
    arr = check_array(name, points, (None, 3), finite=False)
    if not np.all(np.isfinite(arr)):
        bad = int(np.argwhere(~np.isfinite(arr).all(axis=1))[0, 0])
        raise PecletArgumentError(name, "an array of shape (N, 3) of finite numbers", points,
                                  f"row {bad} is {arr[bad].tolist()}")
    return arr
