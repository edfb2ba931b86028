"""``peclet pall-ring``: the reference page end to end.

    peclet pall-ring [--out DIR] [--rings N] [--seed S] [--threads T] [--steps-scale F]
                     [--mc-samples K] [--no-figures] [--quiet]

runs the reference page end to end (:func:`peclet.packing.pipeline.run`), prints the page's
Results table with our numbers beside the page's, and writes the figures, the frozen pack
(``pall_ring_pack.npz``) and ``results.json`` into DIR.
"""
from __future__ import annotations

import argparse
import sys

__all__ = ["add_parser", "run"]


def _positive_int(name):
    def parse(s):
        try:
            v = int(s)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be an integer >= 1, got {s!r}")
        if v < 1:
            raise argparse.ArgumentTypeError(f"{name} must be an integer >= 1, got {s!r}")
        return v
    return parse


def _positive_float(name):
    def parse(s):
        try:
            v = float(s)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number > 0, got {s!r}")
        if not v > 0 or v != v or v == float("inf"):
            raise argparse.ArgumentTypeError(f"{name} must be a finite number > 0, got {s!r}")
        return v
    return parse


def _threads(s):
    import numba

    cap = int(numba.config.NUMBA_NUM_THREADS)
    try:
        v = int(s)
    except ValueError:
        v = 0
    if not 1 <= v <= cap:
        raise argparse.ArgumentTypeError(
            f"--threads must be an integer in [1, {cap}] (NUMBA_NUM_THREADS={cap}), got {s!r}")
    return v


def add_parser(sub):
    pr = sub.add_parser("pall-ring", help="run the Pall-ring page end to end",
                        description="Pour Pall rings into a periodic box (the reference page, "
                        "Steps 1-7), analyse the pack, write figures, npz and results.json.")
    pr.set_defaults(func=run)
    pr.add_argument("--out", default="results", help="output directory (default: ./results)")
    pr.add_argument("--rings", type=_positive_int("--rings"), default=48,
                    help="number of rings (default 48, the page's)")
    pr.add_argument("--seed", type=int, default=5, help="start-cloud seed (default 5)")
    pr.add_argument("--threads", type=_threads, default=None,
                    help="numba threads, 1..NUMBA_NUM_THREADS (default: numba's)")
    pr.add_argument("--steps-scale", type=_positive_float("--steps-scale"), default=1.0,
                    help="multiply every protocol step count (default 1 = the page's 3700)")
    pr.add_argument("--box", type=_positive_float("--box"), default=3.5,
                    help="periodic box side in ring diameters (default 3.5)")
    pr.add_argument("--mc-samples", type=_positive_int("--mc-samples"), default=400_000,
                    help="Monte Carlo points per bulk window (default 400000)")
    pr.add_argument("--shell-points", type=_positive_int("--shell-points"), default=1200,
                    help="surface probes per ring (default 1200)")
    pr.add_argument("--animation", action="store_true",
                    help="also render the pour as pour.gif (adds 10-20 s)")
    pr.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    pr.add_argument("--quiet", action="store_true", help="no progress bar")
    return pr


def run(args):
    from peclet.packing import pipeline

    if args.threads is not None:
        pipeline.set_threads(args.threads)
    res = pipeline.run(out=args.out, rings=args.rings, seed=args.seed, threads=args.threads,
                       steps_scale=args.steps_scale, box=args.box,
                       mc_samples=args.mc_samples, shell_points=args.shell_points,
                       progress=not args.quiet, write_figures=not args.no_figures,
                       animation=args.animation)
    print(f"\nwrote {res['results_json']} and the pack, figures beside it", file=sys.stderr)
    return 0
