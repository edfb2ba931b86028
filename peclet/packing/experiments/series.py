"""Runs with turning walls: the phase loop and the ParaView time series they write.

A kinematic-wall run (the drum, the stirred column) is a list of :class:`Phase` s, each turning
one wall at a constant angular speed for a number of steps; :func:`run_phases` steps through
them, keeps the clock and the angle turned, and calls back after every step (sampling, frames,
snapshots read the state only, so a run's bits do not depend on what is observed), and goes
on from a given step for a run resumed from its checkpoint.
:func:`write_series` writes frames as ``frames/frame_NNNN.vtu`` (grain centres as VTK
vertices with per-grain data, plus optional polylines outlining the walls) and the ``.pvd``
collection ParaView opens as one time series; the frames directory appears whole or not at all
and the index is replaced atomically (:mod:`peclet.core.files`).
"""
from __future__ import annotations

import os
from typing import NamedTuple

import numpy as np

from peclet.core.files import atomic_directory, atomic_write, remove_parts
from peclet.core.validation import PecletArgumentError

__all__ = ["Phase", "run_phases", "turning_clock", "write_series", "grains_mesh", "check_work",
           "reopen", "relocate", "Reopened", "fresh_checkpoint",
           "GRAIN_STEP_SECONDS", "MAX_RUN_SECONDS"]

#: The cost of one grain through one step on one core, in seconds, used to estimate a run's
#: time before it starts: peclet's engines run about 1e6 sphere-steps/s on one core here
#: (benchmarks/bench_hertz.py: 1.05e6), composed grains slower, so this errs short.
GRAIN_STEP_SECONDS = 1e-6

#: Runs estimated longer than this (7 days on one core) are refused before they start.
MAX_RUN_SECONDS = 7 * 86400.0


class Phase(NamedTuple):
    """``steps`` steps with the wall turning at ``omega`` (rad/time) about its axis."""
    name: str
    omega: float
    steps: int


def check_work(phases, grains, name, value):
    """Refuse (PecletArgumentError naming ``name``, whose value is ``value``) a run of
    ``phases`` over ``grains`` grains whose estimated time (:data:`GRAIN_STEP_SECONDS` a
    grain-step) exceeds :data:`MAX_RUN_SECONDS`, stating the steps and the estimate. A run
    with a wall turning at 1e-12 rad/time needs ~1e12 steps a revolution: refused at once
    instead of a progress bar frozen at step 1."""
    steps = sum(int(ph.steps) for ph in phases)
    seconds = float(steps) * max(int(grains), 1) * GRAIN_STEP_SECONDS
    if seconds == float("inf"):       # steps * grains overflowed (a speed of 1e-300): the
        seconds = float(steps) * GRAIN_STEP_SECONDS * max(int(grains), 1)   # other order
    if seconds > MAX_RUN_SECONDS:
        raise PecletArgumentError(
            name, "a value whose run finishes in at most "
            f"{MAX_RUN_SECONDS / 86400:g} days on one core", value,
            f"{steps:.3g} steps of {grains} grains, about {seconds / 86400:.3g} days at "
            f"{GRAIN_STEP_SECONDS:g} s a grain-step")


def run_phases(phases, dt, step, turn, clock, after_step=None, bar=None, start=None):
    """Run ``phases`` (a list of :class:`Phase`): at the start of each, ``turn(omega)`` sets the
    wall's angular speed; then ``step()`` advances the simulation by ``dt``, and
    ``after_step(k, t, angle, phase)`` sees the global step count k (from 1), the time
    t = ``clock()`` since the first phase began (the world's clock, read after the step: the
    simulation owns the time, this loop only reads it), the angle turned (rad, the sum of
    omega dt) and the :class:`Phase`. ``bar`` (a :class:`peclet.packing.bed.progress.Progress`)
    is advanced one step at a time.

    ``start``: None (from the beginning) or the (k, angle) a run stopped at (read from a
    checkpoint): phases that ended by step k are skipped, ``turn`` is called for the phase
    step k + 1 belongs to and every later one, and the angle goes on from ``angle``, so the
    continued run adds the same numbers in the same order as the uninterrupted one. (``turn``
    must only set the speed, as a skipped phase's call is not repeated.) Returns (steps, t,
    angle)."""
    k, angle = (0, 0.0) if start is None else (int(start[0]), float(start[1]))
    skip = k
    for ph in phases:
        if skip and skip >= ph.steps:        # wholly run before the stop
            skip -= ph.steps
            continue
        turn(ph.omega)
        for _ in range(ph.steps - skip):
            step()
            k += 1
            angle += ph.omega * dt
            if after_step is not None:
                after_step(k, clock(), angle, ph)
            if bar is not None:
                bar.update(1, label=ph.name)
        skip = 0
    return k, clock(), angle


def turning_clock(sim, state):
    """The clock :func:`run_phases` reads for a run whose state is ``state`` (a dict): the
    simulation's time ``sim.time`` less ``state["t_begin"]``, the simulation's time when the
    first phase began (recorded by the run when it starts, and in its checkpoints). A checkpoint
    written before ``t_begin`` was recorded gets it as its simulation time less its turning
    time ``state["t"]``, which is equal up to rounding."""
    if "t_begin" not in state:
        state["t_begin"] = sim.time - float(state["t"])
    since = float(state["t_begin"])
    return lambda: sim.time - since


def write_series(out, stem, frames, mesh_of):
    """Write ``out/frames/frame_NNNN.vtu`` for each of ``frames`` (``mesh_of(frame)`` returns
    a ``meshio.Mesh``; a frame is a dict with at least ``t``, the time) and ``out/<stem>.pvd``
    indexing them by time. An earlier run's frames (``frame_*``) are replaced; any other file
    in ``frames/`` stays (the new frames are then written one by one, each atomically)."""
    import meshio

    def fill(tmp):
        for i, f in enumerate(frames):
            meshio.write(os.path.join(tmp, f"frame_{i:04d}.vtu"), mesh_of(f), file_format="vtu")

    fdir = os.path.join(out, "frames")
    remove_parts(fdir, prefixes=("frame_",))
    if os.path.isdir(fdir):
        for i, f in enumerate(frames):
            atomic_write(os.path.join(fdir, f"frame_{i:04d}.vtu"),
                         lambda tmp, f=f: meshio.write(tmp, mesh_of(f), file_format="vtu"))
    else:
        atomic_directory(fdir, fill)
    rows = "\n".join(f'    <DataSet timestep="{f["t"]:.9g}" part="0" '
                     f'file="frames/frame_{i:04d}.vtu"/>' for i, f in enumerate(frames))
    text = ('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1" '
            'byte_order="LittleEndian">\n  <Collection>\n' + rows +
            "\n  </Collection>\n</VTKFile>\n")

    def w(tmp):
        with open(tmp, "w") as fh:
            fh.write(text)
    atomic_write(os.path.join(out, f"{stem}.pvd"), w)


def grains_mesh(X, point_data, outlines=()):
    """A ``meshio.Mesh`` of grain centres ``X`` (n, 3) as vertices carrying ``point_data``
    (name -> (n, ...) array), plus ``outlines``: closed polylines (each (m, 3)) drawn as
    line cells (their points carry zeros in every data array)."""
    import meshio

    n = len(X)
    pts = [np.asarray(X, np.float64)]
    lines, off = [], n
    for ring in outlines:
        m = len(ring)
        pts.append(np.asarray(ring, np.float64))
        lines += [[off + j, off + (j + 1) % m] for j in range(m)]
        off += m
    extra = off - n
    data = {k: np.concatenate([np.asarray(a), np.zeros((extra,) + np.shape(a)[1:],
                                                       np.asarray(a).dtype)])
            for k, a in point_data.items()}
    cells = [("vertex", np.arange(n)[:, None])]
    if lines:
        cells.append(("line", np.array(lines)))
    return meshio.Mesh(np.vstack(pts), cells, point_data=data)


class Reopened(NamedTuple):
    """What :func:`reopen` read of a turning-wall run's checkpoint: the run's checked
    ``spec``, its loop ``state`` and ``arrays``, the path of its ``sim.npz``, the checkpoint
    directory ``cdir``, and the ``out``, ``every`` and ``max_steps`` the resumed run uses."""
    spec: object
    state: dict
    arrays: dict
    sim_path: str
    cdir: str
    out: str
    every: object
    max_steps: object


def reopen(path, out, given, names, threads, checkpoint_every, max_steps, locate, read, same):
    """The start every resume of a turning-wall run shares (the drum's, the stirred
    column's): find its checkpoint under ``path`` (``locate``), ``read`` it, refuse ``given``
    fields that differ from the run's (``same``, errors naming ``names[field]``), set the
    ``threads``, and settle ``out`` (default: the run's own directory), the checkpoint
    interval (default: the run's) and ``max_steps``. Returns a :class:`Reopened`."""
    from ..bed import checkpoint as ckpt
    resume = (names or {}).get("resume", "resume")
    cdir = locate(path, resume)
    saved, st, arrays, sim_path = read(cdir, resume)
    if given:
        same(saved, given, names)
    if threads is not None:
        from ..bed.threads import set_threads
        set_threads(threads)
    every = st["checkpoint_every"] if checkpoint_every is None else checkpoint_every
    if out is None:
        out = os.path.dirname(cdir)
    every, max_steps = ckpt.check_every(out, every, max_steps)
    return Reopened(saved, st, arrays, sim_path, cdir, out, every, max_steps)


def relocate(out, cdir, previous, every, write):
    """Make ``out`` ready for a resumed run and return the checkpoint directory it goes on
    in: with outputs elsewhere, the earlier outputs there (``previous``) are cleared and a
    new checkpoint is started in ``out`` (``write(cdir)``; the one read is left as it is);
    in the run's own directory everything but the checkpoint is cleared."""
    from peclet.core.outputs import clear_outputs

    from ..bed.checkpoint import CHECKPOINT
    os.makedirs(out, exist_ok=True)
    if os.path.abspath(out) != os.path.dirname(cdir):
        clear_outputs(out, previous)
        cdir = os.path.join(os.path.abspath(out), CHECKPOINT)
        if every is not None:
            write(cdir)
    else:
        clear_outputs(out, tuple(f for f in previous if f != CHECKPOINT))
    return cdir


def fresh_checkpoint(out, previous, every, run):
    """(checkpoint directory, outputs still to clear) of a new turning-wall run (``run`` the
    run's name, "drum" or "stir") writing into ``out``: (None, ``previous``) without
    checkpoints (``every`` None); else ``out/checkpoint``, after refusing an unfinished run's
    checkpoint there (unless ``previous`` names it) and clearing the earlier outputs
    ``previous`` (its checkpoint takes their place)."""
    from peclet.core.outputs import clear_outputs

    from ..bed.checkpoint import CHECKPOINT
    if every is None:
        return None, previous
    cdir = os.path.join(os.path.abspath(out), CHECKPOINT)
    if os.path.lexists(cdir) and CHECKPOINT not in previous:
        raise PecletArgumentError("out", f"a directory without a {run} checkpoint (finish "
                                  f"that run with resume_{run}, or name 'checkpoint' in "
                                  "previous to replace it)", out)
    os.makedirs(out, exist_ok=True)
    clear_outputs(out, previous)
    return cdir, ()
