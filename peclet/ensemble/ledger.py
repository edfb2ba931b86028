"""The output directory is the ledger: ``OUT/<spec-id>/`` exists only complete.

Layout::

    OUT/ensemble.json          the ensemble manifest (spec.ensemble_manifest)
    OUT/<spec-id>/results.json the realization's figures, its spec and state hash
    OUT/<spec-id>/pack.npz     the frozen pack (peclet.packing.bed.freeze.save_pack)

A result is written into ``OUT/.peclet-part-<spec-id>-XXXX/`` and that directory is renamed to
``OUT/<spec-id>/`` in one ``os.rename``: a reader sees either nothing or the whole result, and
a crash leaves at most a ``.peclet-part-*`` directory, which the next run removes (only those:
nothing else in OUT is ever deleted or overwritten).
"""
from __future__ import annotations

import json
import os
import shutil


# the umask-respecting mode of a new directory, as atomic_write gives new files
from peclet.core.files import atomic_directory, check_writable_path, jsonable, write_json
from peclet.core.validation import PecletArgumentError

__all__ = ["Ledger", "jsonable"]

MANIFEST = "ensemble.json"
_PART = ".peclet-part-"


def _write_json(path, obj):
    return write_json(path, obj, sort_keys=True)


class Ledger:
    """``OUT`` opened for one ensemble. Construction only checks (cheaply, before any work, and
    writing nothing) that ``out`` can hold this ensemble: a writable directory path, empty or
    holding the SAME manifest; otherwise PecletArgumentError naming ``name``. :meth:`prepare`
    (called by the first :meth:`write`) creates it, writes the manifest and removes leftover
    ``.peclet-part-*`` directories of an interrupted run."""

    def __init__(self, out, manifest, name="out"):
        self.name = name
        self.out = os.path.abspath(os.fspath(out))
        self.manifest = jsonable(manifest)
        self._prepared = False
        if os.path.exists(self.out) and not os.path.isdir(self.out):
            raise PecletArgumentError(name, "a directory", os.fspath(out), "it is a file")
        path = os.path.join(self.out, MANIFEST)
        if not os.path.isdir(self.out):
            check_writable_path(path, name)
            return
        if not os.access(self.out, os.W_OK | os.X_OK):
            raise PecletArgumentError(name, "a writable directory", os.fspath(out))
        old = self._read_manifest(path)
        if old is None:
            foreign = [n for n in os.listdir(self.out) if not n.startswith(_PART)]
            if foreign:
                raise PecletArgumentError(
                    name, "an empty directory or one holding this ensemble", os.fspath(out),
                    f"it holds {len(foreign)} other entries, e.g. {sorted(foreign)[0]!r}, "
                    f"and no {MANIFEST}")
        elif old != self.manifest:
            fo, fn = old.get("fixed", {}), self.manifest["fixed"]
            diff = sorted(k for k in set(fo) | set(fn) if fo.get(k) != fn.get(k))
            if old.get("swept") != self.manifest["swept"]:
                diff.append("swept parameters")
            raise PecletArgumentError(
                name, "an empty directory or one holding this ensemble", os.fspath(out),
                f"it holds another ensemble's results (differs in: "
                f"{', '.join(diff) or 'format'})")

    def prepare(self):
        """Create OUT, write the manifest if absent, clear ``.peclet-part-*`` leftovers."""
        if self._prepared:
            return
        os.makedirs(self.out, exist_ok=True)
        if not os.path.exists(os.path.join(self.out, MANIFEST)):
            _write_json(os.path.join(self.out, MANIFEST), self.manifest)
        for n in os.listdir(self.out):
            if n.startswith(_PART):
                shutil.rmtree(os.path.join(self.out, n), ignore_errors=True)
        self._prepared = True

    def _read_manifest(self, path):
        if not os.path.exists(path):
            return None
        try:
            with open(path) as fh:
                m = json.load(fh)
        except (OSError, ValueError) as exc:
            raise PecletArgumentError(self.name, "a directory holding a readable "
                                      f"{MANIFEST}", self.out, str(exc)) from None
        if not isinstance(m, dict) or "fixed" not in m:
            raise PecletArgumentError(self.name, f"a directory whose {MANIFEST} is a peclet "
                                      "ensemble manifest", self.out)
        return m

    def path(self, spec):
        """``OUT/<spec-id>``."""
        return os.path.join(self.out, spec.id)

    def load(self, spec):
        """The finished result of ``spec`` (its results.json as a dict), or None."""
        p = os.path.join(self.path(spec), "results.json")
        try:
            with open(p) as fh:
                res = json.load(fh)
        except FileNotFoundError:
            return None
        if res.get("spec") != jsonable(spec.as_dict()):
            raise PecletArgumentError(self.name, "a ledger whose results match their spec ids",
                                      p, "results.json describes another spec")
        return res

    def write(self, spec, result, pack):
        """Write ``result`` (a dict) and ``pack`` (freeze.Pack) as ``OUT/<spec-id>/``, all at
        once (temp directory + rename). If another process finished the same spec first,
        keep its directory (the two are bitwise equal: a spec determines its result)."""
        from peclet.packing.bed.freeze import save_pack

        self.prepare()
        final = self.path(spec)

        def fill(tmp):
            save_pack(os.path.join(tmp, "pack.npz"), pack)
            _write_json(os.path.join(tmp, "results.json"), result)

        atomic_directory(final, fill, prefix=_PART)
        return final

    def write_json(self, name, obj):
        """Write ``OUT/name`` (a JSON summary) atomically."""
        self.prepare()
        return _write_json(os.path.join(self.out, name), obj)

