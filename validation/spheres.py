"""Spheres against the packed-bed literature: the whole chain (rain deposition, contacts, walls,
analysis) on the textbook case.

    python validation/spheres.py [--quick] [--out validation/results/spheres.json]

1. Columns: monodisperse spheres, mu = mu_wall = 0.3, e_n = 0.3 ("glass-like"), rained into
   columns of N = D_t / d = 5, 8, 10 (``RainProtocol`` below: one sphere every 4 steps =
   125 spheres per unit time, inserted ``drop`` d above the bed's top at 2 d/time downward,
   settled to KE < 1e-5 m g d per sphere, quenched). Bed height about 10 d (floor and free
   surface zones of 2 d cropped).
   - bulk voidage against Benyahia & O'Neill (2005): eps = 0.390 + 1.740 / (N + 1.140)^2,
     accepted within +-0.02;
   - the radial profile (shells 0.02 d, exact point sampling): eps >= 0.95 at the wall, a first
     minimum of 0.20-0.27 at z = 0.45-0.65, a maximum of 0.50-0.62 near z = 1 (0.8-1.25), a
     second minimum below 0.35 near z = 1.4-1.5 (1.25-1.75) (the ranges of de Klerk 2003 and
     Mueller 1992 for N >~ 5).
2. Periodic box (5 d x 5 d, floor; the same rain from 8 d, ``BOX_RAIN``): solid fraction
   phi = 1 - eps of the bulk at mu = 0, 0.1, 0.3, 1 (the floor alike): 0.625-0.645 at mu = 0
   (random close packing of frictionless spheres), 0.54-0.59 at mu = 1 (random loose
   packing), decreasing with mu (Silbert et al. 2002; Song, Wang & Makse 2008).

Prints a table (ours beside the reference, with the protocol) and writes JSON. ``--quick``
runs reduced beds (about 4 d tall, N = 5 only and two frictions) for a smoke test.

``--contact hertz`` rains the columns with the Hertz–Mindlin law instead of the impulse engine
(``peclet.packing.bed.contact.HertzContact``: E = 1e7 Pa for 1 mm spheres of 2500 kg/m^3, the
LAMMPS column's, nu 0.3, substeps of at most 0.2 Rayleigh times), ``--contact both`` runs
each column with both laws from the same protocol and seeds; ``--ns`` and ``--seeds`` choose
the columns (e.g. ``--only columns --contact both --ns 8 --seeds 1,2 --out
validation/results/spheres_hertz.json``).
"""
from __future__ import annotations

import dataclasses
import json
import math
import os
import sys
import time

import numpy as np

from peclet.core.files import atomic_write
from peclet.packing import Material, RainProtocol, pack
from peclet.packing.bed.contact import HertzContact
from peclet.packing.output import report as bed_report

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:           # run as a script: the repository, for the package below
    sys.path.insert(0, ROOT)

import validation as vargs  # noqa: E402  (the scripts' shared argument handling)

#: The deposition used for every sphere bed here (see the module docstring).
RAIN = RainProtocol(batch=1, insert_every=4, drop=30.0, speed=2.0)
#: The box's deposition: the same rain from 8 d (from 30 d, frictionless spheres order into
#: crystalline layers on the flat floor: phi 0.743 measured in a 4 d tall bed).
BOX_RAIN = RainProtocol(batch=1, insert_every=4, drop=8.0, speed=2.0)
GLASS = Material(e_n=0.3, e_t=0.0, mu=0.3)
V_SPHERE = math.pi / 6.0


def benyahia_oneill(n):
    """Benyahia & O'Neill (2005), mean voidage of equal spheres in a tube of N = D_t / d."""
    return 0.390 + 1.740 / (n + 1.140) ** 2


def count_for(area, height, phi=0.6):
    """Spheres (d = 1) that fill ``area`` to ``height`` at solid fraction ``phi``."""
    return int(round(phi * area * height / V_SPHERE))


def column(n, height=10.0, seed=1, protocol=RAIN, progress=False, contact=None):
    """Rain spheres into a column of N = ``n`` with the contact law ``contact`` (None: the
    impulse engine; a ``HertzContact``); returns the row of the table."""
    cnt = count_for(math.pi * (0.5 * n) ** 2, height)
    t = time.perf_counter()
    res = pack("sphere", f"column:{n:g}", count=cnt, protocol=protocol, material=GLASS,
               seed=seed, progress=progress, contact=contact)
    rep = bed_report.analyse(res, None, figures=False, exports=False)
    f = rep["radial"]["features"]
    ref = benyahia_oneill(n)
    checks = dict(
        bulk=abs(rep["bulk"]["eps"] - ref) <= 0.02,
        wall=f["wall"][1] >= 0.95,
        min1=f["min1"] is not None and 0.20 <= f["min1"][1] <= 0.27
        and 0.45 <= f["min1"][0] <= 0.65,
        max1=f["max1"] is not None and 0.50 <= f["max1"][1] <= 0.62,
        min2=f["min2"] is not None and f["min2"][1] < 0.35)
    law = "impulse" if contact is None else contact.law
    return dict(case=f"column N={n:g}", law=law, seed=seed,
                contact=None if contact is None else contact.to_spec(),
                count=cnt, steps=res.steps, seconds=time.perf_counter()
                - t, eps=rep["bulk"]["eps"], eps_se=rep["bulk"]["eps_se"], eps_ref=ref,
                features=f, checks=checks, container=res.container.label(),
                bed_top=rep["bed_top"])


def box(mu, side=5.0, height=10.0, seed=1, protocol=BOX_RAIN, progress=False):
    """Rain spheres of friction ``mu`` (walls alike) into a periodic box; returns the row."""
    cnt = count_for(side * side, height)
    t = time.perf_counter()
    res = pack("sphere", f"box:{side:g}", count=cnt, protocol=protocol,
               material=Material(0.3, 0.0, mu), seed=seed, progress=progress)
    rep = bed_report.analyse(res, None, figures=False, exports=False)
    return dict(case=f"box mu={mu:g}", count=cnt, steps=res.steps,
                seconds=time.perf_counter() - t, phi=1.0 - rep["bulk"]["eps"],
                phi_se=rep["bulk"]["eps_se"], mu=mu)


BOX_REF = {0.0: (0.625, 0.645), 1.0: (0.54, 0.59)}


def table(cols, boxes, rain=RAIN):
    lines = [f"protocol: rain, {rain.batch} sphere(s) / {rain.insert_every} steps (dt 2e-3), "
             f"drop {rain.drop:g} d (columns) "
             f"or {BOX_RAIN.drop:g} d (boxes) above the bed at {rain.speed:g} d/t, e_n 0.3, "
             f"mu = mu_wall (0.3 in columns); cropped {bed_report.CROP:g} d at floor and "
             "surface", "",
             f"{'case':<14} {'law':<8} {'seed':>4} {'n':>5} {'ours':>16} {'reference':>20}  "
             "radial profile (z, eps)"]
    for r in cols:
        f = r["features"]
        fm = lambda p: "-" if p is None else f"{p[1]:.2f}@{p[0]:.2f}"  # noqa: E731
        ok = "".join("+" if v else "x" for v in r["checks"].values())
        lines.append(f"{r['case']:<14} {r.get('law', 'impulse'):<8} {r.get('seed', 1):>4} "
                     f"{r['count']:>5} {r['eps']:>8.4f}+-{r['eps_se']:.4f} "
                     f"{'B&O ' + format(r['eps_ref'], '.4f') + ' +-0.02':>20}  wall "
                     f"{fm(f['wall'])} min {fm(f['min1'])} max {fm(f['max1'])} min2 "
                     f"{fm(f['min2'])} [{ok}]")
    lines.append("  reference radial: wall >= 0.95, min 0.20-0.27 @ 0.45-0.65, max 0.50-0.62 "
                 "@ ~1, min2 < 0.35 @ 1.4-1.5; [+/x] = bulk, wall, min, max, min2 within")
    prev = None
    for r in boxes:
        ref = BOX_REF.get(r["mu"])
        txt = f"{ref[0]:.3f}-{ref[1]:.3f}" if ref else "between"
        dec = "" if prev is None else ("  (decreasing)" if r["phi"] < prev else
                                       "  (NOT decreasing)")
        lines.append(f"{r['case']:<14} {r['count']:>5} phi {r['phi']:.4f}+-{r['phi_se']:.4f} "
                     f"{txt:>20}{dec}")
        prev = r["phi"]
    return "\n".join(lines)


def main(argv=None):
    ap = vargs.ScriptParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="reduced beds (smoke test)")
    ap.add_argument("--out", type=vargs.output_file,
                    default=os.path.join(os.path.dirname(__file__), "results",
                                         "spheres.json"),
                    help="JSON (a file in an existing directory; default "
                    "validation/results/spheres.json)")
    ap.add_argument("--progress", action="store_true")
    ap.add_argument("--only", choices=("columns", "boxes"), default=None)
    ap.add_argument("--contact", choices=("impulse", "hertz", "both"), default="impulse",
                    help="the columns' contact law (module notes; default impulse)")
    ap.add_argument("--ns", type=vargs.real_list(1.5, 1e4), default=None,
                    help="the columns' N = D_t / d, each >= 1.5 (default 5,8,10; --quick 5)")
    ap.add_argument("--seeds", type=vargs.integer_list(0, 2 ** 31), default=None,
                    help="the columns' seeds (default 1)")
    ap.add_argument("--drop", type=vargs.real(0.0, 1e4), default=RAIN.drop,
                    help=f"the columns' drop height above the bed, d (default {RAIN.drop:g})")
    ap.add_argument("--batch", type=vargs.integer(1, 10 ** 4), default=RAIN.batch,
                    help=f"spheres per insertion in the columns (default {RAIN.batch})")
    ap.add_argument("--insert-every", type=vargs.integer(1, 10 ** 4),
                    default=RAIN.insert_every,
                    help=f"steps between insertions (default {RAIN.insert_every})")
    a = ap.parse_args(argv)
    h = 4.0 if a.quick else 10.0
    ns = () if a.only == "boxes" else tuple(a.ns) if a.ns else (5,) if a.quick else (5, 8, 10)
    mus = () if a.only == "columns" else (0.0, 1.0) if a.quick else (0.0, 0.1, 0.3, 1.0)
    laws = {"impulse": [None], "hertz": [HertzContact()],
            "both": [None, HertzContact()]}[a.contact]
    rain = dataclasses.replace(RAIN, drop=a.drop, batch=a.batch, insert_every=a.insert_every)
    cols = [column(n, height=h, seed=s, protocol=rain, progress=a.progress, contact=law)
            for n in ns for s in (a.seeds or [1]) for law in laws]
    boxes = [box(m, height=h, progress=a.progress) for m in mus]
    text = table(cols, boxes, rain)
    print(text)

    def w(tmp):
        with open(tmp, "w") as fh:
            json.dump(dict(columns=cols, boxes=boxes, quick=a.quick, table=text,
                           rain=rain.to_spec()), fh, indent=1,
                      default=lambda o: o.item() if isinstance(o, np.generic) else str(o))
    atomic_write(a.out, w)
    return 0


if __name__ == "__main__":
    sys.exit(vargs.run(main))
