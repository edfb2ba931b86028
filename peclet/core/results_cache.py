"""Deterministic results kept on disk, keyed by the code that computes them.

Some results are pure functions of a few numbers and of peclet's own code, and cost seconds:
Step 6's wall-thickness sweep (:mod:`peclet.packing.page.sweep_process`) is the same for every run
of the page, whatever its ring count or seed. :func:`load` / :func:`store` keep such results
between runs.

An entry is one JSON file, ``cache_dir()/<kind>/<key>.json``, where ``key`` is the SHA-256 of
the *code stamp* and of the call's parameters. The code stamp covers every ``.py`` file of the
installed ``peclet`` package (its relative path and bytes), the versions of Python, numpy,
numba and llvmlite, the machine and Numba's host CPU: any change to peclet's code, the numeric
libraries or the hardware is a miss, never a stale result. JSON floats round-trip exactly, so a
hit returns the computed values bit for bit. An entry is written whole (a temporary file
renamed over its name, :func:`peclet.core.files.write_text`), so a reader sees a complete
entry or none; an entry that cannot be read or does not hold what its caller expects is a
miss, and the next :func:`store` replaces it. Entries are small (a sweep: 1 kB) and never
pruned: deleting the directory is always safe.

``PECLET_CACHE_DIR`` chooses the directory (default ``$XDG_CACHE_HOME/peclet``, else
``~/.cache/peclet``); ``PECLET_CACHE_DIR=off`` turns the cache off (nothing read or written).
"""
from __future__ import annotations

import hashlib
import json
import os
import platform
import sys

from .files import write_text

__all__ = ["cache_dir", "code_stamp", "load", "store", "OFF"]

#: The value of PECLET_CACHE_DIR that turns the cache off.
OFF = "off"

_STAMP = None


def cache_dir():
    """The cache's directory (not created here), or None when ``PECLET_CACHE_DIR=off``."""
    d = os.environ.get("PECLET_CACHE_DIR")
    if d is not None and d.strip().lower() == OFF:
        return None
    if d:
        return os.path.abspath(os.path.expanduser(d))
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "peclet")


def package_root():
    """The directory of the installed ``peclet`` package."""
    return os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def package_dirs():
    """Every directory of the package (``__pycache__`` skipped), top-down in a fixed order."""
    out = []
    for d, dirs, _ in os.walk(package_root()):
        dirs[:] = sorted(x for x in dirs if x != "__pycache__")
        out.append(d)
    return out


def code_stamp():
    """The hex SHA-256 of peclet's source files, the numeric libraries' versions, the machine
    and Numba's host CPU (computed once per process, about 10 ms)."""
    global _STAMP
    if _STAMP is None:
        import llvmlite
        import numba
        import numpy

        h = hashlib.sha256()
        root = package_root()
        files = [os.path.join(d, f) for d in package_dirs() for f in os.listdir(d)
                 if f.endswith(".py")]
        for f in sorted(files):
            h.update(os.path.relpath(f, root).encode() + b"\0")
            with open(f, "rb") as fh:
                h.update(hashlib.sha256(fh.read()).digest())
        try:
            from llvmlite import binding
            cpu = binding.get_host_cpu_name()
        except Exception:                        # the stamp then holds the machine alone
            cpu = "?"
        h.update(json.dumps([sys.version, numpy.__version__, numba.__version__,
                             llvmlite.__version__, platform.machine(), cpu]).encode())
        _STAMP = h.hexdigest()
    return _STAMP


def _path(kind, params):
    d = cache_dir()
    if d is None:
        return None
    key = hashlib.sha256((code_stamp() + json.dumps(params, sort_keys=True,
                                                    allow_nan=False)).encode()).hexdigest()
    return os.path.join(d, kind, key + ".json")


def load(kind, params, valid=None):
    """The value stored for ``kind`` (a short name) and ``params`` (JSON-able), or None: no
    entry, the cache off, an unreadable entry, or one that ``valid(value)`` (optional) rejects.
    """
    path = _path(kind, params)
    if path is None:
        return None
    try:
        with open(path) as fh:
            entry = json.load(fh)
    except (OSError, ValueError):
        return None
    if not isinstance(entry, dict) or entry.get("params") != json.loads(
            json.dumps(params, sort_keys=True)) or "value" not in entry:
        return None
    value = entry["value"]
    if valid is not None and not valid(value):
        return None
    return value


def store(kind, params, value):
    """Keep ``value`` (JSON-able, no NaN) for ``kind`` and ``params``; returns the entry's
    path, or None when the cache is off or cannot be written (a read-only home: the result is
    simply not kept)."""
    path = _path(kind, params)
    if path is None:
        return None
    text = json.dumps(dict(params=params, value=value), sort_keys=True, allow_nan=False)
    try:
        return write_text(path, text + "\n")
    except OSError:
        return None
