"""Validation scripts: the packing chain against published data (run them as scripts).

The scripts share their argument handling here, so that a bad argument is what the ``peclet``
command line makes of one: a single line ``<script>: error: argument <flag>: must be <the
accepted range>, got <value>``, exit code 2, no usage block and no traceback, before any
work (a run takes minutes; an output path is checked before it, not when it is written).

- :class:`ScriptParser`: ``argparse.ArgumentParser`` whose refusals are that one line;
- argument types: :func:`integer`, :func:`real`, :func:`real_list`, :func:`integer_list`,
  :func:`threads`, :func:`output_file`, :func:`input_file` (each checks the text and the
  range, and its message names the range);
- :func:`run`: a script's entry (``sys.exit(run(main))``): a
  :class:`~peclet.core.validation.PecletArgumentError` its run raises later (an argument
  only the run can judge, e.g. a window the fill cannot hold) is one such line too.
"""
from __future__ import annotations

import argparse
import math
import os
import sys

__all__ = ["ScriptParser", "integer", "real", "real_list", "integer_list", "threads",
           "output_file", "input_file", "run"]


class ScriptParser(argparse.ArgumentParser):
    """argparse with every refusal as one line ``<prog>: error: <message>``, exit code 2."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}\n")


def _range(lo, hi, lo_open=False, hi_open=False):
    from peclet.core.validation import describe_range

    return describe_range(lo, hi, lo_open, hi_open)


def _refuse(accepted, text, detail=""):
    return argparse.ArgumentTypeError(f"must be {accepted}, got {text!r}"
                                      + (f" ({detail})" if detail else ""))


def _int(text, lo, hi):
    what = f"an integer {_range(lo, hi)}"
    try:
        v = float(text)
        if not (math.isfinite(v) and v.is_integer()):
            raise ValueError
        v = int(v)
    except (TypeError, ValueError, OverflowError):
        raise _refuse(what, text) from None
    if not lo <= v <= hi:
        raise _refuse(what, text)
    return v


def _float(text, lo, hi, lo_open, hi_open):
    rng = _range(lo, hi, lo_open, hi_open)
    what = "a finite number" + ("" if rng == "finite" else f" {rng}")
    try:
        v = float(text)
    except (TypeError, ValueError):
        raise _refuse(what, text) from None
    ok = (v > lo if lo_open else v >= lo) and (v < hi if hi_open else v <= hi)
    if not (math.isfinite(v) and ok):
        raise _refuse(what, text)
    return v


def integer(lo=-math.inf, hi=math.inf):
    """An argparse ``type``: an integer (``"3"`` or ``"3.0"``) in [lo, hi]."""
    def conv(text):
        return _int(text, lo, hi)
    conv.__name__ = "integer"
    return conv


def real(lo=-math.inf, hi=math.inf, lo_open=False, hi_open=False):
    """An argparse ``type``: a finite number in the interval."""
    def conv(text):
        return _float(text, lo, hi, lo_open, hi_open)
    conv.__name__ = "number"
    return conv


def real_list(lo=-math.inf, hi=math.inf, lo_open=False, hi_open=False):
    """An argparse ``type``: comma-separated finite numbers (at least one), each in the
    interval; a tuple of floats."""
    rng = _range(lo, hi, lo_open, hi_open)

    def conv(text):
        parts = [p for p in str(text).split(",") if p.strip()]
        if not parts:
            raise _refuse(f"comma-separated numbers {rng}", text)
        try:
            return tuple(_float(p, lo, hi, lo_open, hi_open) for p in parts)
        except argparse.ArgumentTypeError:
            raise _refuse(f"comma-separated numbers, each {rng}", text) from None
    conv.__name__ = "numbers"
    return conv


def integer_list(lo=-math.inf, hi=math.inf):
    """An argparse ``type``: comma-separated integers (at least one), each in [lo, hi]; a
    tuple of ints."""
    rng = _range(lo, hi)

    def conv(text):
        parts = [p for p in str(text).split(",") if p.strip()]
        if not parts:
            raise _refuse(f"comma-separated integers {rng}", text)
        try:
            return tuple(_int(p, lo, hi) for p in parts)
        except argparse.ArgumentTypeError:
            raise _refuse(f"comma-separated integers, each {rng}", text) from None
    conv.__name__ = "integers"
    return conv


def threads(text):
    """An argparse ``type``: Numba threads, an integer in [1, NUMBA_NUM_THREADS]."""
    import numba

    cap = int(numba.config.NUMBA_NUM_THREADS)
    try:
        return _int(text, 1, cap)
    except argparse.ArgumentTypeError:
        raise _refuse(f"an integer in [1, {cap}] (NUMBA_NUM_THREADS)", text) from None


def output_file(text):
    """An argparse ``type``: a file path the script can write at the end of its run: not a
    directory, in an existing writable directory. Returns the path as given."""
    what = "a file path in an existing, writable directory"
    p = os.path.abspath(os.fspath(text))
    if not str(text):
        raise _refuse(what, text)
    if os.path.isdir(p):
        raise _refuse(what, text, "it is a directory")
    parent = os.path.dirname(p)
    if not os.path.exists(parent):
        raise _refuse(what, text, f"{parent} does not exist")
    if not os.path.isdir(parent):
        raise _refuse(what, text, f"{parent} is a file")
    if not os.access(parent, os.W_OK | os.X_OK) or not os.stat(parent).st_mode & 0o222:
        raise _refuse(what, text, f"{parent} is not writable")
    return text


def input_file(text):
    """An argparse ``type``: an existing, readable file. Returns the path as given."""
    what = "an existing, readable file"
    p = os.fspath(text)
    if not os.path.exists(p):
        raise _refuse(what, text, "it does not exist")
    if not os.path.isfile(p):
        raise _refuse(what, text, "it is not a file")
    if not os.access(p, os.R_OK):
        raise _refuse(what, text, "it is not readable")
    return text


def run(main, argv=None):
    """``main(argv)``'s exit code; a PecletArgumentError it raises is printed as one line
    ``<script>: error: <message>`` on stderr with exit code 2 (no traceback)."""
    from peclet.core.validation import PecletArgumentError

    try:
        return main(argv)
    except PecletArgumentError as exc:
        prog = os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else "validation"
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
