"""``peclet pack``: any element into any container, by the page's protocol or by rain.

    peclet pack --element sphere --container column:8 --count 500 --protocol rain \\
                --mu 0.3 --wall-mu 0.3 --out bed/
    peclet pack --resume bed/            # finish an interrupted run, bit for bit

Writes into --out: ``pack.npz`` (``freeze.save_pack``), ``results.json``, the analysis, figures
and exports of ``peclet.packing.profiles`` / ``export`` / ``bed_figures`` (where present), and
``checkpoint/`` while the run lasts (every --checkpoint-every steps; removed at the end unless
--keep-checkpoint). Prints a results table on stdout. Every argument is checked before any
expensive work: a bad one is one line naming it, exit code 2, nothing written.
"""
from __future__ import annotations

import dataclasses
import os
import shutil
import sys

from peclet.core.files import check_output_dir, clear_outputs
from peclet.core.validation import PecletArgumentError, check_float, check_int

from .options import add_bed_options

__all__ = ["add_parser", "run", "OUTPUTS"]

#: What a run writes into --out (an --out holding any of these is another run's).
OUTPUTS = ("results.json", "pack.npz", "checkpoint", "radial_profile.png", "axial_profile.png",
           "bed.png", "bed.stl", "bed.vtu", "transforms.csv")


def add_parser(sub):
    p = sub.add_parser("pack", help="pack any element into a box, column or walled box",
                       description="Pack elements into a container (page protocol or rain "
                       "deposition), analyse the bed and write pack.npz, results.json, "
                       "figures and exports into --out.")
    p.set_defaults(func=run)
    add_bed_options(p)
    p.add_argument("--count", default="48", help="number of elements (default 48)")
    p.add_argument("--mu", default="0.5", help="element-element friction (default 0.5)")
    p.add_argument("--wall-mu", default=None, help="wall friction (default: --mu)")
    p.add_argument("--restitution", default="0.15", help="normal restitution (default 0.15)")
    p.add_argument("--wall-restitution", default=None,
                   help="wall restitution (default: --restitution)")
    p.add_argument("--seed", default="5", help="generator seed >= 0 (default 5)")
    p.add_argument("--steps-scale", default="1",
                   help="page protocol: multiply every step count (default 1)")
    p.add_argument("--batch", default="1", help="rain: elements per insertion (default 1)")
    p.add_argument("--insert-every", default="4",
                   help="rain: steps between insertions (default 4)")
    p.add_argument("--drop", default="30", help="rain: insertion height above the bed, in D "
                   "(default 30)")
    p.add_argument("--out", default=None, help="output directory (default ./pack_results; "
                   "with --resume: the resumed run's)")
    p.add_argument("--threads", default=None, help="numba threads (default: numba's)")
    p.add_argument("--checkpoint-every", default="2000",
                   help="steps between checkpoints in OUT/checkpoint (default 2000)")
    p.add_argument("--resume", default=None, metavar="DIR",
                   help="finish the run checkpointed in DIR (its --out or DIR/checkpoint)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace the outputs of another run in --out")
    p.add_argument("--keep-checkpoint", action="store_true",
                   help="keep OUT/checkpoint after the run ends")
    p.add_argument("--samples", default="100000",
                   help="Monte Carlo points per bulk window (default 100000; the radial "
                        "profile takes 3 %% of it per 0.02 D shell, at least 500)")
    p.add_argument("--no-figures", action="store_true", help="skip figures and exports")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def _num(flag, text, conv, **rng):
    """``text`` converted (int/float) and range-checked, errors naming ``flag``."""
    try:
        v = conv(text)
    except (TypeError, ValueError):
        kind = "an integer" if conv is int else "a number"
        raise PecletArgumentError(flag, kind, text) from None
    return (check_int if conv is int else check_float)(flag, v, **rng)


def _renamed(exc, flag):
    """``exc`` (a PecletArgumentError) with its message naming the CLI ``flag``."""
    msg = str(exc)
    if msg.startswith(exc.argument):
        msg = flag + msg[len(exc.argument):]
    out = PecletArgumentError(flag, "", exc.value)
    out.args = (msg,)
    return out


def _check_out(out, overwrite, resuming_from=None):
    """(absolute --out, an earlier run's outputs in it) after the shared output-directory
    checks; a resumed run's own checkpoint does not count as another run's."""
    return check_output_dir(out, OUTPUTS, overwrite, "--out", dirs=("checkpoint",),
                            keep=(resuming_from,))


def run(args):
    from peclet.packing import api
    from peclet.packing import checkpoint as ckpt

    threads = None if args.threads is None else _num("--threads", args.threads, int, lo=1)
    every = _num("--checkpoint-every", args.checkpoint_every, int, lo=1)
    args.samples = _num("--samples", args.samples, int, lo=1000)
    if args.resume is not None:
        cdir = args.resume
        if not ckpt.is_checkpoint(cdir) and ckpt.is_checkpoint(os.path.join(cdir, "checkpoint")):
            cdir = os.path.join(cdir, "checkpoint")
        if not ckpt.is_checkpoint(cdir):
            raise PecletArgumentError("--resume", "a pack checkpoint directory (an interrupted "
                                      "run's --out or its checkpoint/)", args.resume)
        base = os.path.dirname(os.path.abspath(cdir)) \
            if os.path.basename(os.path.abspath(cdir)) == "checkpoint" else cdir
        out, previous = _check_out(args.out or base, args.overwrite, resuming_from=cdir)
        try:
            api._check_run_args(1, 0, threads, not args.quiet, None, None, None)
            res = api.resume(cdir, progress=not args.quiet, threads=threads,
                             checkpoint_every=every)
        except PecletArgumentError as exc:
            raise _renamed(exc, "--resume") from None
        return _finish(res, out, args, cdir, previous)

    # ---- every check before the element is built
    count = _num("--count", args.count, int, lo=1)
    seed = _num("--seed", args.seed, int, lo=0)
    mu = _num("--mu", args.mu, float, lo=0.0)
    wmu = mu if args.wall_mu is None else _num("--wall-mu", args.wall_mu, float, lo=0.0)
    e = _num("--restitution", args.restitution, float, lo=0.0, hi=1.0)
    we = e if args.wall_restitution is None else _num("--wall-restitution",
                                                      args.wall_restitution, float, lo=0.0,
                                                      hi=1.0)
    scale = _num("--steps-scale", args.steps_scale, float, lo=0.0, lo_open=True)
    if args.protocol not in ("page", "rain"):
        raise PecletArgumentError("--protocol", "one of 'page', 'rain'", args.protocol)
    for flag, value, parse in (("--element", args.element, api._resolve_element),
                               ("--container", args.container, api.parse_container)):
        try:
            parse(value)
        except PecletArgumentError as exc:
            raise _renamed(exc, flag) from None
    out, previous = _check_out(args.out or "pack_results", args.overwrite)
    batch = _num("--batch", args.batch, int, lo=1)
    every_k = _num("--insert-every", args.insert_every, int, lo=1)
    drop = _num("--drop", args.drop, float, lo=0.0)
    proto = api.parse_protocol(args.protocol)
    if args.protocol == "page" and scale != 1.0:
        proto = proto.scaled(scale)
    if args.protocol == "rain":
        proto = dataclasses.replace(proto, batch=batch, insert_every=every_k, drop=drop)
    cdir = os.path.join(out, "checkpoint")
    if args.overwrite and os.path.isdir(cdir):   # the rest is replaced when the run is done
        shutil.rmtree(cdir)
    from peclet.packing import Material
    try:
        res = api.pack(args.element, args.container, count, proto, Material(e, 0.0, mu),
                       Material(we, 0.0, wmu), seed=seed, threads=threads,
                       progress=not args.quiet, checkpoint_dir=cdir, checkpoint_every=every)
    except PecletArgumentError as exc:
        flag = {"container": "--container", "element": "--element"}.get(exc.argument)
        if flag is None:
            raise
        raise _renamed(exc, flag) from None
    return _finish(res, out, args, cdir, previous)


def _finish(res, out, args, cdir, previous):
    from peclet.packing import report as bed_report
    from peclet.packing.freeze import save_pack

    os.makedirs(out, exist_ok=True)
    # no figure of the old run left beside the new results (its checkpoint went before the
    # run; the one this run wrote is handled below)
    clear_outputs(out, tuple(f for f in previous if f != "checkpoint"))
    save_pack(os.path.join(out, "pack.npz"), res.pack)
    report = bed_report.analyse(res, out, figures=not args.no_figures,
                                exports=not args.no_figures, samples=args.samples,
                                shell_samples=max(500, args.samples * 3 // 100))
    bed_report.write_results(os.path.join(out, "results.json"), res, report)
    if not args.keep_checkpoint and os.path.isdir(cdir):
        shutil.rmtree(cdir)
    print(bed_report.table(res, report))
    print(f"\nwrote {os.path.join(out, 'results.json')}, pack.npz and the rest in {out}",
          file=sys.stderr)
    return 0

