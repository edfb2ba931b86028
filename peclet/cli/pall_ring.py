"""``peclet pall-ring``: the reference page end to end.

    peclet pall-ring [--out DIR] [--overwrite] [--rings N] [--seed S] [--threads T]
                     [--steps-scale F] [--box L] [--mc-samples K] [--shell-points M]
                     [--animation] [--no-figures] [--quiet] [--flow [--flow-resolution D/N]]

runs the reference page end to end (:func:`peclet.packing.page.pipeline.run`), prints the page's
Results table with our numbers beside the page's, and writes the figures, the frozen pack
(``pall_ring_pack.npz``) and ``results.json`` into DIR. With ``--flow`` the frozen pack's
permeability k and its dP/L against the Ergun viscous term (lattice Boltzmann,
:mod:`peclet.flow`, at ``--flow-resolution``, default D/8) are added to the Results table and
to results.json (``flow``).

Every option is checked before the ring is built (the rules and caps are stated in
:mod:`peclet.packing.page.checks`): a bad one is a single ``peclet pall-ring: error:``
line naming it, exit code 2, and nothing written. A DIR holding an earlier run's files is
refused unless ``--overwrite``, which removes those files first.
"""
from __future__ import annotations

import sys

__all__ = ["add_parser", "run"]


def _as(name, text, kind):
    """``text`` as ``kind`` (int or float), or a PecletArgumentError naming the option.

    Options are parsed as text and converted here rather than by argparse ``type=``: argparse
    reports a bad value as a usage block and exits from inside the parser, where this is one
    ``peclet pall-ring: error:`` line (exit 2) like every other refusal."""
    from peclet.core.validation import PecletArgumentError

    if text is None or not isinstance(text, str):
        return text
    try:
        return kind(text.strip())
    except ValueError:
        raise PecletArgumentError(name, "an integer" if kind is int else "a number",
                                  text) from None


def add_parser(sub):
    from peclet.packing.page import checks as C

    pr = sub.add_parser("pall-ring", help="run the Pall-ring page end to end",
                        description="Pour Pall rings into a periodic box (the reference page, "
                        "Steps 1-7), analyse the pack, write figures, npz and results.json.")
    pr.set_defaults(func=run)
    pr.add_argument("--out", default="results", help="output directory (default: ./results)")
    pr.add_argument("--overwrite", action="store_true",
                    help="replace the files of an earlier run in --out (they are removed "
                    "first; other files are never touched)")
    pr.add_argument("--rings", default="48",
                    help=f"number of rings, 1..{C.RINGS_MAX} (default 48, the page's)")
    pr.add_argument("--seed", default="5", help="start-cloud seed >= 0 (default 5)")
    pr.add_argument("--threads", default=None,
                    help="numba threads, 1..NUMBA_NUM_THREADS (default: numba's)")
    pr.add_argument("--steps-scale", default="1.0",
                    help=f"multiply every protocol step count, (0, {C.STEPS_SCALE_MAX:g}] "
                    "(default 1 = the page's 3700)")
    pr.add_argument("--box", default="3.5",
                    help="periodic box side in ring diameters (default 3.5); it must exceed "
                    "the engine's bound for the ring and let the start cloud of --rings land "
                    "before the quench (peclet.packing.page.checks states both rules)")
    pr.add_argument("--mc-samples", default="400000",
                    help=f"Monte Carlo points per bulk window, {C.MC_SAMPLES_MIN}.."
                    f"{C.MC_SAMPLES_MAX} (default 400000)")
    pr.add_argument("--shell-points", default="1200",
                    help=f"surface probes per ring, {C.SHELL_POINTS_MIN}..{C.SHELL_POINTS_MAX} "
                    "(default 1200)")
    pr.add_argument("--animation", action="store_true",
                    help="also render the pour as pour.gif (adds 10-20 s)")
    pr.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    pr.add_argument("--quiet", action="store_true", help="no progress bar")
    pr.add_argument("--flow", action="store_true",
                    help="also push a slow flow through the frozen pack (peclet.flow) and add "
                    "k and dP/L / Ergun to the Results table and results.json")
    pr.add_argument("--flow-resolution", default=None,
                    help="with --flow: cells per ring diameter, D/N or N with N in [4, 64] "
                    "and box * N a whole number (default D/8)")
    return pr


def run(args):
    """Convert and check every option (:func:`peclet.packing.page.checks.check_run`, with
    the options' names) before anything is built or written, then run the page."""
    from peclet.dem import warm
    from peclet.packing.page import pipeline
    from peclet.packing.page import checks as pipeline_checks

    # a cold cache: the DEM kernels start compiling now, beside the checks' own compilation
    # (the run finds them started); a refusal stops them
    warming = warm.start_background()
    try:
        flow, kw = _checked(args, pipeline, pipeline_checks)
    except BaseException:
        warm.stop(warming)
        raise
    stages = None
    if flow is not None:
        from peclet.flow import page as flow_page
        stages = {"flow": flow_page.stage(flow)}
    res = pipeline.run(**kw, progress=not args.quiet, write_figures=not args.no_figures,
                       animation=args.animation, stages=stages)
    print(f"\nwrote {res['results_json']} and the pack, figures beside it", file=sys.stderr)
    return 0


def _checked(args, pipeline, pipeline_checks):
    from peclet.packing.bed.threads import set_threads

    # (flow resolution or None, the run's keyword arguments), every option checked
    kw = dict(out=args.out, rings=_as("--rings", args.rings, int),
              seed=_as("--seed", args.seed, int), threads=_as("--threads", args.threads, int),
              steps_scale=_as("--steps-scale", args.steps_scale, float),
              box=_as("--box", args.box, float),
              mc_samples=_as("--mc-samples", args.mc_samples, int),
              shell_points=_as("--shell-points", args.shell_points, int),
              overwrite=args.overwrite)
    pipeline_checks.check_run(**kw, cli=True)
    flow = None
    if args.flow_resolution is not None and not args.flow:
        from peclet.core.validation import PecletArgumentError
        raise PecletArgumentError("--flow-resolution", "given only with --flow",
                                  args.flow_resolution)
    if args.flow:
        from peclet.flow.page import check_resolution

        from .flow import parse_resolution
        flow = check_resolution(parse_resolution(args.flow_resolution or "D/8",
                                                 "--flow-resolution"),
                                kw["box"], "--flow-resolution")
    if kw["threads"] is not None:
        set_threads(kw["threads"], "--threads")
    return flow, kw
