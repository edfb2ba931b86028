"""Checkpoints of a pack run: resume bit for bit, never a torn file.

A checkpoint directory holds

- ``spec.json``: the run's inputs (``PackResult.spec``), written once;
- ``element.npz``: the element as the run uses it (tree, shell, mass, inertia, ...), written
  once, so a resume does not rebuild (re-measure) the element;
- ``ckpt-<step>/``: ``sim.npz`` (``Simulation.save``: bitwise state, shapes, walls, warm-start
  cache), ``state.json`` (the protocol's :class:`~peclet.packing.protocols.RunState`: phase,
  step, inserted count, calm steps, the numpy generator's state) and ``ke.npy`` (the history);
- ``checkpoint.json``: names the latest complete ``ckpt-<step>``.

Every part carries the run's id (a random 128-bit hex drawn by :func:`init`): ``spec.json``
(``run``), ``element.npz`` (``run_id``), ``checkpoint.json`` (``run``) and each
``ckpt-<step>/run.json`` (``run``, with the SHA-256 of that step's ``sim.npz``, ``state.json``
and ``ke.npy``). :func:`read` refuses parts whose ids disagree or whose files are not the ones
hashed (a checkpoint assembled from two runs would resume into a wrong bed); a checkpoint
written before run ids (no part carries one) is read as before.

A checkpoint is written into a temporary directory and renamed into place; only then is
``checkpoint.json`` replaced (atomically) and the older one removed. An interrupt (Ctrl-C) at
any moment leaves ``checkpoint.json`` naming a complete checkpoint.
"""
from __future__ import annotations

import json
import os
import shutil
import uuid

import numpy as np

from peclet.core.files import (atomic_directory, atomic_write, file_sha256, remove_parts,
                               write_json)
from peclet.core.validation import PecletArgumentError

__all__ = ["POINTER", "is_checkpoint", "init", "write", "read", "remove"]

POINTER = "checkpoint.json"
_KIND = "peclet pack checkpoint"
_RUN = "run.json"
_HASHED = ("sim.npz", "state.json", "ke.npy")


def run_id(path):
    """The run id of the checkpoint at ``path`` (``spec.json``'s), None if it has none."""
    with open(os.path.join(os.fspath(path), "spec.json")) as fh:
        return json.load(fh).get("run")


def is_checkpoint(path):
    """Whether ``path`` is a directory holding a pack checkpoint's pointer and spec."""
    p = os.fspath(path)
    return os.path.isfile(os.path.join(p, POINTER)) and os.path.isfile(os.path.join(p, "spec.json"))


def remove(path):
    """Remove the checkpoint at ``path``: its own parts only (a file of the user's kept in the
    same directory stays, and with it the directory)."""
    remove_parts(path, names=(POINTER, "spec.json", "element.npz"),
                 prefixes=("ckpt-", ".tmp-ckpt-"))


def init(path, spec, element):
    """Start a checkpoint directory: ``spec.json`` and ``element.npz`` (dict of arrays).
    Refuses a directory that already holds a checkpoint (resume it instead)."""
    p = os.fspath(path)
    if is_checkpoint(p):
        raise PecletArgumentError("checkpoint_dir", "a directory without a checkpoint (resume "
                                  "an existing one with peclet.packing.resume)", p)
    os.makedirs(p, exist_ok=True)
    run = uuid.uuid4().hex

    def w(tmp):
        with open(tmp, "wb") as fh:
            np.savez(fh, run_id=np.array(run), **element)
    atomic_write(os.path.join(p, "element.npz"), w)
    write_json(os.path.join(p, "spec.json"), dict(kind=_KIND, run=run, spec=spec))


def write(path, sim, state):
    """Write the checkpoint of ``sim`` and ``state`` (a RunState) at ``state.step``."""
    p = os.fspath(path)
    name = f"ckpt-{state.step:09d}"
    final = os.path.join(p, name)
    run = run_id(p)
    for old in os.listdir(p):          # debris of an interrupted write
        if old.startswith(".tmp-ckpt-"):
            shutil.rmtree(os.path.join(p, old), ignore_errors=True)
    if not os.path.isdir(final):
        def fill(tmp):
            sim.save(os.path.join(tmp, "sim.npz"))
            write_json(os.path.join(tmp, "state.json"), state.to_json())
            np.save(os.path.join(tmp, "ke.npy"), np.asarray(state.ke, dtype=np.float64))
            write_json(os.path.join(tmp, _RUN), dict(
                kind=_KIND, run=run,
                sha256={f: file_sha256(os.path.join(tmp, f)) for f in _HASHED}))

        atomic_directory(final, fill, prefix=".tmp-ckpt-")
    write_json(os.path.join(p, POINTER), dict(kind=_KIND, run=run, latest=name,
                                               step=state.step))
    for old in os.listdir(p):
        if old.startswith("ckpt-") and old != name:
            shutil.rmtree(os.path.join(p, old), ignore_errors=True)


def read(path, name="checkpoint_dir"):
    """(spec, element arrays dict, Simulation or None, RunState dict or None, ke array) of the
    checkpoint at ``path``; sim/state are None when no step was checkpointed yet.
    PecletArgumentError naming ``name`` if ``path`` is not a checkpoint."""
    from peclet.dem import Simulation

    p = os.fspath(path)
    bad = PecletArgumentError(name, "a peclet pack checkpoint directory (checkpoint.json, "
                              "spec.json, element.npz)", p)
    if not is_checkpoint(p):
        raise bad
    try:
        with open(os.path.join(p, "spec.json")) as fh:
            meta = json.load(fh)
        with open(os.path.join(p, POINTER)) as fh:
            ptr = json.load(fh)
        if meta.get("kind") != _KIND or ptr.get("kind") != _KIND:
            raise ValueError
        with np.load(os.path.join(p, "element.npz"), allow_pickle=False) as z:
            element = {k: z[k] for k in z.files}
        elem_run = element.pop("run_id", None)
        ids = {"spec.json": meta.get("run"), POINTER: ptr.get("run"),
               "element.npz": None if elem_run is None else str(elem_run)}
        latest = ptr.get("latest")
        d = None if latest is None else os.path.join(p, os.path.basename(latest))
        step_run = None
        if d is not None and os.path.isfile(os.path.join(d, _RUN)):
            with open(os.path.join(d, _RUN)) as fh:
                step_run = json.load(fh)
            ids[f"{os.path.basename(d)}/{_RUN}"] = step_run.get("run")
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        raise bad from None
    _check_parts(name, p, ids, d, step_run)
    try:
        if latest is None:
            return meta["spec"], element, None, None, np.zeros(0)
        sim = Simulation.load(os.path.join(d, "sim.npz"))
        with open(os.path.join(d, "state.json")) as fh:
            state = json.load(fh)
        ke = np.load(os.path.join(d, "ke.npy"), allow_pickle=False)
    except (OSError, ValueError, KeyError, TypeError):
        raise bad from None
    return meta["spec"], element, sim, state, ke


def _check_parts(name, p, ids, d, step_run):
    """Refuse a checkpoint whose parts carry different run ids (or, some of them, none), or
    whose step files are not the ones its ``run.json`` hashed."""
    what = "a checkpoint whose parts all come from one run"
    given = {k: v for k, v in ids.items() if v is not None}
    if given:                                   # else written before run ids: no id to check
        lost = d is not None and step_run is None
        if len(set(given.values())) > 1 or len(given) != len(ids) or lost:
            parts = ", ".join(f"{k}: {v[:8] if v else 'no run id'}" for k, v in ids.items())
            if lost:
                parts += f", {os.path.basename(d)}/{_RUN}: missing"
            raise PecletArgumentError(name, what, p, f"mixed parts ({parts})")
    if d is not None and step_run is not None:
        for f, h in (step_run.get("sha256") or {}).items():
            fp = os.path.join(d, f)
            if not os.path.isfile(fp) or file_sha256(fp) != h:
                raise PecletArgumentError(name, what, p, f"{os.path.basename(d)}/{f} is not "
                                          "the file its run.json hashed (from another run?)")


def mark_started(path):
    """Point ``checkpoint.json`` at no step yet (a run that starts from its beginning)."""
    p = os.fspath(path)
    write_json(os.path.join(p, POINTER), dict(kind=_KIND, run=run_id(p), latest=None, step=0))
