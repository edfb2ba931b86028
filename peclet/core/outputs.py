"""Which files in an output directory a peclet run wrote, so that a rerun removes only those.

A command writes its outputs under a fixed set of names in ``--out`` (files such as
``results.json``, directories such as ``frames/`` or ``checkpoint/``). The user may keep their own
files in the same directory, even inside those sub-directories. So ownership is recorded, not
guessed from names: every run keeps a manifest, :data:`MANIFEST`, beside its outputs, listing each
file it wrote with its size, modification time (ns) and SHA-256.

The life of a run (:func:`check_output_dir`, then ``with recording(...)``):

1. :func:`check_output_dir`, before any work: every file at or under the run's names must be one
   the manifest lists and that is unchanged since (same size and mtime, or the same SHA-256, so a
   ``cp -r`` of the directory keeps its ownership). Anything else there is *in the way*: refused,
   naming the file, with or without ``overwrite``, because the run would write beside or over
   it. Without ``overwrite``, files of an earlier run are refused too.
2. :func:`recording` on entry snapshots what lies under the run's names and writes the manifest
   with a ``running`` section holding that snapshot, so even a run killed with SIGKILL can be
   recognised later: whatever differs from the snapshot was written by it.
3. :func:`clear_outputs` removes exactly the earlier run's own files (never a directory tree
   wholesale) and the directories that become empty.
4. :func:`recording` on exit (any exit: success, exception, Ctrl-C) lists the files that are new or
   changed since the snapshot, keeps the earlier entries that still hold, drops ``running`` and
   replaces the manifest atomically.

A directory written by an older peclet has no manifest: its files count as the user's, so a rerun
is refused naming one of them (delete them by hand once); nothing is removed on a guess.
"""
from __future__ import annotations

import contextlib
import json
import os
import time

from .files import check_writable_path, file_sha256, write_json
from .validation import PecletArgumentError

__all__ = ["MANIFEST", "check_output_dir", "clear_outputs", "recording", "owned_files"]

MANIFEST = ".peclet-outputs.json"
_KIND = "peclet-outputs"


def _stat_key(path):
    """(size, mtime_ns, inode) of the file or link at ``path`` itself (links not followed)."""
    st = os.lstat(path)
    return [st.st_size, st.st_mtime_ns, st.st_ino]


def _walk(out, names):
    """Relative paths (``/``-separated) of every file or link at or under ``names`` in ``out``;
    links to directories are not followed."""
    found = []
    for name in names:
        top = os.path.join(out, name)
        if os.path.islink(top) or os.path.isfile(top):
            found.append(name)
        elif os.path.isdir(top):
            for root, dnames, fnames in os.walk(top):
                for d in list(dnames):
                    if os.path.islink(os.path.join(root, d)):
                        fnames.append(d)
                        dnames.remove(d)
                for f in fnames:
                    found.append(os.path.relpath(os.path.join(root, f), out).replace(os.sep, "/"))
    return sorted(found)


def _read_manifest(out):
    """The manifest in ``out`` as a dict, or an empty one if there is none or it is not ours
    (unreadable or foreign: then nothing counts as peclet's, the safe side)."""
    empty = dict(kind=_KIND, files={}, running=None)
    try:
        with open(os.path.join(out, MANIFEST)) as fh:
            m = json.load(fh)
    except (OSError, ValueError):
        return empty
    if not isinstance(m, dict) or m.get("kind") != _KIND or not isinstance(m.get("files"), dict):
        return empty
    return dict(kind=_KIND, files=m["files"], running=m.get("running"))


def _write_manifest(out, manifest):
    write_json(os.path.join(out, MANIFEST), manifest, indent=1, sort_keys=True)


def _entry(path, sha=None):
    size, mtime, _ = _stat_key(path)
    if os.path.islink(path):
        return dict(size=size, mtime_ns=mtime, link=os.readlink(path))
    return dict(size=size, mtime_ns=mtime, sha256=sha or file_sha256(path))


def _entry_holds(path, entry):
    """Whether the file at ``path`` is still the one ``entry`` describes."""
    if not os.path.lexists(path) or not isinstance(entry, dict):
        return False
    if os.path.islink(path):
        return entry.get("link") == os.readlink(path)
    size, mtime, _ = _stat_key(path)
    if size != entry.get("size") or "sha256" not in entry:
        return False
    return mtime == entry.get("mtime_ns") or file_sha256(path) == entry["sha256"]


def owned_files(out):
    """{relative path: manifest entry or None} of the files in ``out`` that peclet wrote: those
    the manifest lists and that still hold, and those an interrupted run (the manifest's
    ``running`` section) wrote or changed under its names (entry None: not hashed yet)."""
    m = _read_manifest(out)
    owned = {rel: e for rel, e in m["files"].items()
             if _entry_holds(os.path.join(out, rel), e)}
    run = m["running"]
    if isinstance(run, dict) and isinstance(run.get("before"), dict):
        before = run["before"]
        for rel in _walk(out, [n for n in run.get("names", []) if isinstance(n, str)]):
            if rel not in owned and before.get(rel) != _stat_key(os.path.join(out, rel)):
                owned[rel] = None
    return owned


def check_output_dir(out, outputs, overwrite, name="out", dirs=(), keep=()):
    """Check, before any work, that ``out`` can take a run writing ``outputs`` (names inside
    it; those in ``dirs`` are directories, the rest files). Returns ``(absolute path,
    previous)``: ``previous`` the names under which an earlier run's own files lie (only
    possible with ``overwrite``; remove them with :func:`clear_outputs`). Paths in ``keep`` are
    not looked into (e.g. the checkpoint a resumed run reads).

    Refused with :class:`PecletArgumentError` naming ``name``: a non-path, a file, a read-only
    directory (the mode bits too: root may write anywhere, but a directory made read-only was
    made so on purpose), an output name present with the wrong type, a file at or under the
    run's names that no earlier peclet run wrote (named in the message; with or without
    ``overwrite``), an earlier run's outputs without ``overwrite``, and a new path under a file
    or in an unwritable place.
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
    present = []
    for f in outputs:
        q = os.path.join(p, f)
        if not os.path.lexists(q) or q in kept:
            continue
        if os.path.isdir(q) != (f in dirs) or (f in dirs and os.path.islink(q)):
            kind = ("a link" if os.path.islink(q) else
                    "a directory" if os.path.isdir(q) else "a file")
            raise PecletArgumentError(name, "a directory where the run's outputs can be "
                                      "written", shown, f"{f} in it is {kind}")
        present.append(f)
    owned = owned_files(p) if present else {}
    previous = []
    for f in present:
        files = _walk(p, [f])
        foreign = [rel for rel in files if rel not in owned]
        if foreign:
            raise PecletArgumentError(
                name, "a directory whose files in the run's way are peclet's own", shown,
                f"{foreign[0]} is not a file an earlier peclet run wrote here (no {MANIFEST} "
                f"lists it as written by one), and the run writes {f}"
                f"{'/' if f in dirs else ''}: move it away or choose another {name}; "
                "nothing was removed")
        if files:
            previous.append(f)
    if previous and not overwrite:
        listed = ", ".join(previous[:4]) + (", ..." if len(previous) > 4 else "")
        flag = "--overwrite" if name.startswith("--") else "overwrite=True"
        raise PecletArgumentError(name, "a new or empty directory", shown,
                                  f"it holds an earlier run's files ({listed}); pass {flag} "
                                  "to replace them")
    return p, tuple(previous)


def clear_outputs(out, previous):
    """Remove the files an earlier peclet run wrote under the names ``previous`` (as returned
    by :func:`check_output_dir`) from ``out``, then the directories under them left empty.
    Any other file stays where it is, and so does the directory holding it."""
    if not previous:
        return
    owned = owned_files(out)
    removed = []
    for rel in _walk(out, previous):
        if rel in owned:
            os.remove(os.path.join(out, rel))
            removed.append(rel)
    for f in previous:
        top = os.path.join(out, f)
        if os.path.isdir(top) and not os.path.islink(top):
            for root, _, _ in sorted(os.walk(top), key=lambda w: -len(w[0])):
                with contextlib.suppress(OSError):     # not empty: something else is there
                    os.rmdir(root)
    if removed and os.path.isdir(out):
        m = _read_manifest(out)
        m["files"] = {k: v for k, v in m["files"].items() if k not in set(removed)}
        _write_manifest(out, m)


@contextlib.contextmanager
def recording(out, outputs):
    """Record in ``out``'s manifest every file the enclosed run writes under the names
    ``outputs`` (files or directories). ``out`` is created if needed. The manifest is written
    on entry (with the snapshot that lets a killed run be recognised) and on every exit."""
    out = os.path.abspath(os.fspath(out))
    os.makedirs(out, exist_ok=True)
    names = sorted(set(outputs))
    # what earlier runs own, an interrupted one's files included, is settled (hashed) first:
    # the ``running`` section that recognised them is about to describe this run instead
    files = {rel: entry or _entry(os.path.join(out, rel))
             for rel, entry in owned_files(out).items()}
    before = {rel: _stat_key(os.path.join(out, rel)) for rel in _walk(out, names)}
    _write_manifest(out, dict(kind=_KIND, files=files, running=dict(
        names=names, before=before, pid=os.getpid(),
        started=time.strftime("%Y-%m-%dT%H:%M:%S%z"))))
    try:
        yield out
    finally:
        kept = {rel: e for rel, e in files.items() if _entry_holds(os.path.join(out, rel), e)}
        for rel in _walk(out, names):
            path = os.path.join(out, rel)
            if before.get(rel) != _stat_key(path):    # written or rewritten by this run
                kept[rel] = _entry(path)
        _write_manifest(out, dict(kind=_KIND, files=kept, running=None))
