"""Writing files so that nothing a user saved is ever lost or half-written.

:func:`atomic_write` writes to a temporary file beside the target and renames it over, so a
crash or Ctrl-C leaves either the old file or the new one, never a torn one. New files get the
permissions ``open()`` would give (``0o666`` less the umask) instead of mkstemp's ``0o600``.
"""
from __future__ import annotations

import os
import tempfile

from .validation import PecletArgumentError

__all__ = ["atomic_write", "check_writable_path"]


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
