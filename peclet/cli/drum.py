"""``peclet drum``: a rotating drum at a Froude number or rpm (issue 22, item 4).

    peclet drum --element sphere --radius 10 --length 4 --fill 0.35 --froude 1e-2 \\
                --mu 0.5 --revolutions 2 --out drum/
    peclet drum --radius 8 --length 3 --ends periodic --rpm 20 --grain-mm 3 --out drum/
    peclet drum --resume drum/          # finish an interrupted run, bit for bit

Writes into --out ``results.json`` (the dynamic angle: mean and spread over time windows
after the warm-up, the regime with the criteria's values, Mellmann's regimes at this Froude
number), ``snapshots.png``, ``angle.png`` and the ParaView series ``drum.pvd`` +
``frames/``; prints a results table. While the run lasts, ``checkpoint/`` in --out holds its
latest checkpoint (after the settle, every --checkpoint-every steps and at each phase's end;
removed at the end unless --keep-checkpoint): ``--resume DIR`` finishes an interrupted run
bit for bit, with the run's own parameters (an option given with --resume must have the
run's value). Every argument is checked before any work: a bad one is one line naming its
flag, exit code 2, nothing written. See :mod:`peclet.packing.experiments.drum`.
"""
from __future__ import annotations

import math
import os

from peclet.core.outputs import check_output_dir, recording
from peclet.core.validation import PecletArgumentError, check_int

from .options import number, threads_option

__all__ = ["add_parser", "run"]

#: DrumSpec field -> the flag that sets it (errors name the flag).
FLAGS = {"element": "--element", "radius": "--radius", "length": "--length", "ends": "--ends",
         "fill": "--fill", "froude": "--froude", "rpm": "--rpm", "grain_mm": "--grain-mm",
         "mu": "--mu", "e": "--restitution", "wall_mu": "--wall-mu",
         "wall_e": "--wall-restitution", "polydispersity": "--polydispersity",
         "revolutions": "--revolutions", "warmup": "--warmup", "spinup": "--spinup",
         "dt": "--dt", "seed": "--seed", "frames": "--frames", "snapshots": "--snapshots",
         "ribs": "--ribs"}

_FLOATS = ("radius", "length", "fill", "froude", "rpm", "grain_mm", "mu", "e", "wall_mu",
           "wall_e", "polydispersity", "revolutions", "warmup", "spinup", "dt")
_INTS = ("seed", "frames", "snapshots", "ribs")


def add_parser(sub):
    p = sub.add_parser("drum", help="a rotating drum: dynamic angle of repose and flow regime",
                       description="Turn a drum of grains at a Froude number (or rpm) and "
                       "measure the dynamic angle of repose and the flow regime; writes "
                       "results.json, snapshots.png, angle.png and a ParaView series "
                       "(drum.pvd, frames/) into --out.")
    p.set_defaults(func=run)
    a = p.add_argument
    a("--element", default=None, help="sphere (default; polydisperse, see "
      "--polydispersity) or a library element (pall_ring, raschig_ring, ...)")
    a("--radius", default=None, help="drum radius in element diameters D, in [3, 200] "
      "(default 10)")
    a("--length", default=None, help="drum length in D, in [1, 200] (default 4)")
    a("--ends", default=None, help="caps (closed drum, end caps turn with it; default) or "
      "periodic (a slice of a long drum, no end walls)")
    a("--fill", default=None, help="bed volume / drum volume, in (0, 0.8] (default 0.35)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--froude", default=None, help="Fr = omega^2 R / g in (0, 100]")
    g.add_argument("--rpm", default=None, help="revolutions per minute (with --grain-mm)")
    a("--grain-mm", default=None, help="grain diameter in mm, for --rpm and the rpm reported "
      "(default 3)")
    a("--mu", default=None, help="grain-grain friction (default 0.5)")
    a("--wall-mu", default=None, help="wall friction (default: --mu)")
    a("--restitution", default=None, help="grain-grain normal restitution (default 0.3)")
    a("--wall-restitution", default=None, help="wall restitution (default: --restitution)")
    a("--ribs", default=None, help="wall ribs (a rough wall; 0: smooth). Default: one per "
      "1.25 D of circumference")
    a("--polydispersity", default=None, help="spheres: radii 0.5 (1 -+ p) and 0.5 D in "
      "equal shares, p in [0, 0.5) (default 0.1)")
    a("--revolutions", default=None, help="measured revolutions after the warm-up (default 2)")
    a("--warmup", default=None, help="warm-up revolutions before measuring (default 1)")
    a("--spinup", default=None, help="degrees turned at Fr = 0.01 before the warm-up "
      "(default 0; for slow drums)")
    a("--dt", default=None, help="time step (default 4e-3 spheres, 2e-3 elements, at most "
      "0.05 D / (omega R))")
    a("--seed", default=None, help="generator seed >= 0 (default 1)")
    a("--frames", default=None, help="ParaView frames (0: none; default 24)")
    a("--snapshots", default=None, help="cross-sections in snapshots.png, in [1, 12] "
      "(default 4)")
    a("--threads", default=None, help="numba threads (default: numba's)")
    a("--out", default=None, help="output directory (default ./drum_results; with --resume: "
      "the resumed run's)")
    a("--overwrite", action="store_true", help="replace an earlier run's outputs in --out")
    a("--checkpoint-every", default=None, help="turning steps between checkpoints in "
      "OUT/checkpoint, in [0, 1e9] (0: none; default 2000, with --resume the run's)")
    a("--keep-checkpoint", action="store_true", help="keep OUT/checkpoint after the run ends")
    a("--resume", default=None, metavar="DIR", help="finish the interrupted run in DIR (its "
      "--out or DIR/checkpoint), bit for bit; its parameters are the run's (an option given "
      "must have the run's value)")
    a("--no-figures", action="store_true", help="skip snapshots.png and angle.png")
    a("--quiet", action="store_true", help="no progress bar")
    return p


def given_fields(args):
    """The DrumSpec fields set by the options given in ``args`` (converted, not range-checked
    yet: ``DrumSpec.checked`` does that, naming the flags)."""
    kw = {}
    dest = {"e": "restitution", "wall_e": "wall_restitution"}
    for field in _FLOATS + _INTS:
        text = getattr(args, dest.get(field, field))
        if text is not None:
            kw[field] = number(FLAGS[field], text, int if field in _INTS else float)
    for field in ("element", "ends"):
        if getattr(args, field) is not None:
            kw[field] = getattr(args, field)
    return kw


def spec_from_args(args):
    """The checked DrumSpec of the parsed ``args`` (errors name the flags)."""
    from peclet.packing.experiments.drum import DrumSpec

    kw = given_fields(args)
    if kw.get("froude") is None and kw.get("rpm") is None:
        raise PecletArgumentError("--froude", "given, or --rpm (exactly one)", None)
    return DrumSpec(**kw).checked(FLAGS)


def _every(args, default=2000):
    """--checkpoint-every (``default`` when not given; 0: no checkpoints)."""
    if args.checkpoint_every is None:
        return default
    return check_int("--checkpoint-every", number("--checkpoint-every", args.checkpoint_every,
                                                  int), 0, 10 ** 9)


def _element_error(exc, text):
    """A library lookup's error about ``element`` as one naming --element."""
    if exc.argument == "element" and str(exc).startswith("element"):
        err = PecletArgumentError("--element", "", text)
        err.args = ("--element" + str(exc)[len("element"):],)
        return err
    return exc


def run(args):
    from peclet.packing.experiments.drum import OUTPUT_DIRS, OUTPUTS, Drum, run_drum

    if args.resume is not None:
        return _resume(args)
    spec = spec_from_args(args)
    threads = threads_option(args.threads)
    every = _every(args)
    out = args.out or "drum_results"
    if not args.overwrite and os.path.isfile(os.path.join(out, "checkpoint",
                                                          "checkpoint.json")):
        raise PecletArgumentError("--out", "a new or empty directory", out, "it holds an "
                                  f"interrupted drum run: finish it with --resume {out}, or "
                                  "pass --overwrite to replace it")
    out, previous = check_output_dir(out, OUTPUTS, args.overwrite, "--out", dirs=OUTPUT_DIRS)
    try:
        drum = Drum(spec)
        speed = ("--rpm", args.rpm) if args.rpm is not None else ("--froude", args.froude)
        drum.check_room("--fill", "--length", *speed)
    except PecletArgumentError as exc:
        raise _element_error(exc, args.element) from None
    with recording(out, OUTPUTS):
        res = run_drum(spec, out, progress=not args.quiet, figures=not args.no_figures,
                       threads=threads, previous=previous, checkpoint_every=every,
                       keep_checkpoint=args.keep_checkpoint)
    print(table(res))
    return 0


def _resume(args):
    """``--resume DIR``: check everything (the checkpoint, the options given against the
    run's), then finish the run."""
    from peclet.packing.experiments import drum as dr

    threads = threads_option(args.threads)
    every = _every(args, None)                 # None: as the run had it
    cdir = dr.checkpoint_dir(args.resume, "--resume")
    saved, _, _, _ = dr.read_checkpoint(cdir, "--resume")
    given = given_fields(args)
    try:
        dr.same_spec(saved, given, FLAGS)
    except PecletArgumentError as exc:
        raise _element_error(exc, args.element) from None
    out, previous = check_output_dir(args.out or os.path.dirname(cdir), dr.OUTPUTS,
                                     args.overwrite, "--out", dirs=dr.OUTPUT_DIRS,
                                     keep=(cdir,))
    with recording(out, dr.OUTPUTS):
        res = dr.resume_drum(cdir, out, progress=not args.quiet,
                             figures=not args.no_figures, threads=threads, previous=previous,
                             checkpoint_every=every, keep_checkpoint=args.keep_checkpoint,
                             names=dict(FLAGS, resume="--resume"))
    print(table(res))
    return 0


def table(res):
    """The run's results as a text table."""
    a, c = res["angle"], res["criteria"]
    f = lambda x, p=1: "n/a" if x is None or not math.isfinite(x) else f"{x:.{p}f}"  # noqa
    rows = [("element", res["element"]), ("grains", res["grains"]),
            ("Froude number", f"{res['froude']:.3g}"),
            (f"rpm ({res['spec']['grain_mm']:g} mm grains)", f"{res['rpm_for_grain_mm']:.3g}"),
            ("omega (rad/time)", f"{res['omega']:.4g}"),
            ("revolutions (measured)", f"{res['spec']['revolutions']:g} after "
             f"{res['spec']['warmup']:g} warm-up"),
            ("dynamic angle (deg)", f"{f(a['mean'])} +- {f(a['spread'])} (windows), "
             f"5-95 %: {f(a['p05'])}..{f(a['p95'])}"),
            ("regime (measured)", res["regime"]),
            ("Mellmann (2001) at this Fr", ", ".join(res["mellmann"]) or "-"),
            ("criteria", f"rest {f(c.get('rest_share'), 2)}, S-shape {f(c.get('s_shape'), 3)}"
             f" R, airborne {f(c.get('airborne'), 3)}, high {f(c.get('high'), 2)}, "
             f"corotating {f(c.get('corotating'), 2)}"),
            ("fill (measured)", f(res["fill_measured"], 3)),
            ("steps, ms/step", f"{res['steps']}, {res['ms_per_step']:.2f}"),
            ("state hash", res["state_hash"][:16])]
    w = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{w}}  {v}" for k, v in rows)
