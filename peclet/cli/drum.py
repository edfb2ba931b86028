"""``peclet drum``: a rotating drum at a Froude number or rpm (issue 22, item 4).

    peclet drum --element sphere --radius 10 --length 4 --fill 0.35 --froude 1e-2 \\
                --mu 0.5 --revolutions 2 --out drum/
    peclet drum --radius 8 --length 3 --ends periodic --rpm 20 --grain-mm 3 --out drum/

Writes into --out ``results.json`` (the dynamic angle: mean and spread over time windows
after the warm-up, the regime with the criteria's values, Mellmann's regimes at this Froude
number), ``snapshots.png``, ``angle.png`` and the ParaView series ``drum.pvd`` +
``frames/``; prints a results table. Every argument is checked before any work: a bad one is
one line naming its flag, exit code 2, nothing written. See :mod:`peclet.packing.drum`.
"""
from __future__ import annotations

import math

from peclet.core.files import check_output_dir
from peclet.core.validation import PecletArgumentError

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
    a("--element", default="sphere", help="sphere (default; polydisperse, see "
      "--polydispersity) or a library element (pall_ring, raschig_ring, ...)")
    a("--radius", default="10", help="drum radius in element diameters D, in [3, 200] "
      "(default 10)")
    a("--length", default="4", help="drum length in D, in [1, 200] (default 4)")
    a("--ends", default="caps", help="caps (closed drum, end caps turn with it; default) or "
      "periodic (a slice of a long drum, no end walls)")
    a("--fill", default="0.35", help="bed volume / drum volume, in (0, 0.8] (default 0.35)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--froude", default=None, help="Fr = omega^2 R / g in (0, 100]")
    g.add_argument("--rpm", default=None, help="revolutions per minute (with --grain-mm)")
    a("--grain-mm", default="3", help="grain diameter in mm, for --rpm and the rpm reported "
      "(default 3)")
    a("--mu", default="0.5", help="grain-grain friction (default 0.5)")
    a("--wall-mu", default=None, help="wall friction (default: --mu)")
    a("--restitution", default="0.3", help="grain-grain normal restitution (default 0.3)")
    a("--wall-restitution", default=None, help="wall restitution (default: --restitution)")
    a("--ribs", default=None, help="wall ribs (a rough wall; 0: smooth). Default: one per "
      "1.25 D of circumference")
    a("--polydispersity", default="0.1", help="spheres: radii 0.5 (1 -+ p) and 0.5 D in "
      "equal shares, p in [0, 0.5) (default 0.1)")
    a("--revolutions", default="2", help="measured revolutions after the warm-up (default 2)")
    a("--warmup", default="1", help="warm-up revolutions before measuring (default 1)")
    a("--spinup", default="0", help="degrees turned at Fr = 0.01 before the warm-up "
      "(default 0; for slow drums)")
    a("--dt", default=None, help="time step (default 4e-3 spheres, 2e-3 elements, at most "
      "0.05 D / (omega R))")
    a("--seed", default="1", help="generator seed >= 0 (default 1)")
    a("--frames", default="24", help="ParaView frames (0: none; default 24)")
    a("--snapshots", default="4", help="cross-sections in snapshots.png, in [1, 12] "
      "(default 4)")
    a("--threads", default=None, help="numba threads (default: numba's)")
    a("--out", default="drum_results", help="output directory (default ./drum_results)")
    a("--overwrite", action="store_true", help="replace an earlier run's outputs in --out")
    a("--no-figures", action="store_true", help="skip snapshots.png and angle.png")
    a("--quiet", action="store_true", help="no progress bar")
    return p


def spec_from_args(args):
    """The checked DrumSpec of the parsed ``args`` (errors name the flags)."""
    from peclet.packing.drum import DrumSpec

    kw = {}
    dest = {"e": "restitution", "wall_e": "wall_restitution"}
    for field in _FLOATS + _INTS:
        text = getattr(args, dest.get(field, field))
        if text is None:
            kw[field] = None
            continue
        kw[field] = number(FLAGS[field], text, int if field in _INTS else float)
    if kw["froude"] is None and kw["rpm"] is None:
        raise PecletArgumentError("--froude", "given, or --rpm (exactly one)", None)
    for k in ("radius", "length", "fill", "grain_mm", "mu", "e", "polydispersity",
              "revolutions", "warmup", "spinup", "seed", "frames", "snapshots"):
        if kw[k] is None:
            kw.pop(k)
    spec = DrumSpec(element=args.element, ends=args.ends, **kw)
    return spec.checked(FLAGS)


def run(args):
    from peclet.packing.drum import OUTPUT_DIRS, OUTPUTS, Drum, run_drum

    spec = spec_from_args(args)
    threads = threads_option(args.threads)
    out, previous = check_output_dir(args.out, OUTPUTS, args.overwrite, "--out",
                                     dirs=OUTPUT_DIRS)
    try:
        drum = Drum(spec)
        drum.check_room("--fill", "--length")
    except PecletArgumentError as exc:
        if exc.argument == "element" and str(exc).startswith("element"):
            err = PecletArgumentError("--element", "", args.element)
            err.args = ("--element" + str(exc)[len("element"):],)
            raise err from None
        raise
    res = run_drum(spec, out, progress=not args.quiet, figures=not args.no_figures,
                   threads=threads, previous=previous)
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
