"""Run checkpoints (``pack``/``resume`` and the drum): resume bit for bit, never a torn file.

One on-disk format for every run kind. A checkpoint directory holds

- ``spec.json``: the run's kind (e.g. ``"peclet pack checkpoint"``), id and inputs, written
  once;
- ``ckpt-<step>/``: the run's state at that step, written by the run (a pack: ``sim.npz``
  (``Simulation.save``: bitwise state, shapes, walls, warm-start cache), ``state.json`` (the
  protocol's :class:`~peclet.packing.bed.protocols.RunState`: phase, step, inserted count, calm
  steps, the numpy generator's state) and ``ke.npy`` (the history); a drum: ``sim.npz``,
  ``state.json`` (the loop's step, clock, angle, samples) and ``arrays.npz`` (radii, frames)),
  plus ``run.json`` (kind, run id and the SHA-256 of each of those files);
- ``checkpoint.json``: names the latest complete ``ckpt-<step>`` (kind, run id, step);
- a pack also keeps ``element.npz`` (the element as the run uses it: tree, shell, mass,
  inertia, ...; written once with the run id, so a resume does not re-measure the element).

Every part carries the run's id (a random 128-bit hex drawn when the run starts); a reader
refuses parts whose ids disagree or step files that are not the ones hashed (a checkpoint
assembled from two runs would resume into a wrong state). A pack checkpoint written before run
ids (no part carries one) is read as before; the drum's earlier format (``step-<k>/`` with the
hashes in its ``state.json``, the spec in ``checkpoint.json``) is read by
:mod:`peclet.packing.experiments.drum`, and a run resumed from it goes on in this one.

A step is written into a temporary directory and renamed into place
(:func:`~peclet.core.files.atomic_directory`); only then is ``checkpoint.json`` replaced
(atomically) and the older step removed. An interrupt (Ctrl-C) at any moment leaves
``checkpoint.json`` naming a complete step.
"""
from __future__ import annotations

import json
import os
import shutil
import uuid

import numpy as np

from peclet.core.files import (atomic_directory, atomic_write, file_sha256, remove_parts,
                               write_json)
from peclet.core.validation import PecletArgumentError, check_int

__all__ = ["POINTER", "SPEC", "RUN", "CHECKPOINT", "new_run", "start", "write_step",
           "step_ids", "bad_hashes", "check_every", "find", "write_loop_step",
           "read_loop_step", "is_checkpoint", "init", "write", "read", "remove"]

POINTER = "checkpoint.json"
SPEC = "spec.json"
#: A turning-wall run's checkpoint directory inside its output directory.
CHECKPOINT = "checkpoint"
RUN = "run.json"
#: Step directories (``ckpt-<step>``) and the temporary ones being written.
STEP_PREFIX = "ckpt-"
TMP_PREFIX = ".tmp-ckpt-"
#: The drum's earlier step directories (removed with the rest of a checkpoint).
_LEGACY_PREFIXES = ("step-", ".tmp-step-")
_KIND = "peclet pack checkpoint"
_RUN = RUN
_HASHED = ("sim.npz", "state.json", "ke.npy")


# ---------------------------------------------------------------------------- any run kind
def new_run():
    """A fresh run id (128-bit hex)."""
    return uuid.uuid4().hex


def start(path, kind, spec, run):
    """Start the checkpoint directory ``path`` of run ``run``: ``spec.json`` (kind, run id,
    ``spec``: the run's inputs, JSON-able)."""
    p = os.fspath(path)
    os.makedirs(p, exist_ok=True)
    write_json(os.path.join(p, SPEC), dict(kind=kind, run=run, spec=spec))


def write_step(path, kind, run, step, fill, hashed, replace_existing=False):
    """Write step ``step`` of run ``run`` into ``path``: ``fill(tmp)`` writes the step's files
    (``hashed``: their names) into a temporary directory, ``run.json`` (kind, run id, their
    SHA-256) is added and the directory renamed to ``ckpt-<step>``; then ``checkpoint.json``
    points at it and the older steps are removed. An existing ``ckpt-<step>`` is kept (it is
    complete) unless ``replace_existing``."""
    p = os.fspath(path)
    name = f"{STEP_PREFIX}{step:09d}"
    final = os.path.join(p, name)
    for old in os.listdir(p):          # debris of an interrupted write
        if old.startswith((TMP_PREFIX, _LEGACY_PREFIXES[1])):
            shutil.rmtree(os.path.join(p, old), ignore_errors=True)
    if replace_existing and os.path.isdir(final):
        shutil.rmtree(final)
    if not os.path.isdir(final):
        def fill_and_hash(tmp):
            fill(tmp)
            write_json(os.path.join(tmp, RUN), dict(
                kind=kind, run=run,
                sha256={f: file_sha256(os.path.join(tmp, f)) for f in hashed}))

        atomic_directory(final, fill_and_hash, prefix=TMP_PREFIX)
    write_json(os.path.join(p, POINTER), dict(kind=kind, run=run, latest=name, step=step))
    for old in os.listdir(p):
        if old.startswith((STEP_PREFIX, _LEGACY_PREFIXES[0])) and old != name:
            shutil.rmtree(os.path.join(p, old), ignore_errors=True)
    return final


def step_ids(d):
    """``run.json`` of the step directory ``d`` (dict), None if it has none."""
    if not os.path.isfile(os.path.join(d, RUN)):
        return None
    with open(os.path.join(d, RUN)) as fh:
        return json.load(fh)


def bad_hashes(d, sha256):
    """The first file of step directory ``d`` that is missing or not the one ``sha256`` (name
    -> hex) hashed, None if all are."""
    for f, h in (sha256 or {}).items():
        fp = os.path.join(d, f)
        if not os.path.isfile(fp) or file_sha256(fp) != h:
            return f
    return None


# ---------------------------------------------------------------------------- loop runs
# A run that turns a wall phase by phase (the drum, the stirred column) keeps, per step,
# ``sim.npz``, ``arrays.npz`` (its arrays: radii, frames, ...) and ``state.json`` (its loop's
# step, clock, angle, samples; NaN kept), in ``OUT/checkpoint/``.
def check_every(out, every, max_steps):
    """(checkpoint_every or None, max_steps or None) checked: ``every`` needs ``out``, 0 is
    none; ``max_steps`` needs checkpoints (a stopped run resumes from its checkpoint)."""
    if every is not None:
        every = check_int("checkpoint_every", every, 0, 10 ** 9) or None    # 0: none
    if every is not None:
        if out is None:
            raise PecletArgumentError("out", "a directory when checkpoint_every is given",
                                      None)
    if max_steps is not None:
        max_steps = check_int("max_steps", max_steps, 0, 10 ** 12)
        if every is None:
            raise PecletArgumentError("checkpoint_every", "given with max_steps (a stopped "
                                      "run resumes from its checkpoint)", None)
    return every, max_steps


def find(path, name, what):
    """The checkpoint directory of a run at ``path`` (its output directory or the
    ``checkpoint/`` in it); PecletArgumentError naming ``name``, saying it must be ``what``,
    if there is none."""
    if not isinstance(path, (str, os.PathLike)) or not os.fspath(path):
        raise PecletArgumentError(name, what, path)
    p = os.path.abspath(os.fspath(path))
    if not os.path.exists(p):
        raise PecletArgumentError(name, what, os.fspath(path), "it does not exist")
    if not os.path.isdir(p):
        raise PecletArgumentError(name, what, os.fspath(path), "it is a file")
    for c in (os.path.join(p, CHECKPOINT), p):
        if os.path.isfile(os.path.join(c, POINTER)):
            return c
    done = os.path.isfile(os.path.join(p, "results.json"))
    raise PecletArgumentError(name, what, os.fspath(path),
                              "a finished run (its checkpoint is removed at the end unless "
                              "--keep-checkpoint)" if done else f"no {CHECKPOINT}/{POINTER} "
                              "in it")


def _spec_run(path):
    """The run id in the ``spec.json`` at ``path`` (None if missing or unreadable)."""
    try:
        with open(path) as fh:
            meta = json.load(fh)
    except (OSError, ValueError):
        return None
    return meta.get("run") if isinstance(meta, dict) else None


def write_loop_step(cdir, kind, spec, run, step, sim, state, arrays):
    """Write step ``step`` of the loop run ``run`` into ``cdir`` (:func:`write_step`):
    ``sim.npz`` (``sim.save``), ``arrays.npz`` (dict of arrays) and ``state.json`` (``state``
    with the kind, run id and step; NaN kept); ``spec.json`` (``spec``, JSON-able) first if
    the directory has none of this run's."""
    os.makedirs(cdir, exist_ok=True)
    if _spec_run(os.path.join(cdir, SPEC)) != run:
        start(cdir, kind, spec, run)
    doc = dict(kind=kind, run=run, k=step, **state)

    def fill(tmp):
        sim.save(os.path.join(tmp, "sim.npz"))

        def w(path):
            with open(path, "wb") as fh:
                np.savez(fh, **arrays)
        atomic_write(os.path.join(tmp, "arrays.npz"), w)

        def j(path):                       # NaN kept (e.g. an angle without a surface)
            with open(path, "w") as fh:
                json.dump(doc, fh, allow_nan=True)
        atomic_write(os.path.join(tmp, "state.json"), j)

    write_step(cdir, kind, run, step, fill, ("sim.npz", "arrays.npz", "state.json"),
               replace_existing=True)


def read_loop_step(cdir, kind, label, name, what, make_spec):
    """(spec, state dict, arrays dict, path of ``sim.npz``) of the latest step of the loop
    run checkpointed in ``cdir`` (``make_spec(dict)`` builds the spec); a pointer of another
    kind (``label``: the run's name in the message), a missing or damaged part, parts of two
    runs or a file that is not the one hashed: PecletArgumentError naming ``name``, saying it
    must be ``what``. Reads the drum's earlier format too (the spec in the pointer, the hashes
    in ``state.json``)."""
    def bad(detail):
        return PecletArgumentError(name, what, cdir, detail)
    try:
        with open(os.path.join(cdir, POINTER)) as fh:
            ptr = json.load(fh)
    except (OSError, ValueError):
        raise bad(f"{POINTER} is not readable JSON") from None
    if not isinstance(ptr, dict) or ptr.get("kind") != kind:
        raise bad(f"{POINTER} is not a {label} checkpoint's (kind "
                  f"{ptr.get('kind') if isinstance(ptr, dict) else None!r})")
    legacy = "spec" in ptr                 # the drum's earlier format: the spec in the pointer
    try:
        if legacy:
            meta = dict(run=ptr.get("run"), spec=ptr["spec"])
        else:
            with open(os.path.join(cdir, SPEC)) as fh:
                meta = json.load(fh)
        spec = make_spec(meta["spec"])
        d = os.path.join(cdir, os.path.basename(str(ptr["latest"])))
        with open(os.path.join(d, "state.json")) as fh:
            st = json.load(fh)
        with np.load(os.path.join(d, "arrays.npz"), allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        step_run = st if legacy else step_ids(d)
        if step_run is None:
            raise OSError(f"{os.path.basename(d)}/{RUN} is missing")
    except (OSError, ValueError, KeyError, TypeError, PecletArgumentError) as exc:
        raise bad(f"an incomplete or damaged checkpoint: {exc}") from None
    runs = {ptr.get("run"), meta.get("run"), st.get("run"), step_run.get("run")}
    if st.get("kind") != kind or step_run.get("kind") != kind or len(runs) != 1 or \
            st.get("k") != ptr.get("step"):
        raise bad(f"{os.path.basename(d)} is not the step {POINTER} names (parts of two runs)")
    f = bad_hashes(d, step_run.get("sha256"))
    if f is not None:
        raise bad(f"{os.path.basename(d)}/{f} is not the file its "
                  f"{'state.json' if legacy else RUN} hashed")
    return spec, st, arrays, os.path.join(d, "sim.npz")


# ---------------------------------------------------------------------------- pack runs


def run_id(path):
    """The run id of the checkpoint at ``path`` (``spec.json``'s), None if it has none."""
    with open(os.path.join(os.fspath(path), SPEC)) as fh:
        return json.load(fh).get("run")


def is_checkpoint(path):
    """Whether ``path`` is a directory holding a pack checkpoint's pointer and spec."""
    p = os.fspath(path)
    return os.path.isfile(os.path.join(p, POINTER)) and os.path.isfile(os.path.join(p, "spec.json"))


def remove(path, own=("element.npz",)):
    """Remove the checkpoint at ``path`` (any run kind's; ``own``: the kind's files besides the
    common ones, a pack's ``element.npz`` by default): its own parts only (a file of the
    user's kept in the same directory stays, and with it the directory)."""
    remove_parts(path, names=(POINTER, SPEC) + tuple(own),
                 prefixes=(STEP_PREFIX, TMP_PREFIX) + _LEGACY_PREFIXES)


def init(path, spec, element):
    """Start a checkpoint directory: ``spec.json`` and ``element.npz`` (dict of arrays).
    Refuses a directory that already holds a checkpoint (resume it instead)."""
    p = os.fspath(path)
    if is_checkpoint(p):
        raise PecletArgumentError("checkpoint_dir", "a directory without a checkpoint (resume "
                                  "an existing one with peclet.packing.resume)", p)
    os.makedirs(p, exist_ok=True)
    run = new_run()

    def w(tmp):
        with open(tmp, "wb") as fh:
            np.savez(fh, run_id=np.array(run), **element)
    atomic_write(os.path.join(p, "element.npz"), w)
    start(p, _KIND, spec, run)


def write(path, sim, state):
    """Write the checkpoint of ``sim`` and ``state`` (a RunState) at ``state.step``."""
    def fill(tmp):
        sim.save(os.path.join(tmp, "sim.npz"))
        write_json(os.path.join(tmp, "state.json"), state.to_json())
        np.save(os.path.join(tmp, "ke.npy"), np.asarray(state.ke, dtype=np.float64))

    write_step(path, _KIND, run_id(path), state.step, fill, _HASHED)


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
        step_run = None if d is None else step_ids(d)
        if step_run is not None:
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
        f = bad_hashes(d, step_run.get("sha256"))
        if f is not None:
            raise PecletArgumentError(name, what, p, f"{os.path.basename(d)}/{f} is not "
                                      "the file its run.json hashed (from another run?)")


def mark_started(path):
    """Point ``checkpoint.json`` at no step yet (a run that starts from its beginning)."""
    p = os.fspath(path)
    write_json(os.path.join(p, POINTER), dict(kind=_KIND, run=run_id(p), latest=None, step=0))
