"""Writing files so that nothing a user saved is ever lost or half-written.

:func:`atomic_write` writes to a temporary file beside the target and renames it over, so a
crash or Ctrl-C leaves either the old file or the new one, never a torn one. New files get the
permissions ``open()`` would give (``0o666`` less the umask) instead of mkstemp's ``0o600``.
"""
from __future__ import annotations

import json
import math
import os
import shutil
import tempfile

import numpy as np

from .validation import PecletArgumentError

__all__ = ["atomic_write", "atomic_directory", "check_writable_path", "check_output_dir",
           "clear_outputs", "jsonable", "write_json", "write_text"]


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


def check_output_dir(out, outputs, overwrite, name="out", dirs=(), keep=()):
    """Check, before any work, that ``out`` can take a run writing ``outputs`` (names inside
    it; those in ``dirs`` are directories, the rest files). Returns ``(absolute path,
    previous)``: ``previous`` the names of an earlier run's outputs present (only possible with
    ``overwrite``; remove them with :func:`clear_outputs`). Paths in ``keep`` are not counted
    (e.g. the checkpoint a resumed run reads).

    Refused with :class:`PecletArgumentError` naming ``name``: a non-path, a file, a read-only
    directory (the mode bits too: root may write anywhere, but a directory made read-only was
    made so on purpose), an output name present with the wrong type, an earlier run's outputs
    without ``overwrite``, and a new path under a file or in an unwritable place.
    """
    if not isinstance(out, (str, os.PathLike)) or not os.fspath(out):
        raise PecletArgumentError(name, "a directory path", out)
    shown = os.fspath(out)
    p = os.path.abspath(shown)
    if not os.path.exists(p):
        check_writable_path(os.path.join(p, "probe"), name)
        return p, ()
    if not os.path.isdir(p):
        raise PecletArgumentError(name, "a directory", shown, "it is a file")
    if not os.access(p, os.W_OK | os.X_OK) or not os.stat(p).st_mode & 0o222:
        raise PecletArgumentError(name, "a writable directory", shown, "it is read-only")
    kept = {os.path.abspath(os.fspath(k)) for k in keep if k is not None}
    previous = []
    for f in outputs:
        q = os.path.join(p, f)
        if not os.path.lexists(q) or q in kept:
            continue
        if os.path.isdir(q) != (f in dirs):
            kind = "a directory" if os.path.isdir(q) else "a file"
            raise PecletArgumentError(name, "a directory where the run's outputs can be "
                                      "written", shown, f"{f} in it is {kind}")
        previous.append(f)
    if previous and not overwrite:
        listed = ", ".join(previous[:4]) + (", ..." if len(previous) > 4 else "")
        flag = "--overwrite" if name.startswith("--") else "overwrite=True"
        raise PecletArgumentError(name, "a new or empty directory", shown,
                                  f"it holds an earlier run's files ({listed}); pass {flag} "
                                  "to replace them")
    return p, tuple(previous)


def clear_outputs(out, previous):
    """Remove the earlier run's outputs ``previous`` (names returned by
    :func:`check_output_dir`) from ``out``; nothing else is touched."""
    for f in previous:
        q = os.path.join(out, f)
        if os.path.isdir(q) and not os.path.islink(q):
            shutil.rmtree(q)
        elif os.path.lexists(q):
            os.remove(q)


def file_sha256(path):
    """The SHA-256 hex digest of the file at ``path`` (read in 1 MiB blocks)."""
    import hashlib

    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()
