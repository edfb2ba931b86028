"""Checking what an engine under certification answers, before any figure is computed from it.

A certificate compares numbers, and every comparison with NaN is false: an engine answering NaN
would never "violate" Equation 1 nor "disagree" on a sign. So each answer from a backend goes
through :func:`ask` first, which returns either a float64 array of the promised shape with every
value finite, or the text of what is wrong (the call raised or timed out; the answer is None,
not numeric, of the wrong shape, or holds NaN/inf), with the answer itself shown. A certificate
that gets such a text fails with it as its counterexample.
"""
from __future__ import annotations

import traceback

import numpy as np

from ..loading import backend_name

__all__ = ["ask", "ask_bound", "show_answer"]


def show_answer(value, limit=6) -> str:
    """A short, exact description of ``value`` (type, dtype, shape and the first few entries)."""
    if value is None:
        return "None"
    if isinstance(value, np.ndarray):
        flat = value.reshape(-1)[:limit].tolist() if value.dtype != object else \
            [repr(v) for v in value.reshape(-1)[:limit]]
        more = " ..." if value.size > limit else ""
        return f"ndarray(dtype={value.dtype}, shape={value.shape}, values={flat}{more})"
    text = repr(value)
    return f"{type(value).__name__} {text if len(text) <= 200 else text[:197] + '...'}"


def _as_numbers(value, shape, label):
    """(float64 array, None) or (None, why) for one array-like answer of ``shape``."""
    if value is None:
        return None, f"{label} returned None"
    if isinstance(value, (str, bytes)):
        return None, f"{label} returned a string: {show_answer(value)}"
    try:
        a = np.asarray(value)
    except Exception as exc:  # a ragged or exotic object: the answer is unusable, say why
        return None, f"{label} returned {show_answer(value)}, not an array ({exc})"
    if a.dtype == object or a.dtype.kind not in "iuf":
        return None, f"{label} returned non-numeric {show_answer(a)}"
    if a.shape != tuple(shape):
        return None, (f"{label} returned shape {a.shape}, expected {tuple(shape)}: "
                      f"{show_answer(a)}")
    a = a.astype(np.float64)
    bad = ~np.isfinite(a)
    if bad.any():
        first = int(np.argmax(bad.reshape(-1)))
        return None, (f"{label} returned {int(bad.sum())} non-finite value(s) of {a.size} "
                      f"(first at flat index {first}: {float(a.reshape(-1)[first])!r}): "
                      f"{show_answer(a)}")
    return a, None


def _call(backend, method, args):
    """(answer, None) or (None, why) for ``backend.method(*args)``; never raises."""
    label = f"{backend_name(backend)}.{method}"
    try:
        return getattr(backend, method)(*args), None
    except Exception as exc:  # an engine that raises fails the certificate, it does not crash it
        tb = traceback.format_exception_only(type(exc), exc)[-1].strip()
        return None, f"{label} raised {tb}"


def ask(backend, method, node_ints, node_reals, root, points):
    """Ask ``backend.evaluate`` (or ``evaluate_grad``) at ``points`` (N, 3).

    Returns ``(phi, None)`` with ``phi`` (N,) float64, finite (for ``evaluate_grad`` a pair
    ``(phi (N,), grad (N, 3))``), or ``(None, why)``: the answer was not that, and ``why`` says
    what it was.
    """
    label = f"{backend_name(backend)}.{method}"
    n = len(points)
    out, why = _call(backend, method, (node_ints, node_reals, root, points))
    if why:
        return None, why
    if method != "evaluate_grad":
        return _as_numbers(out, (n,), label)
    if not isinstance(out, (tuple, list)) or len(out) != 2:
        return None, f"{label} returned {show_answer(out)}, expected a pair (phi, grad)"
    phi, why = _as_numbers(out[0], (n,), label + " phi")
    if why:
        return None, why
    grad, why = _as_numbers(out[1], (n, 3), label + " grad")
    return (None, why) if why else ((phi, grad), None)


def ask_bound(backend, node_ints, node_reals, root):
    """Ask ``backend.bound``: ``((centre (3,), radius, certified), None)`` or ``(None, why)``.

    The radius may be ``+inf`` (an unbounded node); NaN, a negative radius, a non-finite centre
    or a claim that is not a bool are refused.
    """
    label = f"{backend_name(backend)}.bound"
    out, why = _call(backend, "bound", (node_ints, node_reals, root))
    if why:
        return None, why
    if not isinstance(out, (tuple, list)) or len(out) != 3:
        return None, f"{label} returned {show_answer(out)}, expected (centre, radius, certified)"
    c, why = _as_numbers(out[0], (3,), label + " centre")
    if why:
        return None, why
    r, cert = out[1], out[2]
    try:
        r = float(r)
    except (TypeError, ValueError):
        return None, f"{label} returned radius {show_answer(r)}, not a number"
    if np.isnan(r) or r < 0:
        return None, f"{label} returned radius {r!r} (must be >= 0, or inf if unbounded)"
    if not isinstance(cert, (bool, np.bool_)):
        return None, f"{label} returned certified={show_answer(cert)}, not a bool"
    return (c, r, bool(cert)), None
