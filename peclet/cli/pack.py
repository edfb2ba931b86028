"""``peclet pack``: any element into any container, by the page's protocol or by rain.

    peclet pack --element sphere --container column:8 --count 500 --protocol rain \\
                --mu 0.3 --wall-mu 0.3 --out bed/
    peclet pack --resume bed/            # finish an interrupted run, bit for bit

Writes into --out: ``pack.npz`` (``freeze.save_pack``), ``results.json``, the analysis, figures
and exports of ``peclet.packing.analysis.profiles`` / ``export`` / ``bed_figures`` (where present), and
``checkpoint/`` while the run lasts (every --checkpoint-every steps; removed at the end unless
--keep-checkpoint). Prints a results table on stdout. Every argument is checked before any
expensive work: a bad one is one line naming it, exit code 2, nothing written.
"""
from __future__ import annotations

import dataclasses
import os
import sys

from peclet.core.outputs import check_output_dir, clear_outputs, recording
from peclet.core.validation import PecletArgumentError, check_float, check_int

from .options import HERTZ_OPTIONS, add_bed_options, add_contact_options, contact_option

__all__ = ["add_parser", "run", "OUTPUTS"]

#: What a run writes into --out (an --out holding any of these is another run's).
OUTPUTS = ("results.json", "pack.npz", "checkpoint", "radial_profile.png", "axial_profile.png",
           "bed.png", "bed.stl", "bed.vtu", "transforms.csv", "bed_stl")

#: The OUTPUTS that are directories (bed_stl/: --stl-layout per-element).
OUTPUT_DIRS = ("checkpoint", "bed_stl")


def add_parser(sub):
    p = sub.add_parser("pack", help="pack any element into a box, column or walled box",
                       description="Pack elements into a container (page protocol or rain "
                       "deposition), analyse the bed and write pack.npz, results.json, "
                       "figures and exports into --out.")
    p.set_defaults(func=run)
    add_bed_options(p, ("page", "rain", "grow"))
    p.set_defaults(container=None)      # grow: the periodic cube; page and rain: box:3.5
    add_contact_options(p)
    p.add_argument("--count", default="48", help="number of elements (default 48)")
    p.add_argument("--mu", default="0.5", help="element-element friction (default 0.5)")
    p.add_argument("--wall-mu", default=None, help="wall friction (default: --mu)")
    p.add_argument("--restitution", default="0.15", help="normal restitution (default 0.15)")
    p.add_argument("--wall-restitution", default=None,
                   help="wall restitution (default: --restitution)")
    p.add_argument("--seed", default="5", help="generator seed >= 0 (default 5)")
    p.add_argument("--steps-scale", default=None,
                   help="page protocol only: multiply every step count (default 1)")
    p.add_argument("--batch", default=None,
                   help="rain only: elements per insertion (default 1)")
    p.add_argument("--insert-every", default=None,
                   help="rain only: steps between insertions (default 4)")
    p.add_argument("--drop", default=None, help="rain only: insertion height above the bed, "
                   "in D, in [0, 1e4] (default 30)")
    p.add_argument("--rate", default=None, help="grow only: starting growth rate d ln(phi)/dt "
                   "in (0, 10], at least 1e-4 (default 0.5; the overlap control slows it near "
                   "jamming)")
    p.add_argument("--target-phi", default=None, help="grow only: stop when the envelope "
                   "fraction of the container reaches this, in (start fraction, 1) (default: "
                   "grow to jamming)")
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
    p.add_argument("--stl-resolution", default=None, type=_stl_resolution,
                   help="element mesh of bed.stl and bed.vtu: a chord error in element "
                        "diameters D in [0.005, 0.1] (e.g. 0.01 or 0.01D) or a triangle "
                        "budget per element 'Ntri', N in [100, 200000] (e.g. 2000tri); "
                        "default 1000tri (1000 Pall rings: STL 50 MB + VTU 23 MB)")
    p.add_argument("--stl-layout", default="merged", choices=("merged", "per-element"),
                   help="merged (default): one bed.stl (ASCII, one named solid per element "
                        "and the container, up to 200 elements; binary, one solid, above); "
                        "per-element: bed_stl/ with one binary STL per element and "
                        "container.stl")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def _stl_resolution(text):
    """--stl-resolution's argparse type: the canonical text (e.g. "1000tri", "0.01D"); a bad
    value is one line naming the flag, exit 2, before any work."""
    import argparse

    from peclet.packing.output.export import parse_resolution

    try:
        return str(parse_resolution(text, "--stl-resolution"))
    except PecletArgumentError as exc:
        raise argparse.ArgumentTypeError(str(exc)[len("--stl-resolution "):]) from None


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


#: Options only one protocol uses: given with the other, they are refused (as ``peclet
#: ensemble`` refuses ``--steps-scale`` with rain), never silently ignored.
PROTOCOL_OPTIONS = {"--steps-scale": ("steps_scale", "page"), "--batch": ("batch", "rain"),
                    "--insert-every": ("insert_every", "rain"), "--drop": ("drop", "rain"),
                    "--rate": ("rate", "grow"), "--target-phi": ("target_phi", "grow")}

#: Most Monte Carlo points per bulk window: each costs about 100 bytes at the sampling's peak
#: (coordinates, the counts, the window's temporaries), so 10^7 are about 1 GB.
SAMPLES_MAX = 10_000_000
BYTES_PER_SAMPLE = 100


def _protocol_options(args):
    """Refuse an option the chosen protocol does not use (one line naming it)."""
    for flag, (dest, proto) in PROTOCOL_OPTIONS.items():
        if getattr(args, dest) is not None and args.protocol != proto:
            raise PecletArgumentError(flag, f"given only with --protocol {proto} (the "
                                      f"{args.protocol} protocol does not use it)",
                                      getattr(args, dest))


def _missing_file(flag, path, what):
    """PecletArgumentError naming ``flag`` when ``path`` does not exist."""
    if not os.path.exists(path):
        raise PecletArgumentError(flag, what, path, "it does not exist")


def _bed_rules(element, container, count, proto, seed):
    """The checks that need the element's size but not its measurement (a second or two):
    the container fits the element and the start cloud (page protocol: ``PageProtocol.start``)
    stays in it, the page's start cloud lands before the quench (``check_landing``, the rule
    of ``peclet pall-ring``), and the count forms a bed: at least one element per D^2 of the
    container's cross-section (fewer cannot cover the floor once: a film whose bulk window
    holds next to nothing). Errors name the CLI flags."""
    import numpy as np

    from peclet.packing.bed import api
    from peclet.packing.bed.protocols import Body

    el = api.resolve_element(element)
    d = api.element_diameter(el)
    cont = api.parse_container(container).bound(d)
    c0, r0, _ = el.builder.node_bound(el.root)
    ctx = dict(container=cont, body=Body(-1, 1.0, np.ones(3), float(np.linalg.norm(c0) + r0),
                                         d), count=count)
    try:
        _, _, _, top = proto.start(ctx, np.random.default_rng(seed))
        if proto.kind == "page":
            proto.check_landing(ctx, top, "--count")
    except PecletArgumentError as exc:
        raise _renamed(exc, {"count": "--count", "container": "--container"}.get(
            exc.argument, exc.argument)) from None
    layer = cont.cross_area() / (d * d)
    if cont.kind != "tree" and count < layer:
        raise PecletArgumentError(
            "--count", f">= {int(np.ceil(layer))} for {cont.label()} (the bed rule: at least "
            "one element per D^2 of the cross-section, a bed about one element deep; fewer "
            "is a film)", count, f"cross-section {layer:.4g} D^2")


def _landed(res, out):
    """The landing rule after the run (``protocols``): True if the bed landed; otherwise the
    pack is saved to OUT/pack.npz, one error line says why and the bed is not analysed."""
    from peclet.packing.bed.api import landing_message
    from peclet.packing.bed.freeze import save_pack

    rec = res.state.landing
    if rec is None or rec["landed"]:
        return True
    os.makedirs(out, exist_ok=True)
    save_pack(os.path.join(out, "pack.npz"), res.pack)
    print(f"peclet pack: error: {landing_message(rec)}; not analysed (the state is in "
          f"{os.path.join(out, 'pack.npz')})", file=sys.stderr)
    return False


def _check_out(out, overwrite, resuming_from=None):
    """(absolute --out, an earlier run's outputs in it) after the shared output-directory
    checks; a resumed run's own checkpoint does not count as another run's."""
    return check_output_dir(out, OUTPUTS, overwrite, "--out", dirs=OUTPUT_DIRS,
                            keep=(resuming_from,))


def run(args):
    from peclet.packing.bed import api
    from peclet.packing.bed import checkpoint as ckpt
    from peclet.packing.bed.containers import MAX_DROP

    threads = None if args.threads is None else _num("--threads", args.threads, int, lo=1)
    every = _num("--checkpoint-every", args.checkpoint_every, int, lo=1)
    args.samples = _num("--samples", args.samples, int, lo=1000)
    if args.samples > SAMPLES_MAX:
        raise PecletArgumentError("--samples", f"an integer in [1000, {SAMPLES_MAX}]",
                                  args.samples, f"about {BYTES_PER_SAMPLE} bytes per sample "
                                  f"at the sampling's peak: {SAMPLES_MAX} is about "
                                  f"{SAMPLES_MAX * BYTES_PER_SAMPLE / 1e9:g} GB")
    if args.resume is not None:
        for flag, value in [("--contact", args.contact)] + [
                (f, getattr(args, a)) for f, a in HERTZ_OPTIONS.items()]:
            if value is not None and not (flag == "--contact" and value == "impulse"):
                raise PecletArgumentError(flag, "left out with --resume (the checkpoint "
                                          "carries the run's contact law)", value)
        cdir = args.resume
        _missing_file("--resume", cdir, "a pack checkpoint directory (an interrupted run's "
                      "--out or its checkpoint/)")
        if not ckpt.is_checkpoint(cdir) and ckpt.is_checkpoint(os.path.join(cdir, "checkpoint")):
            cdir = os.path.join(cdir, "checkpoint")
        if not ckpt.is_checkpoint(cdir):
            raise PecletArgumentError("--resume", "a pack checkpoint directory (an interrupted "
                                      "run's --out or its checkpoint/)", args.resume)
        base = os.path.dirname(os.path.abspath(cdir)) \
            if os.path.basename(os.path.abspath(cdir)) == "checkpoint" else cdir
        out, previous = _check_out(args.out or base, args.overwrite, resuming_from=cdir)
        try:
            api.check_run_args(1, 0, threads, not args.quiet, None, None, None)
        except PecletArgumentError as exc:
            raise _renamed(exc, "--resume") from None
        with recording(out, OUTPUTS):
            try:
                res = api.resume(cdir, progress=not args.quiet, threads=threads,
                                 checkpoint_every=every)
            except PecletArgumentError as exc:
                raise _renamed(exc, "--resume") from None
            if not _landed(res, out):
                return 1
            return _finish(res, out, args, cdir, previous)

    # ---- every check before the element is built
    count = _num("--count", args.count, int, lo=1)
    try:
        api.check_run_args(count, 0, None, True, None, None, None, name="--count")
    except PecletArgumentError as exc:
        raise _renamed(exc, "--count") from None
    if not args.no_figures:      # the whole bed's export size, before the run
        from peclet.packing.output import export

        export.check_bed_triangles(count, args.stl_resolution or export.DEFAULT_RESOLUTION,
                                   "--stl-resolution")
    seed = _num("--seed", args.seed, int, lo=0)
    mu = _num("--mu", args.mu, float, lo=0.0)
    wmu = mu if args.wall_mu is None else _num("--wall-mu", args.wall_mu, float, lo=0.0)
    e = _num("--restitution", args.restitution, float, lo=0.0, hi=1.0)
    we = e if args.wall_restitution is None else _num("--wall-restitution",
                                                      args.wall_restitution, float, lo=0.0,
                                                      hi=1.0)
    if args.protocol not in ("page", "rain", "grow"):
        raise PecletArgumentError("--protocol", "one of 'page', 'rain', 'grow'", args.protocol)
    _protocol_options(args)
    law = contact_option(args, args.protocol)
    if args.protocol == "grow":
        return _grow(args, count, seed, mu, e, threads)
    if args.container is None:
        args.container = "box:3.5"
    scale = 1.0 if args.steps_scale is None else _num("--steps-scale", args.steps_scale,
                                                       float, lo=0.0, hi=100.0, lo_open=True)
    if isinstance(args.element, str) and args.element.endswith(".npz"):
        _missing_file("--element", args.element, "a flat-encoding .npz (node_ints, "
                      "node_reals, root)")
    # the element's walls are checked against the probe lattice here, before --out is made
    for flag, value, parse in (("--element", args.element,
                                lambda v: api.check_walls(api.resolve_element(v))),
                               ("--container", args.container, api.parse_container)):
        try:
            parse(value)
        except PecletArgumentError as exc:
            raise _renamed(exc, flag) from None
    out, previous = _check_out(args.out or "pack_results", args.overwrite)
    batch = _num("--batch", "1" if args.batch is None else args.batch, int, lo=1)
    every_k = _num("--insert-every", "4" if args.insert_every is None else args.insert_every,
                   int, lo=1)
    drop = _num("--drop", "30" if args.drop is None else args.drop, float, lo=0.0,
                hi=MAX_DROP)
    proto = api.parse_protocol(args.protocol)
    if args.protocol == "page" and scale != 1.0:
        proto = proto.scaled(scale)
    if args.protocol == "rain":
        proto = dataclasses.replace(proto, batch=batch, insert_every=every_k, drop=drop)
    _bed_rules(args.element, args.container, count, proto, seed)
    from peclet.packing import Material
    if law is not None:        # E, nu and the step rule, printed with the dt it chose
        for m, flag in ((Material(e, 0.0, mu), "--restitution"),
                        (Material(we, 0.0, wmu), "--wall-restitution")):
            try:
                law.check_material(m, "material")
            except PecletArgumentError as exc:
                raise _renamed(exc, flag) from None
        model = api.element_model(api.resolve_element(args.element))
        try:
            print(f"peclet pack: {law.describe(model, proto.dt)}", file=sys.stderr)
        except PecletArgumentError as exc:
            raise _renamed(exc, "--youngs") from None
    cdir = os.path.join(out, "checkpoint")
    with recording(out, OUTPUTS):
        # the old checkpoint goes now; the rest is replaced when the run is done
        clear_outputs(out, tuple(f for f in previous if f == "checkpoint"))
        try:
            res = api.pack(args.element, args.container, count, proto, Material(e, 0.0, mu),
                           Material(we, 0.0, wmu), seed=seed, threads=threads,
                           progress=not args.quiet, checkpoint_dir=cdir,
                           checkpoint_every=every, contact=law)
        except PecletArgumentError as exc:
            flag = {"container": "--container", "element": "--element"}.get(exc.argument)
            if flag is None:
                raise
            raise _renamed(exc, flag) from None
        if not _landed(res, out):
            return 1
        return _finish(res, out, args, cdir, previous)


#: GrowSpec fields named by their flags in the errors of ``--protocol grow``.
GROW_FLAGS = {"count": "--count", "rate": "--rate", "container": "--container",
              "target_phi": "--target-phi", "wall_mu": "--wall-mu",
              "wall_e_n": "--wall-restitution", "element": "--element"}


def _grow(args, count, seed, mu, e, threads):
    """``--protocol grow``: growth to jamming or to --target-phi, in a periodic cube (no
    --container) or a closed box:AxBxC / column:N (peclet.packing.experiments.grow)."""
    from peclet.packing.experiments import grow as growth

    rate = 0.5 if args.rate is None else _num("--rate", args.rate, float, lo=0.0, hi=10.0,
                                              lo_open=True)
    floor = growth.GrowSpec().gamma_min
    if rate < floor:          # the spec would blame gamma_min, which the CLI does not set
        raise PecletArgumentError("--rate", f"in (0, 10] and >= {floor:g} (the rate below which "
                                  "the bed counts as jammed)", rate)
    target = None if args.target_phi is None else _num("--target-phi", args.target_phi, float,
                                                       lo=0.0, hi=1.0, lo_open=True,
                                                       hi_open=True)
    walls = {k: None if v is None else _num(flag, v, float, lo=0.0)
             for k, flag, v in (("wall_mu", "--wall-mu", args.wall_mu),
                                ("wall_e_n", "--wall-restitution", args.wall_restitution))}
    from peclet.packing.bed import api
    from peclet.packing.bed.user_shapes import is_user_file
    if is_user_file(args.element):          # sampled once, in the run (seconds for a mesh)
        _missing_file("--element", args.element.partition(":")[0], "a mesh file")
    else:
        try:
            api.resolve_element(args.element)
        except PecletArgumentError as exc:
            raise _renamed(exc, "--element") from None
    spec = growth.GrowSpec(element=args.element, count=count, rate=rate, mu=mu, e_n=e,
                           seed=seed, container=args.container or "periodic",
                           target_phi=target, **walls).checked(GROW_FLAGS)
    out, previous = check_output_dir(args.out or "pack_results", growth.OUTPUTS,
                                     args.overwrite, "--out")
    try:
        res = growth.grow(spec, progress=not args.quiet, threads=threads)
    except PecletArgumentError as exc:
        if exc.argument not in GROW_FLAGS:
            raise
        raise _renamed(exc, GROW_FLAGS[exc.argument]) from None
    with recording(out, growth.OUTPUTS):
        growth.write_outputs(res, out, previous, figures=not args.no_figures)
    print(growth.table(res))
    return 0


def _finish(res, out, args, cdir, previous):
    from peclet.packing.output import report as bed_report
    from peclet.packing.bed.freeze import save_pack

    os.makedirs(out, exist_ok=True)
    # no figure of the old run left beside the new results (its checkpoint went before the
    # run; the one this run wrote is handled below)
    clear_outputs(out, tuple(f for f in previous if f != "checkpoint"))
    save_pack(os.path.join(out, "pack.npz"), res.pack)
    from peclet.packing.output import export

    stl_res = getattr(args, "stl_resolution", None) or export.DEFAULT_RESOLUTION
    try:
        if not args.no_figures:
            export.check_bed_triangles(res.pack.n, stl_res, "stl_resolution")
        report = bed_report.analyse(res, out, figures=not args.no_figures,
                                    exports=not args.no_figures, samples=args.samples,
                                    shell_samples=max(500, args.samples * 3 // 100),
                                    stl_resolution=stl_res,
                                    stl_layout=getattr(args, "stl_layout", "merged"))
    except PecletArgumentError as exc:
        if exc.argument != "stl_resolution":
            raise
        raise _renamed(exc, "--stl-resolution") from None
    bed_report.write_results(os.path.join(out, "results.json"), res, report)
    if not args.keep_checkpoint:
        from peclet.packing.bed import checkpoint as ckpt
        ckpt.remove(cdir)
    print(bed_report.table(res, report))
    print(f"\nwrote {os.path.join(out, 'results.json')}, pack.npz and the rest in {out}",
          file=sys.stderr)
    return 0

