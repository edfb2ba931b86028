"""The flow solver beyond creeping flow, thin walls and grown packs (issue 44).

    python validation/flow_re.py [--quick] [--json FILE] [--rungs tube,grown,curve,stability]
                                 [--tube-resolutions 8,16] [--grown-pack grown.npz]
                                 [--curve-pack pack.npz] [--curve-container column:4]
                                 [--curve-resolution 8] [--reynolds 0.01:100:8]
                                 [--stability-reynolds 3,10,20,30]

1. ``tube``: a referee for thin walls. One tube (outer diameter D, wall 0.12 D: the page
   ring's wall) along x in a periodic box 1.5 D square, 1 D long; outside the tube a plate 0.25
   D thick across the flow closes the outer region (joined to the tube's wall), so only the
   bore carries flow and the fluid outside sits at rest on both sides of the thin wall. The
   bore's flow is Hagen-Poiseuille exactly: k_bore = (R_i^2 / 8) (pi R_i^2 / A_box), R_i =
   0.38 D, relative to the box's cross-section A_box. Compared: k = nu U / g with U the flux
   over uncut links per cell (the figure peclet reports for packs) against k_bore; beside it
   the nodal velocities in the bore against the parabola (relative L2) and the largest speed
   outside the tube relative to the bore's centre-line speed (a leak through the wall would
   show there). The axis is off the nodes (0.13, 0.29 cells) so the wall cuts links at many
   fractions. Accepted: within 1 % at D/16 (``peclet flow``'s former single resolution and
   the issue's page-pack figure; D/8, the page's ``--flow`` default, is reported beside it).
2. ``grown``: a grown, triply periodic pack (``--grown-pack``, written by ``peclet pack
   --protocol grow``; quick: 40 spheres grown here) through :func:`peclet.flow.permeability`
   along x, y and z: k against Carman-Kozeny, the Kozeny constant and Happel's.
3. ``curve``: dP/L against Re (:func:`peclet.flow.pressure_drop_curve`) for ``--curve-pack``
   (default: the grown pack; ``--curve-container`` the container it was made in, e.g.
   column:4 for the 90 spheres of ``validation.flow.rained_column(4, 90, seed=3)``) with the
   Forchheimer fit and the ratios to Ergun and Eisfeld & Schnitzlein.
4. ``stability``: why the curve stops. The same curve (``--stability-reynolds``, the curve's
   pack, container and resolution) with each wall rule and magic product of
   :data:`STABILITY_VARIANTS`: the corrected linear rule (the curve's), plain Bouzidi, halfway
   bounce-back on every link, and bounce-back with Lambda = 1/12. Per variant the highest
   steady Re, the first point that was not steady, its status and its cell Reynolds number
   max|u| / nu. If halfway bounce-back stops where the interpolated rules stop, the wall
   rule is not what limits the curve.

Prints tables; ``--json`` writes every number.
"""
from __future__ import annotations

import math
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:           # run as a script: the repository, for the package below
    sys.path.insert(0, ROOT)

from peclet.flow import Grid, build_geometry, solve  # noqa: E402

NU = 1.0 / 6.0
#: The page ring's wall (D).
PAGE_WALL = 0.12


def tube(resolution=16, wall=PAGE_WALL, box=1.5, length=1.0, plate=0.25, g=1e-6, tol=1e-9,
         max_steps=200_000):
    """The tube referee (module docstring) at ``resolution`` cells per D. Lengths in cells
    inside; returns the figures in D."""
    res = float(resolution)
    ro, ri = 0.5 * res, (0.5 - wall) * res
    nx = int(round(length * res))
    n = int(round(box * res))
    cy, cz = 0.5 * n + 0.13, 0.5 * n + 0.29
    xc = 0.5 * nx
    mid = 0.5 * (ri + ro)

    def phi(p):
        r = np.hypot(p[:, 1] - cy, p[:, 2] - cz)
        wall_sd = np.maximum(r - ro, ri - r)                  # < 0 in the tube's wall
        dx = np.abs(np.mod(p[:, 0] - xc + 0.5 * nx, nx) - 0.5 * nx)
        plate_sd = np.maximum(dx - 0.5 * plate * res, mid - r)  # < 0 in the outer plate
        return np.minimum(wall_sd, plate_sd)
    grid = Grid((0.0, 0.0, 0.0), 1.0, (nx, n, n), (True, True, True))
    geo = build_geometry(grid, phi)
    t0 = time.perf_counter()
    r = solve(geo, [g, 0.0, 0.0], nu=NU, tol=tol, max_steps=max_steps)
    k = NU * float(r.U[0]) / g / res ** 2
    k_exact = (0.5 - wall) ** 2 / 8.0 * math.pi * (0.5 - wall) ** 2 / box ** 2
    rr = np.hypot(geo.ijk[:, 1] - cy, geo.ijk[:, 2] - cz)
    bore = rr < ri
    ue = g / (4.0 * NU) * (ri * ri - rr[bore] ** 2)
    ub = r.u[bore, 0]
    outside = rr > ro
    return {"resolution": res, "wall_cells": wall * res, "R_i_cells": ri, "k_D2": k,
            "k_exact_D2": k_exact, "err": k / k_exact - 1.0,
            "bore_l2": float(np.sqrt(((ub - ue) ** 2).sum() / (ue ** 2).sum())),
            "outside_speed": float(np.abs(r.u[outside]).max() / (g / (4.0 * NU) * ri * ri)),
            "thin_links": int(geo.thin_links), "steps": r.steps, "converged": r.converged,
            "balance": r.balance, "seconds": time.perf_counter() - t0}


def grown_bed(path, resolution=8, axes=("x", "y", "z"), tol=1e-6):
    """k of a grown pack along each axis against Carman-Kozeny (k = eps^3 d^2 / (180 (1 -
    eps)^2), d the Sauter diameter) and the Kozeny constant against Happel's."""
    from peclet.flow import permeability
    from peclet.flow.correlations import carman_kozeny, happel_kozeny
    rows = []
    for ax in axes:
        pf = permeability(path, resolution=resolution, axis=ax, tol=tol)
        ck = carman_kozeny(pf.eps, pf.d_sauter)
        rows.append({"axis": ax, "resolution": pf.resolution, "eps": pf.eps, "k_D2": pf.k_D2,
                     "k_ck": ck, "ratio_ck": pf.k_D2 / ck, "kozeny": pf.kozeny,
                     "kozeny_happel": happel_kozeny(pf.eps),
                     "ergun_ratio": pf.ergun_ratio_sauter, "steps": pf.flow.steps,
                     "converged": pf.flow.converged, "balance": pf.solid_drag_balance,
                     "dims": pf.info["dims"], "elements": int(pf.drag.size),
                     "seconds": pf.flow.seconds})
    return rows


def curve(path, reynolds, resolution=8, axis="y", max_steps=200_000, tol=1e-6,
          container=None):
    """:func:`peclet.flow.pressure_drop_curve` of ``path`` (in ``container``): its summary."""
    from peclet.flow import pressure_drop_curve
    from peclet.flow.output import curve_table
    c = pressure_drop_curve(path, reynolds, resolution=resolution, axis=axis, tol=tol,
                            max_steps=max_steps, container=container)
    print(curve_table(c), flush=True)
    return c.summary()


#: (scheme, magic) of the ``stability`` rung: the curve's rule first.
STABILITY_VARIANTS = (("linear", 0.25), ("bouzidi", 0.25), ("bounce_back", 0.25),
                      ("bounce_back", 1.0 / 12.0))


def stability(path, reynolds, resolution=8, axis="y", container=None, tol=1e-5,
              max_steps=40_000, variants=STABILITY_VARIANTS):
    """The ``stability`` rung (module docstring): per (scheme, magic) of ``variants`` one
    :func:`peclet.flow.pressure_drop_curve` over ``reynolds``; the rows."""
    from peclet.flow import pressure_drop_curve
    rows = []
    for scheme, magic in variants:
        t0 = time.perf_counter()
        c = pressure_drop_curve(path, reynolds, resolution=resolution, axis=axis, tol=tol,
                                max_steps=max_steps, container=container, scheme=scheme,
                                magic=magic)
        ok = [p for p in c.points if p.status == "steady"]
        bad = next((p for p in c.points if p.status not in ("steady", "not run")), None)
        rows.append({"scheme": scheme, "magic": magic, "Re_steady": ok[-1].Re if ok else None,
                     "cell_re_steady": ok[-1].cell_re if ok else None,
                     "f": [p.f for p in c.points], "Re": [p.Re for p in c.points],
                     "stop_Re_target": bad.Re_target if bad else None,
                     "stop_status": bad.status if bad else "", "stop_nu": bad.nu if bad else None,
                     "stop_cell_re": bad.cell_re if bad else None,
                     "seconds": time.perf_counter() - t0})
        print(f"   {scheme}, Lambda {magic:.4g}: steady to Re "
              f"{rows[-1]['Re_steady']}, then {rows[-1]['stop_status'] or 'nothing'} at Re "
              f"{rows[-1]['stop_Re_target']} (cell Re {rows[-1]['stop_cell_re']})", flush=True)
    return rows


def grow_spheres(out, count=40, seed=3):
    """A small grown sphere bed (``peclet pack --protocol grow``) in ``out``: its grown.npz."""
    from peclet.packing.experiments import grow as growth
    res = growth.grow(growth.GrowSpec(count=count, mu=0.0, seed=seed), progress=False)
    growth.write_outputs(res, out, figures=False)
    return os.path.join(out, "grown.npz")


def _table(rows, cols):
    from benchmarks._report import table
    return table([[r[c] if not isinstance(r[c], float) else f"{r[c]:.5g}" for c in cols]
                  for r in rows], cols)


RUNGS = ("tube", "grown", "curve", "stability")


def _rungs(text):
    import argparse
    parts = {t.strip() for t in str(text).split(",") if t.strip()}
    if not parts or parts - set(RUNGS):
        raise argparse.ArgumentTypeError(f"must be a comma-separated subset of "
                                         f"{','.join(RUNGS)}, got {text!r}")
    return parts


def main(argv=None):
    import json
    import tempfile
    import warnings

    import validation as vargs
    ap = vargs.ScriptParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="reduced sizes")
    ap.add_argument("--json", type=vargs.output_file, default=None, help="write the results")
    ap.add_argument("--rungs", type=_rungs, default=set(RUNGS),
                    help="subset of " + ",".join(RUNGS))
    ap.add_argument("--tube-resolutions", type=vargs.integer_list(4, 64), default=None,
                    help="cells per D (default 8,16; quick 8)")
    ap.add_argument("--grown-pack", type=vargs.input_file, default=None,
                    help="a grown.npz (default: 40 spheres grown here)")
    ap.add_argument("--grown-resolutions", type=vargs.integer_list(4, 64), default=None,
                    help="cells per D, grid study along x (default 8,16; quick 6)")
    ap.add_argument("--curve-pack", type=vargs.input_file, default=None,
                    help="the curve's pack (default the grown pack)")
    ap.add_argument("--curve-container", default=None,
                    help="the curve's container, e.g. column:4 (default: the pack's own)")
    ap.add_argument("--curve-resolution", type=vargs.integer(4, 64), default=8,
                    help="cells per D (default 8)")
    ap.add_argument("--curve-axis", default="y", help="x, y or z (default y)")
    ap.add_argument("--reynolds", default="0.01:100:8", help="lo:hi:n (default 0.01:100:8)")
    ap.add_argument("--stability-reynolds", default="3,10,20,30",
                    help="the stability rung's Reynolds numbers (default 3,10,20,30)")
    a = ap.parse_args(argv)
    rungs = a.rungs
    warnings.simplefilter("ignore")
    out = {}
    if "tube" in rungs:
        out["tube"] = [tube(r) for r in (a.tube_resolutions or ((8,) if a.quick else (8, 16)))]
        print("1. tube, wall 0.12 D, outer region closed: k against Hagen-Poiseuille in the "
              "bore\n" + _table(out["tube"], ["resolution", "wall_cells", "R_i_cells", "k_D2",
                                             "k_exact_D2", "err", "bore_l2", "outside_speed",
                                             "steps"]), flush=True)
    grown = a.grown_pack
    if grown is None and rungs & {"grown", "curve", "stability"}:
        grown = grow_spheres(tempfile.mkdtemp(prefix="peclet-grown-"), 40 if a.quick else 180)
    if "grown" in rungs:
        rs = a.grown_resolutions or ((6,) if a.quick else (8, 16))
        rows = [grown_bed(grown, r, axes=("x",))[0] for r in rs]
        out["grown"] = {"pack": grown, "runs": rows}
        print("\n2. grown pack " + grown + "\n" + _table(rows, [
            "axis", "resolution", "eps", "k_D2", "ratio_ck", "kozeny", "kozeny_happel",
            "ergun_ratio", "balance", "steps"]), flush=True)
        if len(rows) >= 2:
            from peclet.flow import richardson
            ext = richardson([1.0 / r["resolution"] for r in rows], [r["k_D2"] for r in rows])
            fin = rows[-1]
            ext["ratio_ck"] = ext["k0"] / fin["k_ck"]
            ext["kozeny"] = fin["kozeny"] * fin["k_D2"] / ext["k0"]
            out["grown"]["richardson"] = ext
            print(f"   extrapolated k = {ext['k0']:.5g} D^2, {ext['ratio_ck']:.4f} of "
                  f"Carman-Kozeny (Sauter d), Kozeny constant {ext['kozeny']:.3f}")
    if "curve" in rungs:
        path = a.curve_pack or grown
        print(f"\n3. pressure drop curve, {path}", flush=True)
        out["curve"] = curve(path, a.reynolds, a.curve_resolution, a.curve_axis,
                             container=a.curve_container)
    if "stability" in rungs:
        path = a.curve_pack or grown
        print(f"\n4. why the curve stops, {path} at D/{a.curve_resolution}", flush=True)
        out["stability"] = stability(path, a.stability_reynolds, a.curve_resolution,
                                     a.curve_axis, container=a.curve_container)
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(out, fh, indent=1, default=float)
    return 0


if __name__ == "__main__":
    import validation as vargs
    sys.exit(vargs.run(main))
