"""The flow solver's validation ladder (peclet.flow, issue 25).

    python validation/flow.py [--quick] [--json FILE] [--page-pack pall_ring_pack.npz]
                              [--rungs slit,pipe,zh,random,column,page]
                              [--zh-fractions 0.125,0.5236] [--zh-resolutions 8,16]
                              [--column-resolutions 8,12,16] [--page-resolutions 8,16,24]

1. Poiseuille flow in a periodic slit, walls at fractions q = 0.1, 0.3, 0.5, 0.7 of a link:
   exact to round-off (TRT, magic 3/16, linear interpolated bounce-back with its parabolic
   correction); the max error relative to the centre-line speed is printed.
2. Poiseuille flow in a pipe (radius R = 4, 8, 16 cells; curved wall): relative L2 error of
   u and the observed order.
3. Simple-cubic arrays of spheres against Zick & Homsy (1982), K = F / (6 pi mu a U) with F
   = (dP/L) L^3 the force per sphere and U the superficial velocity (the mass flux over
   uncut links), at the seven solid fractions, at 8 and 16 cells per diameter (full run: 24
   as well for c >= 0.125; the dilute boxes at 24 are 65^3 and 52^3 cells); accepted within
   2% at >= 16, observed order from the finest two. ``--zh-fractions`` and
   ``--zh-resolutions`` choose a subset (every chosen fraction at every chosen resolution);
   with ``--json`` the rows run replace the file's rows of the same fraction and resolution
   and the others are kept, each row saying under which convergence scheme it ran
   (``convergence``: rows from before the force-balance criterion are marked as such).
4. A random sphere pack (``peclet.packing.pack``: spheres rained into a periodic box) against
   the Carman-Kozeny (k = eps^3 d^2 / (180 (1 - eps)^2)) and Ergun viscous (150) terms, flow
   along y (the window wrapped, dP/L measured away from its seam; mirrored, k along y comes
   out ~30% too high: see :mod:`peclet.flow.permeability`); the whole period's k, the seam's
   share and the force balance beside it.
5. Column sections (``column``): Poiseuille flow in an empty pipe made by a column's wall
   (the container's own side-wall tree; k = R^2 / 8 relative to the pipe's cross-section,
   R = 1 D at D/4, D/8, D/12, D/16: error and observed order); the same pipe with a sphere
   (0.8 R across) at the wrapped section's seam (k fitted away from the seam against the
   whole period's); a rained sphere column (``peclet.packing.pack``, D_t = 5 D, 150 spheres;
   quick: 4 D, 90) at D/8, D/12 and D/16 (``--column-resolutions``; quick: D/5, D/6): a grid
   study of k with Richardson extrapolation and the observed order (as ``peclet flow
   --resolutions``), and per resolution k, porosity with the near-wall region, D_t / d_p,
   dP/L against Eisfeld & Schnitzlein, the seam's share, the wall's share of the drag, the
   force balance and the period-2 swing.
6. The page's 48-ring pack (``--page-pack``, written by ``peclet pall-ring``) at D/8, D/16
   and D/24 (``--page-resolutions``; quick: D/8, D/12), Richardson-extrapolated (observed
   order from the three), with each run's lattice size, fluid nodes, memory of the solver's
   arrays, the process's peak resident memory and the iteration count; the whole period's k
   (the seam included) is extrapolated beside it.

Prints tables; ``--json`` writes every number (with ``--rungs`` a subset, the other rungs of
an existing file are kept, so rungs can be run one at a time; ``convergence_scheme`` and
``commands`` say, per rung, under which scheme and by which command its figures were made);
``--quick`` runs reduced sizes (tests).
"""
from __future__ import annotations

import math
import os
import sys
import time

import numpy as np

from peclet.flow import Grid, build_geometry, permeability, richardson, solve

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:           # run as a script: the repository, for the package below
    sys.path.insert(0, ROOT)

import validation as vargs  # noqa: E402  (the scripts' shared argument handling)

#: Zick & Homsy (1982), simple cubic arrays: solid fraction -> K.
ZICK_HOMSY = {0.027: 2.008, 0.064: 2.810, 0.125: 4.292, 0.216: 7.442, 0.343: 15.4,
              0.45: 28.1, 0.5236: 42.1}
NU = 1.0 / 6.0

#: How the figures of a rung (or a Zick & Homsy row) were converged.
CURRENT = ("two-step means; stop when the mean velocity's relative change and its geometric "
           "tail are < tol and |wall force / body force - 1| < 1e-4 (peclet.flow.solver, "
           "since fd6da9d)")
EARLIER = ("EARLIER SCHEME, not re-run: converged before fd6da9d (one-phase checks of the "
           "mean velocity only, no force-balance criterion); kept for reference")


def slit(q0, n=8, nu=NU, g=1e-6, tol=1e-12):
    """Max |u - u_exact| / u_max in a slit of n nodes, walls q0 beyond the outer nodes."""
    width = n - 1 + 2 * q0
    grid = Grid((0.0, 0.0, 0.0), 1.0, (2, n, 2), (True, False, True))
    geo = build_geometry(grid, lambda p: np.minimum(p[:, 1] + q0, (n - 1 + q0) - p[:, 1]))
    r = solve(geo, [g, 0.0, 0.0], nu=nu, tol=tol, max_steps=400_000)
    y = geo.ijk[:, 1] + q0
    ue = g / (2 * nu) * y * (width - y)
    return {"q": q0, "n": n, "err": float(np.abs(r.u[:, 0] - ue).max() / ue.max()),
            "steps": r.steps}


def pipe(radius, nu=NU, g=1e-6, tol=1e-10, scheme="linear"):
    """Relative L2 error of the axial velocity in a pipe of ``radius`` cells (axis x)."""
    m = int(math.ceil(radius)) + 2
    c = m + 0.37          # the axis off the nodes, so q takes many values
    grid = Grid((0.0, 0.0, 0.0), 1.0, (2, 2 * m + 2, 2 * m + 2), (True, False, False))

    def phi(p):
        return radius - np.sqrt((p[:, 1] - c) ** 2 + (p[:, 2] - c) ** 2)
    geo = build_geometry(grid, phi)
    r = solve(geo, [g, 0.0, 0.0], nu=nu, tol=tol, max_steps=400_000, scheme=scheme)
    rr2 = (geo.ijk[:, 1] - c) ** 2 + (geo.ijk[:, 2] - c) ** 2
    ue = g / (4 * nu) * (radius ** 2 - rr2)
    err = float(np.sqrt(((r.u[:, 0] - ue) ** 2).sum() / (ue ** 2).sum()))
    return {"R": radius, "scheme": scheme, "err": err,
            "steps": r.steps}


def sphere_array(c, cells_per_d, nu=NU, g=1e-6, tol=1e-8, mass="local"):
    """K of a simple cubic array at solid fraction c: period L = ceil(d (pi / 6c)^(1/3)) cells
    (so the diameter has at least ``cells_per_d`` cells), radius from c exactly."""
    L = int(math.ceil(cells_per_d * (math.pi / (6 * c)) ** (1 / 3) - 1e-9))
    a = min(L * (3 * c / (4 * math.pi)) ** (1 / 3), 0.5 * L)
    cen = np.full(3, 0.5 * (L - 1))

    def phi(p):
        d = p - cen
        d -= L * np.round(d / L)
        return np.sqrt((d * d).sum(1)) - a
    geo = build_geometry(Grid((0.0, 0.0, 0.0), 1.0, (L, L, L), (True, True, True)), phi)
    t0 = time.perf_counter()
    r = solve(geo, [g, 0.0, 0.0], nu=nu, tol=tol, max_steps=400_000, mass=mass)
    K = g * L ** 3 / (6 * math.pi * nu * a * r.U[0])
    K_nodes = g * L ** 3 / (6 * math.pi * nu * a * r.U_nodes[0])
    ref = ZICK_HOMSY[c]
    return {"c": c, "resolution": cells_per_d, "cells_per_d": 2 * a, "L": L, "K": float(K),
            "ref": ref, "err": float(K / ref - 1.0), "err_node_mean": float(K_nodes / ref - 1.0),
            "mass": mass, "steps": r.steps, "converged": r.converged,
            "seconds": time.perf_counter() - t0,
            "balance": float(r.link_force[:, 0].sum() / (g * geo.n_fluid)),
            "parity_swing": r.parity_swing, "convergence": CURRENT}


def random_spheres(count=60, box=3.0, resolution=12, seed=1, tol=1e-6):
    """Spheres rained into box:``box`` (peclet.packing.pack), then the flow along y."""
    from peclet.packing import Material, pack
    res = pack("sphere", f"box:{box:g}", count=count, protocol="rain",
               material=Material(e_n=0.3, e_t=0.0, mu=0.3), seed=seed, progress=False)
    pf = permeability(res.pack, resolution=resolution, tol=tol)
    e = pf.eps
    ck = e ** 3 / (180.0 * (1 - e) ** 2)
    s = pf.summary()
    return {"count": count, "resolution": resolution, "eps": e, "k_D2": pf.k_D2,
            "k_carman_kozeny": ck, "ratio_ck": pf.k_D2 / ck, "kozeny": pf.kozeny,
            "ergun_ratio": pf.ergun_ratio_sauter, "d_sauter": pf.d_sauter,
            "window": pf.info["window"], "Re": pf.Re, "steps": pf.flow.steps,
            "k_D2_period": s["k_D2_period"], "ratio_ck_period": s["k_D2_period"] / ck,
            "seam_share": s.get("seam_share", math.nan),
            "seam_share_se": s.get("seam_share_se", math.nan),
            "seam_share_by_margin": s.get("seam_share_by_margin", {}),
            "k_D2_seam_free": s.get("k_D2_seam_free", math.nan),
            "dpdl_source": s["dpdl_source"], "solid_drag_balance": pf.solid_drag_balance,
            "balance_two_step": s["balance_two_step"], "parity_swing": s["parity_swing"],
            "converged": s["converged"], "seconds": s["seconds"]}


def page_pack(path, resolutions=(8, 16, 24), tol=1e-6):
    """k of the page's pack at each resolution (cells per D) and the Richardson extrapolation;
    per run also the lattice (dims, cells, fluid nodes), the solver's array memory, the
    process's peak resident memory so far and the steps."""
    import resource
    rows = []
    for r in resolutions:
        t0 = time.perf_counter()
        pf = permeability(path, resolution=r, tol=tol)
        row = {k: v for k, v in pf.summary().items() if not isinstance(v, (list, dict))
               or k in ("window", "dims")}
        row["peak_rss_MiB"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
        row["wall_seconds"] = time.perf_counter() - t0
        rows.append(row)
        print(f"   page D/{r}: k = {row['k_D2']:.5g} D^2, dP/L / Ergun (Sauter) "
              f"{row['ergun_ratio_sauter']:.4f}, {row['steps']} steps, lattice "
              f"{row['dims']}, {row['fluid_nodes']} fluid nodes, {row['memory_MiB']:.0f} MiB",
              flush=True)
    ext = richardson([1.0 / r for r in resolutions], [x["k_D2"] for x in rows])
    fin = rows[-1]
    # the extrapolated k in the finest run's Kozeny and Ergun ratios (both ~ 1/k)
    ext["ergun_ratio_sauter"] = fin["ergun_ratio_sauter"] * fin["k_D2"] / ext["k0"]
    ext["ergun_ratio_envelope"] = fin["ergun_ratio_envelope"] * fin["k_D2"] / ext["k0"]
    ext["kozeny"] = fin["kozeny"] * fin["k_D2"] / ext["k0"]
    ext_period = richardson([1.0 / r for r in resolutions], [x["k_D2_period"] for x in rows])
    return {"runs": rows, "richardson": ext, "richardson_period": ext_period}


def _lone_sphere_column(n, y, r):
    """A column:n pack of one sphere of radius r on the axis at height y (the pipe rungs)."""
    from peclet.core import geom
    from peclet.packing.bed.containers import Container
    from peclet.packing.bed.freeze import Pack
    c = Container.column(n)
    b = geom.SceneBuilder()
    root = b.add_leaf("sphere", [r])
    ni, nr, _, _ = b.encode()
    cx, cz = c.center_xz
    return Pack(positions=np.array([[cx, y, cz]]), quaternions=np.array([[0.0, 0, 0, 1]]),
                box=np.array(c.period), ring_volume=4.0 / 3.0 * math.pi * r ** 3,
                node_ints=ni, node_reals=nr, home_root=root, bounding_radius=r,
                shell=np.zeros((0, 3)), mass=np.nan, inv_inertia=np.full(3, np.nan)), c


def column_pipe(resolutions=(4, 8, 12, 16)):
    """k of an empty pipe (column:2, R = 1 D) against R^2 / 8, per resolution."""
    pk, c = _lone_sphere_column(2.0, 30.0, 0.5)
    rows = []
    for r in resolutions:
        pf = permeability(pk, resolution=r, container=c, window=(0.0, 2.0), tol=1e-9,
                          area_n=40, seam_margin=0.5)
        rows.append({"R_cells": r, "k_D2": pf.k_D2, "err": pf.k_D2 / 0.125 - 1.0,
                     "seam_share": pf.info["seam_share"], "steps": pf.flow.steps})
    for a, b in zip(rows, rows[1:]):
        b["order"] = math.log(abs(a["err"]) / abs(b["err"])) / math.log(b["R_cells"]
                                                                         / a["R_cells"])
    return rows


def column_seam(resolution=8, margin=1.5):
    """The pipe with a sphere of diameter 0.8 D at the seam: k away from the seam (fit) and
    over the whole period, against the empty pipe's at the same resolution."""
    pk, c = _lone_sphere_column(2.0, 30.0, 0.5)
    k_pipe = permeability(pk, resolution=resolution, container=c, window=(0.0, 6.0),
                          tol=1e-9, area_n=40).k_D2
    pk, c = _lone_sphere_column(2.0, 0.0, 0.4)
    pf = permeability(pk, resolution=resolution, container=c, window=(0.0, 6.0), tol=1e-9,
                      area_n=40, seam_margin=margin)
    return {"resolution": resolution, "margin_D": margin, "k_pipe": k_pipe,
            "k_seam_free": pf.k_D2, "ratio_seam_free": pf.k_D2 / k_pipe,
            "k_period": pf.info["k_D2_period"],
            "ratio_period": pf.info["k_D2_period"] / k_pipe,
            "seam_share": pf.info["seam_share"], "seam_share_se": pf.info["seam_share_se"]}


def rained_column(n=5.0, count=150, seed=3):
    """Spheres rained into column:n (``peclet.packing.pack``): the pack and its container."""
    from peclet.packing import Material, RainProtocol, pack
    res = pack("sphere", f"column:{n:g}", count=count,
               protocol=RainProtocol(drop=3.0, settle_steps=3000, calm_steps=20,
                                     quench_steps=20),
               material=Material(e_n=0.3, e_t=0.0, mu=0.3), seed=seed, progress=False)
    return res.pack, res.container


def column_bed(n=5.0, count=150, resolutions=(8, 12, 16), seed=3, tol=1e-6):
    """A grid study on a column section: spheres rained into column:n, the flow through the
    middle of the bed at each resolution (as ``peclet flow --resolutions``: the same
    :func:`~peclet.flow.permeability` and :func:`~peclet.flow.richardson`), k extrapolated
    with the observed order (3 resolutions; 2 assume order 2), the whole period's k (seam
    included) likewise."""
    pk, cont = rained_column(n, count, seed)
    keep = ("resolution", "k_D2", "k_D2_period", "eps", "eps_core", "D_t_over_d_p", "A_w",
            "ergun_wall_ratio", "ergun_ratio_volume", "seam_share", "seam_share_se",
            "seam_planes", "seam_share_by_margin", "dpdl_source", "wall_drag_share",
            "solid_drag_balance", "balance_two_step",
            "parity_swing", "steps", "converged", "window", "dims", "fluid_nodes", "Re",
            "seconds", "mlups", "memory_MiB")
    rows = []
    for r in resolutions:
        s = permeability(pk, resolution=r, container=cont, tol=tol).summary()
        rows.append({k: s[k] for k in keep})
        print(f"   column:{n:g} bed D/{r}: k = {s['k_D2']:.5g} D^2 (whole period "
              f"{s['k_D2_period']:.5g}), seam share {s['seam_share']:+.4f}, "
              f"{s['steps']} steps, {s['seconds']:.0f} s", flush=True)
    out = {"count": count, "column_D": n, "seed": seed, "runs": rows}
    if len(rows) >= 2:
        hs = [1.0 / r for r in resolutions]
        out["richardson"] = richardson(hs, [x["k_D2"] for x in rows])
        out["richardson_period"] = richardson(hs, [x["k_D2_period"] for x in rows])
        if len(rows) >= 3:
            # the two finest with order 2 assumed: a bracket where the observed order is far
            # from the scheme's (a pack's k need not converge smoothly at coarse resolutions)
            out["richardson_two_finest"] = richardson(hs[-2:], [x["k_D2"] for x in rows[-2:]])
        fin = rows[-1]
        out["richardson"]["ergun_wall_ratio"] = (fin["ergun_wall_ratio"] * fin["k_D2"]
                                                 / out["richardson"]["k0"])
    return out


def _table(rows, cols):
    from benchmarks._report import table
    return table([[r[c] if not isinstance(r[c], float) else f"{r[c]:.5g}" for c in cols]
                  for r in rows], cols)


RUNGS = ("slit", "pipe", "zh", "random", "column", "page")


def _rungs(text):
    parts = [t.strip() for t in str(text).split(",") if t.strip()]
    if not parts or any(p not in RUNGS for p in parts):
        import argparse
        raise argparse.ArgumentTypeError(f"must be a comma-separated subset of "
                                         f"{','.join(RUNGS)}, got {text!r}")
    return set(parts)


def _fractions(text):
    """--zh-fractions: a comma-separated subset of Zick & Homsy's seven solid fractions."""
    import argparse
    accepted = "a comma-separated subset of " + ",".join(f"{c:g}" for c in ZICK_HOMSY)
    try:
        vals = vargs.real_list(0.0, 1.0, lo_open=True)(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"must be {accepted}, got {text!r}") from None
    out = []
    for v in vals:
        match = [c for c in ZICK_HOMSY if abs(c - v) < 1e-9]
        if not match:
            raise argparse.ArgumentTypeError(f"must be {accepted}, got {text!r}")
        if match[0] not in out:
            out.append(match[0])
    return tuple(out)


def _zh_ladder(fractions, resolutions, quick):
    """(c, resolution) pairs to run: the chosen ones, else the default ladder."""
    fr = fractions or ((0.125, 0.5236) if quick else tuple(ZICK_HOMSY))
    pairs = []
    for c in fr:
        rs = resolutions or ((8, 16) if quick or c < 0.1 else (8, 16, 24))
        pairs += [(c, int(r)) for r in sorted(set(rs))]
    return pairs


def _nominal(row):
    """A Zick & Homsy row's nominal cells per diameter (rows before the field: the
    resolution the diameter was rounded up from)."""
    return int(row.get("resolution", math.floor(row["cells_per_d"] + 1e-9)))


def _zh_merge(old, new):
    """The rows run (``new``) replace ``old`` rows of the same fraction and resolution; kept
    rows without a ``convergence`` field predate it and are marked as the earlier scheme.
    Sorted by fraction and resolution; ``order`` between successive resolutions of a fraction
    (``order_note`` when either row is from the earlier scheme)."""
    ran = {(z["c"], _nominal(z)) for z in new}
    kept = []
    for z in old:
        if (z["c"], _nominal(z)) in ran:
            continue
        z = {k: v for k, v in z.items() if k not in ("order", "order_note")}
        z.setdefault("resolution", _nominal(z))
        z.setdefault("convergence", EARLIER)
        kept.append(z)
    rows = sorted(kept + list(new), key=lambda z: (z["c"], z["resolution"]))
    for c in dict.fromkeys(z["c"] for z in rows):
        rs = [z for z in rows if z["c"] == c]
        for a, b in zip(rs, rs[1:]):
            e1, e2 = abs(a["err"]), abs(b["err"])
            b["order"] = (math.log(e1 / e2) / math.log(b["cells_per_d"] / a["cells_per_d"])
                          if e1 > 0 and e2 > 0 else math.nan)
            if a["convergence"] != CURRENT or b["convergence"] != CURRENT:
                b["order_note"] = "from a row of the earlier scheme"
    return rows


def main(argv=None):
    import json
    import shlex
    import warnings
    ap = vargs.ScriptParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="reduced sizes")
    ap.add_argument("--json", type=vargs.output_file, default=None,
                    help="write the results here (a file in an existing directory)")
    ap.add_argument("--page-pack", type=vargs.input_file, default=None,
                    help="the page's pall_ring_pack.npz (an existing file)")
    ap.add_argument("--rungs", type=_rungs, default=set(RUNGS),
                    help="the rungs to run, a comma-separated subset of " + ",".join(RUNGS)
                    + " (default all; page only with --page-pack)")
    ap.add_argument("--zh-fractions", type=_fractions, default=None,
                    help="Zick & Homsy: the solid fractions to run (default all seven)")
    ap.add_argument("--zh-resolutions", type=vargs.integer_list(4, 64), default=None,
                    help="Zick & Homsy: cells per sphere diameter, each in [4, 64], run at "
                    "every chosen fraction (default 8,16 below c = 0.1, else 8,16,24)")
    ap.add_argument("--column-resolutions", type=vargs.integer_list(4, 64), default=None,
                    help="the rained column's grid study: cells per D, each in [4, 64] "
                    "(default 8,12,16; quick 5,6)")
    ap.add_argument("--page-resolutions", type=vargs.integer_list(4, 64), default=None,
                    help="the page's pack: cells per D, each in [4, 64] (default 8,16,24; "
                    "quick 8,12)")
    a = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    command = "python validation/flow.py " + " ".join(
        shlex.quote(x) for x in (sys.argv[1:] if argv is None else argv))
    out = {}
    if a.json and os.path.isfile(a.json) and a.rungs != set(RUNGS):
        with open(a.json) as fh:
            out = json.load(fh)
    scheme = out.setdefault("convergence_scheme", {})
    commands = out.setdefault("commands", {})
    for rung, key in (("slit", "slit"), ("pipe", "pipe"), ("random", "random_spheres"),
                      ("column", "column_bed"), ("page", "page")):
        if key in out and rung not in scheme:       # a rung kept from before these fields
            scheme[rung] = EARLIER

    def ran(rung):
        scheme[rung] = CURRENT
        commands[rung] = command

    if "slit" in a.rungs:
        out["slit"] = [slit(q) for q in (0.1, 0.3, 0.5, 0.7)]
        ran("slit")
        print("1. Poiseuille slit (8 nodes), max error / u_max\n"
              + _table(out["slit"], ["q", "n", "err", "steps"]))
    if "pipe" in a.rungs:
        radii = (4.0, 8.0) if a.quick else (4.0, 8.0, 16.0)
        out["pipe"] = [pipe(R, scheme=s) for s in ("linear", "bouzidi") for R in radii]
        for i, p in enumerate(out["pipe"]):
            prev = out["pipe"][i - 1] if i else None
            p["order"] = (math.log(prev["err"] / p["err"]) / math.log(p["R"] / prev["R"])
                          if prev and prev["scheme"] == p["scheme"] else "")
        ran("pipe")
        print("\n2. Poiseuille pipe, relative L2 error (linear: with the parabolic correction, "
              "exact up to the convergence tolerance; bouzidi: plain, second order)\n"
              + _table(out["pipe"], ["R", "scheme", "err", "order", "steps"]))
    if "zh" in a.rungs:
        new = []
        for c, r in _zh_ladder(a.zh_fractions, a.zh_resolutions, a.quick):
            new.append(sphere_array(c, r))
            z = new[-1]
            print(f"   ZH c={c} d={r}: K={z['K']:.4f} err={z['err']:+.4f} (L = {z['L']}, "
                  f"{z['steps']} steps, {z['seconds']:.1f} s)", flush=True)
        zh = _zh_merge(out.get("zick_homsy", []), new)
        for z in new:
            z["command"] = command
        out["zick_homsy"] = zh
        scheme["zh"] = ("per row (field 'convergence'): rows run by one of the commands in "
                        "'commands' (each row's 'command') are current, the others are marked "
                        "as the earlier scheme")
        commands["zh"] = list(dict.fromkeys(z["command"] for z in zh if z.get("command")))
        print("\n3. Zick & Homsy simple cubic arrays (K = F / 6 pi mu a U; U the flux over "
              "uncut links; err_node_mean: U from the mean node velocity instead; * = a row "
              "of the earlier convergence scheme, not re-run)\n"
              + _table([{**z, "order": z.get("order", ""),
                         "c": f"{z['c']:g}" + ("" if z["convergence"] == CURRENT else " *")}
                        for z in zh],
                       ["c", "cells_per_d", "L", "K", "ref", "err", "err_node_mean", "order",
                        "steps"]))
        cur = [z for z in zh if z["resolution"] >= 16 and z["convergence"] == CURRENT]
        old = [z for z in zh if z["resolution"] >= 16 and z["convergence"] != CURRENT]
        ok = all(abs(z["err"]) <= 0.02 for z in cur + old)
        out["zick_homsy_within_2pct_at_16"] = ok
        out["zick_homsy_at_16"] = {
            "within_2pct_current": all(abs(z["err"]) <= 0.02 for z in cur),
            "fractions_current": sorted({z["c"] for z in cur}),
            "max_abs_err_current": max((abs(z["err"]) for z in cur), default=math.nan),
            "within_2pct_earlier_rows": all(abs(z["err"]) <= 0.02 for z in old),
            "fractions_earlier_rows_only": sorted({z["c"] for z in old}
                                                  - {z["c"] for z in cur})}
        print(f"   within 2% at >= 16 cells per diameter: {ok} (current rows at "
              f"c = {', '.join(f'{c:g}' for c in out['zick_homsy_at_16']['fractions_current'])}"
              f"; max |err| {out['zick_homsy_at_16']['max_abs_err_current']:.4f})")
    if "random" in a.rungs:
        out["random_spheres"] = random_spheres(*((40, 3.0, 8) if a.quick else (150, 4.0, 16)))
        ran("random")
        rs = out["random_spheres"]
        print("\n4. Random sphere pack\n" + _table([rs], ["count", "resolution", "eps",
                                                         "k_D2", "k_carman_kozeny", "ratio_ck",
                                                         "kozeny", "ergun_ratio"])
              + f"\n   whole period (seam included) k = {rs['k_D2_period']:.5g} D^2 "
              f"({rs['ratio_ck_period']:.4f} of Carman-Kozeny), seam share "
              f"{rs['seam_share']:+.4f} +- {rs['seam_share_se']:.4f}, wall force / body "
              f"force {rs['solid_drag_balance']:.8f}")
    if "column" in a.rungs:
        out["column_pipe"] = column_pipe((4, 8) if a.quick else (4, 8, 12, 16))
        print("\n5. Column sections\n   empty pipe made by the column's wall (R = 1 D), k "
              "against R^2 / 8\n" + _table([{**r, "order": r.get("order", "")}
                                              for r in out["column_pipe"]],
                                             ["R_cells", "k_D2", "err", "order", "seam_share",
                                              "steps"]))
        out["column_seam"] = column_seam(6 if a.quick else 8)
        print("   a sphere (0.8 D) at the seam: k over the empty pipe's\n"
              + _table([out["column_seam"]], ["resolution", "margin_D", "ratio_seam_free",
                                              "ratio_period", "seam_share",
                                              "seam_share_se"]))
        cres = a.column_resolutions or ((5, 6) if a.quick else (8, 12, 16))
        out["column_bed"] = column_bed(*((4.0, 90) if a.quick else (5.0, 150)),
                                       resolutions=cres)
        ran("column")
        cb = out["column_bed"]
        print("   rained sphere column, middle of the bed: grid study\n"
              + _table(cb["runs"], ["resolution", "k_D2", "k_D2_period", "eps", "eps_core",
                                    "A_w", "ergun_wall_ratio", "seam_share", "seam_share_se",
                                    "wall_drag_share", "balance_two_step", "parity_swing",
                                    "steps"]))
        if "richardson" in cb:
            ext, extp = cb["richardson"], cb["richardson_period"]
            print(f"   extrapolated k = {ext['k0']:.5g} D^2 ({_order_text(ext)}); whole "
                  f"period {extp['k0']:.5g} D^2 ({_order_text(extp)})"
                  + (f"; the two finest, order 2 assumed: "
                     f"{cb['richardson_two_finest']['k0']:.5g} D^2"
                     if "richardson_two_finest" in cb else ""))
    if "page" in a.rungs and a.page_pack:
        pres = a.page_resolutions or ((8, 12) if a.quick else (8, 16, 24))
        out["page"] = page_pack(a.page_pack, pres)
        ran("page")
        print("\n6. The page's ring pack\n" + _table(out["page"]["runs"],
              ["resolution", "k_D2", "k_D2_period", "seam_share", "seam_share_se", "kozeny",
               "ergun_ratio_sauter", "ergun_ratio_envelope", "solid_drag_balance", "steps",
               "lattice_cells", "fluid_nodes", "memory_MiB", "peak_rss_MiB"]))
        ext = out["page"]["richardson"]
        print(f"   extrapolated k = {ext['k0']:.5g} D^2 ({_order_text(ext)}), dP/L / Ergun "
              f"(Sauter) {ext['ergun_ratio_sauter']:.4f}, (envelope) "
              f"{ext['ergun_ratio_envelope']:.4f}; whole period "
              f"{out['page']['richardson_period']['k0']:.5g} D^2")
    if a.json:
        from benchmarks._report import write_json
        write_json(a.json, out)
    return 0


def _order_text(ext):
    p = ext["p"]
    return ("order 2 assumed" if ext["assumed_p"] else f"observed order {p:.2f}"
            if math.isfinite(p) else "not monotone: finest value")


if __name__ == "__main__":
    sys.exit(vargs.run(main))
