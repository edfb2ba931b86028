"""``peclet ensemble``: many packs (seeds x a parameter sweep) on Dask, and their statistics.

    peclet ensemble --element pall_ring --container box:3.5 --seeds 1-32 \\
                    --sweep mu=0.3,0.5,0.8 --out DIR [--scheduler ADDR] [--count N] \\
                    [--steps-scale F]

runs every (sweep point, seed) as one Dask task (an embedded LocalCluster by default; an existing
scheduler with ``--scheduler tcp://HOST:8786`` or ``DASK_SCHEDULER_ADDRESS``), writes each
realization to ``DIR/<spec-id>/`` as it finishes (a rerun skips those), then writes
``summary.csv``, ``summary.json`` (per sweep point: count, mean, standard error and 95% interval
of eps, f_env and Z) and ``summary.png`` into DIR and prints the table.
"""
from __future__ import annotations

import math
import os
import sys

from .options import add_bed_options

__all__ = ["add_parser", "run"]

#: Optional fixed values: CLI flag -> PackSpec field.
_FIXED = {"count": "--count", "steps_scale": "--steps-scale", "mu": "--mu", "e_n": "--e-n",
          "e_t": "--e-t", "mc_samples": "--mc-samples"}


def add_parser(sub):
    from peclet.ensemble.spec import SWEEPABLE

    pr = sub.add_parser("ensemble", help="many packs (seeds x sweep) on Dask, with statistics",
                        description="Run an ensemble of packs as Dask tasks (embedded "
                        "LocalCluster or --scheduler) and summarise eps, f_env and Z per "
                        "sweep point (mean, standard error, 95% interval).")
    pr.set_defaults(func=run)
    add_bed_options(pr)
    pr.add_argument("--seeds", required=True,
                    help="start-cloud seeds: e.g. 1-32 or 1-4,10 (integers >= 0)")
    pr.add_argument("--sweep", action="append", default=None, metavar="KEY=V1,V2,...",
                    help=f"swept parameter, KEY one of {', '.join(SWEEPABLE)} or a numeric "
                    "parameter of --element (e.g. thickness=0.03,0.06,0.12 for pall_ring; see "
                    "--element); repeat for a Cartesian product")
    pr.add_argument("--out", required=True, help="output directory (the ledger)")
    pr.add_argument("--scheduler", default=None,
                    help="address of a running Dask scheduler, tcp://HOST:8786 (default: "
                    "$DASK_SCHEDULER_ADDRESS, else an embedded LocalCluster)")
    pr.add_argument("--workers", default=None, help="LocalCluster worker processes "
                    "(default cores // --threads)")
    pr.add_argument("--threads", default=None,
                    help="Numba threads per realization (default 1)")
    for field, flag in _FIXED.items():
        pr.add_argument(flag, dest=field, default=None,
                        help=f"fixed {field} of every realization (default: the page's)")
    pr.add_argument("--quiet", action="store_true", help="no progress bar")
    return pr


def _number(flag, text, integer):
    """CLI text -> a number for check_field / check_int (which name ``flag``)."""
    from peclet.core.validation import PecletArgumentError

    try:
        v = float(text)
    except ValueError:
        raise PecletArgumentError(flag, "an integer" if integer else "a number", text) \
            from None
    if integer and not (math.isfinite(v) and v.is_integer()):
        raise PecletArgumentError(flag, "an integer", text)
    return int(v) if integer else v


def _specs(args):
    """(specs, sweep) from the arguments; every error names its flag."""
    from peclet.core.validation import PecletArgumentError, check_int
    from peclet.ensemble.runner import machine_cores
    from peclet.ensemble.spec import check_field, make_specs, parse_seeds, parse_sweep
    from peclet.packing.bed.elements import element_text, parse_element
    from peclet.packing.bed.user_shapes import file_element_text

    seeds = parse_seeds(args.seeds, "--seeds")
    element = file_element_text(args.element, "--element")
    if element is None:
        element = element_text(*parse_element(args.element, "--element"))
    sweep = parse_sweep(args.sweep, "--sweep", element=element)
    fixed = {}
    for field, flag in _FIXED.items():
        text = getattr(args, field)
        if text is None:
            continue
        if field in sweep:
            raise PecletArgumentError("--sweep", f"a parameter not also fixed by {flag}",
                                      field)
        fixed[field] = check_field(field, _number(flag, text, field in ("count",
                                                                          "mc_samples")), flag)
    local = args.scheduler is None and not os.environ.get("DASK_SCHEDULER_ADDRESS")
    for flag, text in (("--workers", args.workers), ("--threads", args.threads)):
        if text is not None:
            # on this machine a realization cannot use more threads than it has cores
            hi = machine_cores() if local and flag == "--threads" else 4096
            check_int(flag, _number(flag, text, True), 1, hi)
    try:
        specs = make_specs(seeds, sweep, element=element, container=args.container,
                           protocol=args.protocol, **fixed)
    except PecletArgumentError as exc:
        # a spec field's error (e.g. steps_scale with --protocol rain) names its flag
        flag = dict(_FIXED, element="--element", container="--container",
                    protocol="--protocol").get(exc.argument)
        if flag is None:
            raise
        msg = str(exc)
        out = PecletArgumentError(flag, "", exc.value)
        out.args = (flag + msg[len(exc.argument):] if msg.startswith(exc.argument) else msg,)
        raise out from None
    return specs, sweep


def _table(points, swept):
    head = [*swept, "n", "eps (95% interval)", "f_env (95% interval)", "Z (95% interval)"]
    lines = []
    for p in points:
        cells = [f"{p[k]:g}" for k in swept] + [str(p["n"])]
        for name, fmt in (("eps", ".4f"), ("f_env", ".4f"), ("Z", ".3f")):
            m, se, lo, hi = (p[f"{name}_{s}"] for s in ("mean", "se", "ci_lo", "ci_hi"))
            cells.append(f"{m:{fmt}} +- {se:{fmt}} [{lo:{fmt}}, {hi:{fmt}}]"
                         if math.isfinite(se) else f"{m:{fmt}} (n < 2)")
        lines.append(cells)
    w = [max(len(str(r[i])) for r in [head] + lines) for i in range(len(head))]
    fmt = lambda r: "  ".join(f"{c:<{w[i]}}" for i, c in enumerate(r))  # noqa: E731
    return "\n".join([fmt(head), "-" * (sum(w) + 2 * len(w))] + [fmt(r) for r in lines])


def run(args):
    from peclet.ensemble import runner, summary

    specs, sweep = _specs(args)
    swept = list(sweep)
    workers = None if args.workers is None else int(args.workers)
    threads = None if args.threads is None else int(args.threads)
    try:
        rows = runner.run(specs, args.out, scheduler=args.scheduler, threads_per_worker=threads,
                          n_workers=workers, progress=not args.quiet, swept=swept,
                          log=lambda s: print(s, file=sys.stderr),
                          arg_names=dict(out="--out", scheduler="--scheduler"))
    except runner.EnsembleError as exc:
        print(f"peclet ensemble: {exc}; the others are in {args.out}; rerun to retry",
              file=sys.stderr)
        return 1
    points = summary.summarize(rows, swept)
    out = os.path.abspath(args.out)
    summary.write_csv(os.path.join(out, "summary.csv"), points)
    summary.write_json(os.path.join(out, "summary.json"), points, swept,
                       extra=dict(realizations=len(rows),
                                  reused=sum(r["reused"] for r in rows)))
    summary.write_figure(os.path.join(out, "summary.png"), points, rows, swept)
    print(_table(points, swept))
    print(f"\nwrote summary.csv, summary.json, summary.png and {len(rows)} realization(s) "
          f"in {out}", file=sys.stderr)
    return 0
