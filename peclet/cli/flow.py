"""``peclet flow``: permeability and pressure drop of a frozen pack (lattice Boltzmann).

    peclet flow pall_ring_pack.npz --out flow/                   (grid study D/8, D/16: default)
    peclet flow pall_ring_pack.npz --resolution D/16 --out flow/ (one resolution only)
    peclet flow pack.npz --resolutions 12,16,24 --out flow/      (grid study + Richardson)
    peclet flow rcp/grown.npz --axis x --out flow/               (a grown, triply periodic bed)
    peclet flow pack.npz --reynolds 0.01:100:8 --resolution D/8 --out curve/   (dP/L vs Re)
    peclet flow bed/pack.npz --resolution D/12 --out flow/       (a column: its section)
    peclet flow bed/pack.npz --resolutions 8,12,16 --out flow/   (the section's grid study)

A box pack along y (the default) takes k from the body force over the wrapped window's whole
period, its seam included, and prints the fit away from the seam beside it; along x or z the
body force is exact (peclet.flow.permeability, "Where dP/L comes from"); the force balance
(wall force / body force) is the check for both.

A pack made in a column (``peclet pack --container column:N``) runs as a section of the bed
with the column's wall (read from the results.json beside the pack, or given by --container):
flow along the axis, periodic over the section, k and dP/L measured away from the section's
seam and compared with Eisfeld & Schnitzlein's wall-corrected Ergun equation
(peclet.flow.permeability).

A grown bed (``peclet pack --protocol grow``'s grown.npz) is triply periodic: the lattice is
its whole cell, the body force the exact dP/L along x, y or z (peclet.flow.packs).

By default k is computed at two resolutions and extrapolated (Richardson; order 2 assumed
with two, observed with three or more), so no single unconverged figure is the answer;
``--resolution`` runs one. ``--reynolds`` runs the pressure-drop curve instead (one steady run
per Reynolds number, the Forchheimer fit, Ergun and Eisfeld & Schnitzlein beside it;
peclet.flow.curve), writing ``curve.json`` and ``curve.png``. Every run prints the container,
the flow axis and the window it used.

Any pack peclet writes (``peclet pack``'s pack.npz, ``peclet pall-ring``'s
pall_ring_pack.npz, a grown bed's grown.npz). Writes into --out ``results.json`` (every resolution's k, dP/L, Kozeny
constant, Ergun ratios, drag spread; the extrapolated k), ``velocity.vti``, ``velocity.vtu``
(the finest run's field, lattice units) and ``slice.png``; prints a table. Every argument is
checked before any work: a bad one is one line naming its flag, exit code 2.
"""
from __future__ import annotations

import math
import os
import time
import warnings

from peclet.core.validation import PecletArgumentError

from .options import number, threads_option

__all__ = ["add_parser", "run", "parse_resolution", "OUTPUTS"]

OUTPUTS = ("results.json", "velocity.vti", "velocity.vtu", "slice.png")
#: What ``--reynolds`` writes.
CURVE_OUTPUTS = ("curve.json", "curve.png")
#: The grid study run unless told otherwise (cells per D).
DEFAULT_STUDY = (8.0, 16.0)
#: Defaults of the curve's Mach bound and lowest viscosity (peclet.flow.curve).
MACH = 0.3
NU_MIN = 2e-3


def add_parser(sub):
    p = sub.add_parser("flow", help="permeability of a frozen pack (lattice Boltzmann)",
                       description="Push a slow flow through a frozen pack (D3Q19 TRT "
                       "lattice Boltzmann on the exact trees) and report the permeability, "
                       "dP/L, the Kozeny constant and the Ergun viscous ratio; writes "
                       "results.json, velocity.vti, velocity.vtu and slice.png into --out.")
    p.set_defaults(func=run)
    a = p.add_argument
    a("pack", help="a pack .npz written by peclet (pack.npz, pall_ring_pack.npz)")
    a("--resolution", default=None, help="one resolution only (no grid study): cells per "
      "element diameter, D/N or N, N in [4, 64]; with --reynolds the curve's (default D/8)")
    a("--resolutions", default=None, help="the grid study's resolutions, comma-separated "
      f"(default {','.join(f'{r:g}' for r in DEFAULT_STUDY)}); k is extrapolated "
      "(Richardson: order 2 assumed with 2, observed with 3 or more)")
    a("--reynolds", default=None, help="a pressure-drop curve instead: lo:hi:n (n "
      "log-spaced Reynolds numbers rho U D / mu, 0 < lo <= hi <= 1000) or a comma list; one "
      "steady run each at --resolution (default D/8), the Forchheimer fit, curve.json and "
      "curve.png (peclet.flow.curve)")
    a("--mach", default=str(MACH), help="with --reynolds: bound on max|u| / c_s, in (0, 0.3] "
      f"(default {MACH:g})")
    a("--nu-min", default=str(NU_MIN), help="with --reynolds: lowest lattice viscosity, in "
      f"[1e-4, 1/6] (default {NU_MIN:g}, tau+ = 0.506)")
    a("--axis", default="y", help="flow direction x, y (the bed's axis, default) or z "
      "(a column: y)")
    a("--container", default=None, help="the pack's container: box (periodic) or column:N "
      "(N element diameters, as peclet pack); default: the one recorded in the results.json "
      "beside the pack, else box")
    a("--seam-margin", default="1", help="distance (D, >= 0) from the wrapped window's seam "
      "beyond which dP/L is measured (default 1)")
    a("--window", default=None, help="y0,y1: the bulk window in D (default: the page's, 1 D "
      "above the floor to 0.8 D below the highest centre; a column: the middle of the bed, "
      "2 D off the floor and the top)")
    a("--y-mode", default="wrap", help="wrap (the window periodic onto itself, with a seam; "
      "default), mirror (window + its mirror image: no seam, but k along y too high: "
      "peclet.flow.permeability) or open (refused: no walls)")
    a("--re", default="0.01", help="target Reynolds number U D / nu in (0, 10] (default 0.01)")
    a("--tol", default="1e-6", help="relative convergence tolerance on the mean velocity "
      "(default 1e-6; the force balance must also close to 1e-4: peclet.flow.solver)")
    a("--max-steps", default="100000", help="step limit per resolution (default 100000)")
    a("--threads", default=None, help="numba threads (default: numba's)")
    a("--out", default="flow_results", help="output directory (default ./flow_results)")
    a("--overwrite", action="store_true", help="replace an earlier run's outputs in --out")
    a("--quiet", action="store_true", help="no progress bar")
    return p


def parse_resolution(text, flag="--resolution"):
    """``D/16`` or ``16`` -> 16.0 (cells per D), in [4, 64]."""
    t = str(text).strip()
    if t.upper().startswith("D/"):
        t = t[2:]
    v = number(flag, t, float)
    if not 4.0 <= v <= 64.0:
        raise PecletArgumentError(flag, "D/N or N with N in [4, 64] cells per diameter", text)
    return v


def _options(args):
    from peclet.flow.permeability import Y_MODES
    if args.resolutions is not None:
        parts = [s for s in str(args.resolutions).split(",") if s.strip()]
        res = sorted({parse_resolution(s, "--resolutions") for s in parts})
        if len(res) < 2:
            raise PecletArgumentError("--resolutions", "at least 2 different resolutions",
                                      args.resolutions)
    elif args.resolution is not None:
        res = [parse_resolution(args.resolution)]
    elif args.reynolds is not None:
        res = [8.0]
    else:
        res = list(DEFAULT_STUDY)
    if args.reynolds is not None and len(res) > 1:
        raise PecletArgumentError("--resolutions", "left out with --reynolds (the curve runs "
                                  "at one --resolution)", args.resolutions)
    if args.axis not in ("x", "y", "z"):
        raise PecletArgumentError("--axis", "x, y or z", args.axis)
    if args.y_mode not in Y_MODES:
        raise PecletArgumentError("--y-mode", "mirror, wrap or open", args.y_mode)
    if args.y_mode == "open":
        raise PecletArgumentError("--y-mode", "mirror or wrap: the pack is not periodic in y "
                                  "and has no walls there, so fluid would leave the box",
                                  args.y_mode)
    window = None
    if args.window is not None:
        parts = str(args.window).split(",")
        if len(parts) != 2:
            raise PecletArgumentError("--window", "y0,y1 in D with y1 > y0", args.window)
        window = (number("--window", parts[0], float), number("--window", parts[1], float))
        if not (math.isfinite(window[0]) and math.isfinite(window[1])
                and window[1] > window[0]):
            raise PecletArgumentError("--window", "y0,y1 in D with y1 > y0", args.window)
    re_ = number("--re", args.re, float)
    if not (math.isfinite(re_) and 0.0 < re_ <= 10.0):
        raise PecletArgumentError("--re", "a number in (0, 10]", args.re)
    tol = number("--tol", args.tol, float)
    if not (math.isfinite(tol) and 0.0 < tol < 1.0):
        raise PecletArgumentError("--tol", "a number in (0, 1)", args.tol)
    steps = number("--max-steps", args.max_steps, int)
    if steps < 1:
        raise PecletArgumentError("--max-steps", "an integer >= 1", args.max_steps)
    margin = number("--seam-margin", args.seam_margin, float)
    if not (math.isfinite(margin) and margin >= 0.0):
        raise PecletArgumentError("--seam-margin", "a distance >= 0 in D", args.seam_margin)
    return res, window, re_, tol, steps, margin


def _reason(message):
    """The parenthesised reason at the end of a PecletArgumentError message ("... got 'x'
    (reason)"), or the whole message."""
    tail = message.split(", got ", 1)[-1]
    i = tail.find(" (")
    return tail[i + 2:-1] if i >= 0 and tail.endswith(")") else message


def _curve_options(args):
    """(Reynolds numbers, mach, nu_min) of --reynolds, --mach, --nu-min (None without
    --reynolds)."""
    if args.reynolds is None:
        return None
    from peclet.flow.curve import parse_reynolds
    rey = parse_reynolds(args.reynolds, "--reynolds")
    mach = number("--mach", args.mach, float)
    if not (math.isfinite(mach) and 0.0 < mach <= 0.3):
        raise PecletArgumentError("--mach", "a number in (0, 0.3]", args.mach)
    nu_min = number("--nu-min", args.nu_min, float)
    if not (math.isfinite(nu_min) and 1e-4 <= nu_min <= 1.0 / 6.0):
        raise PecletArgumentError("--nu-min", "a number in [1e-4, 1/6]", args.nu_min)
    return rey, mach, nu_min


def _load(args, window):
    """(pack, container, source) of the pack file: a grown bed is a periodic cell
    (peclet.flow.packs); other packs get --container or the one recorded beside them."""
    from peclet.flow.domain import PeriodicCell
    from peclet.flow.packs import load_flow_pack
    from peclet.flow.setup import _check_column_holds, pack_container
    try:
        pack, found, source = load_flow_pack(args.pack)
    except PecletArgumentError as exc:
        raise PecletArgumentError("pack", "a peclet pack file (.npz written by peclet pack, "
                                  "peclet pall-ring or peclet pack --protocol grow)", args.pack,
                                  _reason(str(exc))) from None
    if isinstance(found, PeriodicCell):
        for flag, v in (("--container", args.container), ("--window", window)):
            if v is not None:
                raise PecletArgumentError(flag, "left out for a grown (triply periodic) pack: "
                                          "the lattice is its whole periodic cell", v)
        return pack, found, source
    try:
        cont, source = pack_container(args.pack if args.container is None else pack,
                                      args.container)
        if cont is not None:
            _check_column_holds(pack, cont)
    except PecletArgumentError as exc:
        raise PecletArgumentError("--container", "box or column:N holding the pack",
                                  args.container, _reason(str(exc))) from None
    if cont is not None and args.axis != "y":
        raise PecletArgumentError("--axis", "y for a column section (the column's axis; its "
                                  "wall closes x and z)", args.axis)
    return pack, cont, source


def domain_line(info, axis):
    """One line stating the container, the flow axis and the window of a run."""
    kind = info["container"]
    y0, y1 = info["window"]
    if kind == "periodic":
        where = (f"a triply periodic cell {info['box'][0]:g} x {y1 - y0:g} x "
                 f"{info['box'][1]:g} D (grown bed): the lattice is one whole period, no "
                 "window and no seam")
    elif kind == "column":
        where = (f"a column section, diameter {info['column_diameter_D']:g} D, its wall closing "
                 f"x and z; window y in [{y0:.4g}, {y1:.4g}] D wrapped (seam kept out of dP/L)")
    else:
        where = (f"a periodic box {info['box'][0]:g} x {info['box'][1]:g} D in x and z; window "
                 f"y in [{y0:.4g}, {y1:.4g}] D ({info['y_mode']})")
    return f"domain: {where}; flow along {axis}; dP/L: {info.get('dpdl_source', '?')}"


def run(args):
    import numpy as np

    from peclet.core.files import write_json
    from peclet.core.outputs import check_output_dir, clear_outputs, recording
    from peclet.flow import output
    from peclet.flow.correlations import happel_kozeny
    from peclet.flow.permeability import ThinWallWarning, permeability, richardson
    from peclet.packing.bed.progress import Progress

    res, window, re_, tol, steps, margin = _options(args)
    curve_opts = _curve_options(args)
    threads = threads_option(args.threads)
    pack, cont, source = _load(args, window)
    from peclet.flow.permeability import check_lattice_memory
    flag = "--resolutions" if args.resolutions is not None else "--resolution"
    for r in res:               # every lattice of a grid study fits, before the first runs
        check_lattice_memory(pack, r, window, args.y_mode, cont, flag, f"D/{r:g}")
    out, previous = check_output_dir(args.out, CURVE_OUTPUTS if curve_opts else OUTPUTS,
                                     args.overwrite, "--out")
    if threads is not None:
        import numba
        numba.set_num_threads(threads)
    if curve_opts is not None:
        return _run_curve(args, pack, cont, res[0], window, curve_opts, tol, steps, margin,
                          out, previous)
    rows, runs = [], []
    for r in res:
        bar = Progress(steps, desc=f"flow D/{r:g}", enabled=not args.quiet,
                       note=None)
        t0 = time.perf_counter()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", ThinWallWarning)
            try:
                pf = permeability(pack, resolution=r, axis=args.axis, window=window,
                                  y_mode=args.y_mode, Re=re_, tol=tol, max_steps=steps,
                                  progress=bar, container=cont if cont is not None
                                  else "box", seam_margin=margin)
                pf.info["container_source"] = source
            finally:
                bar.close()
        for w in caught:
            print(f"peclet flow: warning: {w.message}", flush=True)
        s = pf.summary()
        s["kozeny_happel"] = happel_kozeny(s["eps"]) if s["eps"] < 1.0 else math.nan
        s["wall_seconds"] = time.perf_counter() - t0
        rows.append(s)
        runs.append(pf)
    study = None
    if len(res) >= 2:
        study = richardson([1.0 / r for r in res], [s["k_D2"] for s in rows])
    finest = runs[-1]
    with recording(out, OUTPUTS):
        clear_outputs(out, previous)
        output.write_vti(os.path.join(out, "velocity.vti"), finest.flow)
        output.write_vtu(os.path.join(out, "velocity.vtu"), finest.flow)
        output.slice_figure(os.path.join(out, "slice.png"), finest.flow,
                            plane="xy" if args.axis != "z" else "yz",
                            title=f"|u| at D/{res[-1]:g}, mid-z plane (lattice units)")
        write_json(os.path.join(out, "results.json"),
                   {"pack": os.path.abspath(args.pack), "runs": rows, "richardson": study,
                    "elements": pack.n, "drag_finest": np.asarray(finest.drag).tolist()})
    print(domain_line(rows[-1], args.axis))
    print(table(rows, study))
    if rows[-1]["d_sauter"] < 0.9 * (6.0 * float(pack.ring_volume) / math.pi) ** (1.0 / 3.0):
        from peclet.flow.correlations import RING_NOTE
        print(f"note: {RING_NOTE}")
    print(f"\nwrote results.json, velocity.vti, velocity.vtu and slice.png in {out}")
    return 0


def table(rows, study=None):
    """The runs as a text table (one column per resolution)."""
    keys = [("k (D^2)", "k_D2", "{:.5g}"), ("k (cells^2)", "k_lattice", "{:.4g}"),
            ("dP/L (lattice)", "dpdl_lattice", "{:.3e}"), ("Re (U D / nu)", "Re", "{:.3g}"),
            ("porosity (lattice)", "eps", "{:.4f}"), ("Kozeny constant (d_s)", "kozeny",
                                                      "{:.3f}"),
            ("  Happel cell model at this eps", "kozeny_happel", "{:.3f}"),
            ("dP/L / Ergun, Sauter d", "ergun_ratio_sauter", "{:.3f}"),
            ("dP/L / Ergun, envelope d", "ergun_ratio_envelope", "{:.3f}"),
            ("drag spread (CV)", "drag_cv", "{:.3f}"), ("wall force / body force",
                                                         "solid_drag_balance", "{:.7f}"),
            ("period-2 swing of that", "parity_swing", "{:.2e}"),
            ("column D_t / d_p", "D_t_over_d_p", "{:.3f}"),
            ("porosity, core (> 1 D from wall)", "eps_core", "{:.4f}"),
            ("k whole period, seam incl. (D^2)", "k_D2_period", "{:.5g}"),
            ("k away from the seam, fit (D^2)", "k_D2_seam_free", "{:.5g}"),
            ("seam share of the drive", "seam_share", "{:+.4f}"),
            ("  its standard error", "seam_share_se", "{:.4f}"),
            ("Eisfeld-Schnitzlein A_w", "A_w", "{:.4f}"),
            ("dP/L / Eisfeld-Schnitzlein (wall)", "ergun_wall_ratio", "{:.3f}"),
            ("dP/L / Ergun, volume d, no wall", "ergun_ratio_volume", "{:.3f}"),
            ("column wall's share of the drag", "wall_drag_share", "{:.4f}"),
            ("steps", "steps", "{}"), ("converged", "converged", "{}"),
            ("MLUPS", "mlups", "{:.2f}"), ("wall time (s)", "wall_seconds", "{:.1f}")]
    head = ["", *[f"D/{r['resolution']:g}" for r in rows]]
    keys = [k for k in keys if all(k[1] in r for r in rows)]
    body = [[name, *[fmt.format(r[k]) for r in rows]] for name, k, fmt in keys]
    if study is not None:
        p = study["p"]
        body.append(["k extrapolated (D^2)", f"{study['k0']:.5g}"
                     + (" (order 2 assumed: two resolutions cannot show the order; three, "
                        "e.g. --resolutions 8,12,16, give the observed one)"
                        if study["assumed_p"] else
                        f" (observed order {p:.2f})" if math.isfinite(p) else
                        " (not monotone: finest value)")] + [""] * (len(rows) - 1))
    w = [max(len(str(x[i])) for x in [head] + body) for i in range(len(head))]
    line = lambda r: "  ".join(str(c).ljust(w[i]) if i == 0 else str(c).rjust(w[i])
                               for i, c in enumerate(r))
    return "\n".join([line(head), "  ".join("-" * x for x in w)] + [line(r) for r in body])


def _run_curve(args, pack, cont, resolution, window, opts, tol, steps, margin, out, previous):
    """``--reynolds``: the pressure-drop curve (peclet.flow.curve), its table, curve.json and
    curve.png."""
    from peclet.core.files import write_json
    from peclet.core.outputs import clear_outputs, recording
    from peclet.flow import output
    from peclet.flow.curve import pressure_drop_curve
    from peclet.flow.permeability import ThinWallWarning

    rey, mach, nu_min = opts
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ThinWallWarning)
        c = pressure_drop_curve(pack, rey, resolution=resolution, axis=args.axis,
                                window=window, y_mode=args.y_mode,
                                container=cont if cont is not None else "box", mach=mach,
                                nu_min=nu_min, tol=tol, max_steps=steps, seam_margin=margin)
    for w in caught:
        print(f"peclet flow: warning: {w.message}", flush=True)
    with recording(out, CURVE_OUTPUTS):
        clear_outputs(out, previous)
        write_json(os.path.join(out, "curve.json"),
                   {"pack": os.path.abspath(args.pack), **c.summary()})
        output.curve_figure(os.path.join(out, "curve.png"), c)
    print(domain_line(c.info, args.axis))
    print(f"D/{c.resolution:.4g}, eps {c.eps:.4f}, Sauter d {c.d_sauter:.4f} D, "
          f"Mach bound max|u| < {c.mach_bound:g} c_s, nu >= {c.nu_min:g}")
    print(output.curve_table(c))
    print(f"\nwrote curve.json and curve.png in {out}")
    return 0
