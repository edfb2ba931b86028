"""Writing files so that nothing a user saved is ever lost or half-written.

:func:`atomic_write` writes to a temporary file beside the target and renames it over, so a
crash or Ctrl-C leaves either the old file or the new one, never a torn one. New files get the
permissions ``open()`` would give (``0o666`` less the umask) instead of mkstemp's ``0o600``.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
import tempfile

import numpy as np

from .validation import PecletArgumentError

__all__ = ["atomic_write", "atomic_directory", "check_writable_path", "file_sha256",
           "jsonable", "remove_parts", "write_json", "write_text"]


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


def check_writable_path(path, name="path"):
    """Raise :class:`PecletArgumentError` unless ``path`` can be created or replaced as a file.

    Checked up front (before expensive work): the path is not a directory, its parent is a
    directory (or can be created: no component of it is a file), and that directory is
    writable.
    """
    p = os.path.abspath(os.fspath(path))
    if os.path.isdir(p):
        raise PecletArgumentError(name, "a file path", os.fspath(path), "it is a directory")
    parent = os.path.dirname(p)
    probe = parent
    while not os.path.exists(probe):
        probe = os.path.dirname(probe)
    if not os.path.isdir(probe):
        raise PecletArgumentError(name, "a file path", os.fspath(path),
                                  f"{probe} is a file, not a directory")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise PecletArgumentError(name, "a writable location", os.fspath(path),
                                  f"{probe} is not writable")
    return p


def atomic_write(path, write, mode=None):
    """Call ``write(tmp_path)`` on a temporary file beside ``path``, then rename it over ``path``.

    ``mode``: the permission bits of the result; default ``0o666 & ~umask`` for a new file and
    the old file's bits when one is replaced. On any exception (including KeyboardInterrupt)
    the temporary file is removed and ``path`` is untouched. Returns ``path``.
    """
    path = os.fspath(path)
    d = os.path.dirname(os.path.abspath(path))
    os.makedirs(d, exist_ok=True)
    if mode is None:
        try:
            mode = os.stat(path).st_mode & 0o7777
        except FileNotFoundError:
            mode = 0o666 & ~_umask()
    fd, tmp = tempfile.mkstemp(dir=d, prefix=".peclet-tmp-", suffix=os.path.splitext(path)[1])
    os.close(fd)
    try:
        write(tmp)
        os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise
    return path


def jsonable(x):
    """``x`` with numpy scalars/arrays as Python numbers/lists and non-finite floats as None
    (strict JSON has no NaN or inf); dict keys become strings."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (np.integer, int)):
        return int(x)
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(float(x)) else None
    return x


def write_text(path, text, newline=None):
    """Write the string ``text`` to ``path`` atomically (``newline`` as for :func:`open`:
    ``""`` keeps the line endings ``text`` already has, as a CSV writer's). Returns ``path``."""
    def write(tmp):
        with open(tmp, "w", newline=newline) as fh:
            fh.write(text)
    return atomic_write(path, write)


def write_json(path, obj, indent=1, sort_keys=False):
    """Write :func:`jsonable` ``obj`` as JSON to ``path`` atomically (newline-terminated)."""
    def dump(tmp):
        with open(tmp, "w") as fh:
            json.dump(jsonable(obj), fh, indent=indent, sort_keys=sort_keys, allow_nan=False)
            fh.write("\n")
    return atomic_write(path, dump)


def atomic_directory(path, fill, prefix=".peclet-tmp-"):
    """Create the directory ``path`` whole: ``fill(tmp)`` writes into a temporary sibling
    directory (named ``prefix...``), which is then renamed to ``path``, so a reader sees either
    nothing or everything. Returns True if this call created ``path``, False if it existed
    already (another writer finished first; its contents are kept). On any exception the
    temporary directory is removed and ``path`` is untouched."""
    path = os.path.abspath(os.fspath(path))
    parent = os.path.dirname(path)
    os.makedirs(parent, exist_ok=True)
    tmp = tempfile.mkdtemp(prefix=prefix + os.path.basename(path) + "-", dir=parent)
    try:
        fill(tmp)
        os.chmod(tmp, 0o777 & ~_umask())
        try:
            os.rename(tmp, path)
        except OSError:
            if not os.path.isdir(path):
                raise
            shutil.rmtree(tmp, ignore_errors=True)
            return False
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return True


def remove_parts(directory, names=(), prefixes=()):
    """Remove from ``directory`` the entries a peclet format owns: those named in ``names`` and
    those whose names start with one of ``prefixes`` (whole, if directories); then the
    directory itself if that left it empty. Anything else in it stays, and so does it.
    A missing ``directory`` is fine."""
    d = os.fspath(directory)
    if not os.path.isdir(d):
        return
    for entry in os.listdir(d):
        if entry in names or entry.startswith(tuple(prefixes)):
            q = os.path.join(d, entry)
            if os.path.isdir(q) and not os.path.islink(q):
                shutil.rmtree(q)
            else:
                os.remove(q)
    if not os.listdir(d):
        os.rmdir(d)


def file_sha256(path):
    """The SHA-256 hex digest of the file at ``path`` (read in 1 MiB blocks)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()
