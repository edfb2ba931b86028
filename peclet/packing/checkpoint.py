"""Checkpoints of a pack run: resume bit for bit, never a torn file.

A checkpoint directory holds

- ``spec.json``: the run's inputs (``PackResult.spec``), written once;
- ``element.npz``: the element as the run uses it (tree, shell, mass, inertia, ...), written
  once, so a resume does not rebuild (re-measure) the element;
- ``ckpt-<step>/``: ``sim.npz`` (``Simulation.save``: bitwise state, shapes, walls, warm-start
  cache), ``state.json`` (the protocol's :class:`~peclet.packing.protocols.RunState`: phase,
  step, inserted count, calm steps, the numpy generator's state) and ``ke.npy`` (the history);
- ``checkpoint.json``: names the latest complete ``ckpt-<step>``.

A checkpoint is written into a temporary directory and renamed into place; only then is
``checkpoint.json`` replaced (atomically) and the older one removed. An interrupt (Ctrl-C) at
any moment leaves ``checkpoint.json`` naming a complete checkpoint.
"""
from __future__ import annotations

import json
import os
import shutil

import numpy as np

from peclet.core.files import atomic_directory, atomic_write, write_json
from peclet.core.validation import PecletArgumentError

__all__ = ["POINTER", "is_checkpoint", "init", "write", "read"]

POINTER = "checkpoint.json"
_KIND = "peclet pack checkpoint"


def is_checkpoint(path):
    """Whether ``path`` is a directory holding a pack checkpoint's pointer and spec."""
    p = os.fspath(path)
    return os.path.isfile(os.path.join(p, POINTER)) and os.path.isfile(os.path.join(p, "spec.json"))


def init(path, spec, element):
    """Start a checkpoint directory: ``spec.json`` and ``element.npz`` (dict of arrays).
    Refuses a directory that already holds a checkpoint (resume it instead)."""
    p = os.fspath(path)
    if is_checkpoint(p):
        raise PecletArgumentError("checkpoint_dir", "a directory without a checkpoint (resume "
                                  "an existing one with peclet.packing.resume)", p)
    os.makedirs(p, exist_ok=True)

    def w(tmp):
        with open(tmp, "wb") as fh:
            np.savez(fh, **element)
    atomic_write(os.path.join(p, "element.npz"), w)
    write_json(os.path.join(p, "spec.json"), dict(kind=_KIND, spec=spec))


def write(path, sim, state):
    """Write the checkpoint of ``sim`` and ``state`` (a RunState) at ``state.step``."""
    p = os.fspath(path)
    name = f"ckpt-{state.step:09d}"
    final = os.path.join(p, name)
    for old in os.listdir(p):          # debris of an interrupted write
        if old.startswith(".tmp-ckpt-"):
            shutil.rmtree(os.path.join(p, old), ignore_errors=True)
    if not os.path.isdir(final):
        def fill(tmp):
            sim.save(os.path.join(tmp, "sim.npz"))
            write_json(os.path.join(tmp, "state.json"), state.to_json())
            np.save(os.path.join(tmp, "ke.npy"), np.asarray(state.ke, dtype=np.float64))

        atomic_directory(final, fill, prefix=".tmp-ckpt-")
    write_json(os.path.join(p, POINTER), dict(kind=_KIND, latest=name, step=state.step))
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
        latest = ptr.get("latest")
        if latest is None:
            return meta["spec"], element, None, None, np.zeros(0)
        d = os.path.join(p, os.path.basename(latest))
        sim = Simulation.load(os.path.join(d, "sim.npz"))
        with open(os.path.join(d, "state.json")) as fh:
            state = json.load(fh)
        ke = np.load(os.path.join(d, "ke.npy"), allow_pickle=False)
    except (OSError, ValueError, KeyError, TypeError):
        raise bad from None
    return meta["spec"], element, sim, state, ke


def mark_started(path):
    """Point ``checkpoint.json`` at no step yet (a run that starts from its beginning)."""
    write_json(os.path.join(os.fspath(path), POINTER), dict(kind=_KIND, latest=None, step=0))
