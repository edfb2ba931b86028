"""Numpy-array message framing for out-of-process backends (stdlib + numpy only).

This module is deliberately free of any ``peclet`` import, so a child process in another
interpreter or virtual environment (one whose ``peclet`` is a different engine) can load it by
file path and serve its engine. A message is an 8-byte little-endian count of arrays followed by,
per array, an 8-byte length and the bytes ``np.save`` writes (``allow_pickle=False``).

Requests: ``[method name (str array), *args]``. Replies: ``["ok", *results]`` or
``["error", message]``. Methods: ``evaluate(node_ints, node_reals, root, points) -> phi``,
``evaluate_grad(...) -> (phi, grad)``, ``bound(node_ints, node_reals, root) -> (centre, radius,
certified)``, ``methods() -> names``, ``close``.
"""
from __future__ import annotations

import io
import struct
import sys
import traceback

import numpy as np

METHODS = ("evaluate", "evaluate_grad", "bound")


def write_message(stream, arrays) -> None:
    """Write ``arrays`` (each converted with ``np.asarray``) as one framed message."""
    chunks = []
    for a in arrays:
        buf = io.BytesIO()
        np.save(buf, np.asarray(a), allow_pickle=False)
        data = buf.getvalue()
        chunks.append(struct.pack("<Q", len(data)) + data)
    stream.write(struct.pack("<Q", len(chunks)) + b"".join(chunks))
    stream.flush()


def _read_exact(stream, n):
    data = stream.read(n)
    if data is None or len(data) != n:
        raise EOFError(f"pipe closed: wanted {n} bytes, got {0 if data is None else len(data)}")
    return data


def read_message(stream) -> list:
    """Read one framed message; returns the list of arrays."""
    (count,) = struct.unpack("<Q", _read_exact(stream, 8))
    out = []
    for _ in range(count):
        (size,) = struct.unpack("<Q", _read_exact(stream, 8))
        out.append(np.load(io.BytesIO(_read_exact(stream, size)), allow_pickle=False))
    return out


def serve(backend, stdin=None, stdout=None) -> None:
    """Answer requests for ``backend`` on binary ``stdin``/``stdout`` until EOF or ``close``.

    ``backend`` implements ``evaluate`` and optionally ``evaluate_grad`` and ``bound``.
    Anything the backend prints goes to stderr, so it cannot corrupt the stream.
    """
    stdin = sys.stdin.buffer if stdin is None else stdin
    stdout = sys.stdout.buffer if stdout is None else stdout
    sys.stdout = sys.stderr
    while True:
        try:
            msg = read_message(stdin)
        except EOFError:
            return
        method = str(msg[0])
        if method == "close":
            write_message(stdout, ["ok"])
            return
        try:
            if method == "methods":
                reply = [np.array([m for m in METHODS if hasattr(backend, m)] or [""])]
            elif method in METHODS and hasattr(backend, method):
                ni, nr, root = msg[1], msg[2], int(msg[3])
                args = (ni, nr, root) + ((msg[4],) if method != "bound" else ())
                res = getattr(backend, method)(*args)
                reply = list(res) if isinstance(res, tuple) else [res]
            else:
                raise ValueError(f"unknown method {method!r}")
            write_message(stdout, ["ok"] + [np.asarray(r) for r in reply])
        except Exception:  # reported to the parent, which raises it there
            write_message(stdout, ["error", traceback.format_exc()])
