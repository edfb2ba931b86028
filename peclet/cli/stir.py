"""``peclet stir``: upstream's stirred column, grains mixed by a pitched-blade impeller
(issue 22, item 4).

    peclet stir --out stir/                                # the page: 22,121 grains, 5 rev
    peclet stir --grain-radius 0.8 --revolutions 1 --out stir_small/   # ~2,800 grains
    peclet stir --resume stir/          # finish an interrupted run, bit for bit

Writes into --out ``results.json`` (the Lacey mixing index against revolutions, grains
escaped, the minimum wall distance over grain centres, the peak grain speed over the tip
speed, ms/step), ``lacey.png``, ``snapshot.png`` and the ParaView series ``stir.pvd`` +
``frames/``; prints a results table. While the run lasts, ``checkpoint/`` in --out holds its
latest checkpoint (every --checkpoint-every steps and at the settle's end; removed at the end
unless --keep-checkpoint): ``--resume DIR`` finishes an interrupted run bit for bit, with the
run's own parameters. Every argument is checked before any work: a bad one is one line naming
its flag, exit code 2, nothing written. See :mod:`peclet.packing.experiments.stir`.
"""
from __future__ import annotations

import math
import os

from peclet.core.outputs import check_output_dir, recording
from peclet.core.validation import PecletArgumentError, check_int

from .options import number, threads_option

__all__ = ["add_parser", "run"]

#: StirSpec field -> its flag (errors name the flag); the integer fields.
FLAGS = {"radius": "--radius", "height": "--height", "grain_radius": "--grain-radius",
         "count": "--count", "e": "--restitution", "mu": "--mu", "dt": "--dt",
         "omega": "--omega", "revolutions": "--revolutions", "settle": "--settle",
         "seed": "--seed", "frames": "--frames"}
_INTS = ("count", "seed", "frames")


def add_parser(sub):
    p = sub.add_parser("stir", help="a stirred column: Lacey mixing index against impeller "
                       "revolutions",
                       description="Fill upstream's stirred column (capsule column R 20, H 24; "
                       "4-blade impeller pitched 45 degrees, tip radius 16) with grains, turn "
                       "the impeller and follow the Lacey mixing index; writes results.json, "
                       "lacey.png, snapshot.png and a ParaView series (stir.pvd, frames/) into "
                       "--out.")
    p.set_defaults(func=run)
    a = p.add_argument
    a("--radius", default=None, help="column radius, >= 17 (default 20)")
    a("--height", default=None, help="height of the column's cylinder above the floor, >= 11 "
      "(default 24)")
    a("--grain-radius", default=None, help="grain radius in [0.05, 2] (default 0.4)")
    a("--count", default=None, help="grains (default: the page's fill height, 22,121 at "
      "radius 0.4, 22,121 (0.4/r)^3 otherwise)")
    a("--restitution", default=None, help="normal restitution, all contacts (default 0.2)")
    a("--mu", default=None, help="friction, all contacts (default 0.5)")
    a("--dt", default=None, help="time step in (0, 0.02] (default 2e-3)")
    a("--omega", default=None, help="impeller speed, rad/time, in (0, 100] (default 1.5)")
    a("--revolutions", default=None, help="impeller revolutions in (0, 100] (default 5)")
    a("--settle", default=None, help="time the fill settles before stirring, in [0, 100] "
      "(default 2)")
    a("--seed", default=None, help="generator seed >= 0 (default 1)")
    a("--frames", default=None, help="ParaView frames (0: none; default 20)")
    a("--threads", default=None, help="numba threads (default: numba's)")
    a("--out", default=None, help="output directory (default ./stir_results; with --resume: "
      "the resumed run's)")
    a("--overwrite", action="store_true", help="replace an earlier run's outputs in --out")
    a("--checkpoint-every", default=None, help="steps between checkpoints in OUT/checkpoint, "
      "in [0, 1e9] (0: none; default 2000, with --resume the run's)")
    a("--keep-checkpoint", action="store_true", help="keep OUT/checkpoint after the run ends")
    a("--resume", default=None, metavar="DIR", help="finish the interrupted run in DIR (its "
      "--out or DIR/checkpoint), bit for bit; its parameters are the run's (an option given "
      "must have the run's value)")
    a("--no-figures", action="store_true", help="skip lacey.png and snapshot.png")
    a("--quiet", action="store_true", help="no progress bar")
    return p


def given_fields(args):
    """The StirSpec fields set by the options given in ``args`` (converted, not range-checked
    yet: ``StirSpec.checked`` does that, naming the flags)."""
    kw = {}
    for field, flag in FLAGS.items():
        text = getattr(args, flag[2:].replace("-", "_"))
        if text is not None:
            kw[field] = number(flag, text, int if field in _INTS else float)
    return kw


def spec_from_args(args):
    """The checked StirSpec of the parsed ``args`` (errors name the flags)."""
    from peclet.packing.experiments.stir import StirSpec

    return StirSpec(**given_fields(args)).checked(FLAGS)


def _every(args, default=2000):
    """--checkpoint-every (``default`` when not given; 0: no checkpoints)."""
    if args.checkpoint_every is None:
        return default
    return check_int("--checkpoint-every", number("--checkpoint-every", args.checkpoint_every,
                                                  int), 0, 10 ** 9)


def run(args):
    from peclet.packing.experiments.stir import OUTPUT_DIRS, OUTPUTS, StirredColumn, run_stir

    if args.resume is not None:
        return _resume(args)
    spec = spec_from_args(args)
    threads = threads_option(args.threads)
    every = _every(args)
    out = args.out or "stir_results"
    if not args.overwrite and os.path.isfile(os.path.join(out, "checkpoint",
                                                          "checkpoint.json")):
        raise PecletArgumentError("--out", "a new or empty directory", out, "it holds an "
                                  f"interrupted stir run: finish it with --resume {out}, or "
                                  "pass --overwrite to replace it")
    out, previous = check_output_dir(out, OUTPUTS, args.overwrite, "--out",
                                     dirs=OUTPUT_DIRS)
    StirredColumn(spec).check_room("--count", "--omega")
    with recording(out, OUTPUTS):
        res = run_stir(spec, out, progress=not args.quiet, figures=not args.no_figures,
                       threads=threads, previous=previous, checkpoint_every=every,
                       keep_checkpoint=args.keep_checkpoint)
    print(table(res))
    return 0


def _resume(args):
    """``--resume DIR``: check everything (the checkpoint, the options given against the
    run's), then finish the run."""
    from peclet.packing.experiments import stir as st

    threads = threads_option(args.threads)
    every = _every(args, None)                 # None: as the run had it
    cdir = st.checkpoint_dir(args.resume, "--resume")
    saved, _, _, _ = st.read_checkpoint(cdir, "--resume")
    st.same_spec(saved, given_fields(args), FLAGS)
    out, previous = check_output_dir(args.out or os.path.dirname(cdir), st.OUTPUTS,
                                     args.overwrite, "--out", dirs=st.OUTPUT_DIRS,
                                     keep=(cdir,))
    with recording(out, st.OUTPUTS):
        res = st.resume_stir(cdir, out, progress=not args.quiet,
                             figures=not args.no_figures, threads=threads, previous=previous,
                             checkpoint_every=every, keep_checkpoint=args.keep_checkpoint,
                             names=dict(FLAGS, resume="--resume"))
    print(table(res))
    return 0


def table(res):
    """The run's results as a text table."""
    f = lambda x, p=3: "n/a" if x is None or not math.isfinite(x) else f"{x:.{p}f}"  # noqa
    s = res["samples"]
    curve = ", ".join(f"{r}: {f(min(s, key=lambda x: abs(x['revolutions'] - r))['lacey'])}"
                      for r in range(int(res["spec"]["revolutions"]) + 1)) if s else ""
    rows = [("grains", res["grains"]),
            ("impeller", f"omega {res['spec']['omega']:g}, tip speed {res['tip_speed']:g}"),
            ("revolutions", f"{res['spec']['revolutions']:g} after {res['settle_steps']} "
             "settle steps"),
            ("Lacey index", f"{f(res['lacey_start'])} -> {f(res['lacey_end'])}"),
            ("Lacey by revolution", curve or "-"),
            ("grains escaped (max)", res["escaped_max"]),
            ("min wall distance of a centre", f(res["min_wall_sdf"], 4)),
            ("min wall clearance (- overlap)", f(res["min_clearance"], 4)),
            ("peak grain speed / tip speed", f(res["peak_speed_over_tip"], 3)),
            ("steps, ms/step", f"{res['steps']}, {res['ms_per_step']:.2f}"),
            ("state hash", res["state_hash"][:16])]
    w = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{w}}  {v}" for k, v in rows)
