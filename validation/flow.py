"""The flow solver's validation ladder (peclet.flow, issue 25).

    python validation/flow.py [--quick] [--json FILE] [--page-pack pall_ring_pack.npz]
                              [--rungs slit,pipe,zh,random,page]

1. Poiseuille flow in a periodic slit, walls at fractions q = 0.1, 0.3, 0.5, 0.7 of a link:
   exact to round-off (TRT, magic 3/16, linear interpolated bounce-back with its parabolic
   correction); the max error relative to the centre-line speed is printed.
2. Poiseuille flow in a pipe (radius R = 4, 8, 16 cells; curved wall): relative L2 error of
   u and the observed order.
3. Simple-cubic arrays of spheres against Zick & Homsy (1982), K = F / (6 pi mu a U) with F
   = (dP/L) L^3 the force per sphere and U the superficial velocity (the mass flux over
   uncut links), at the seven solid fractions, at 8 and 16 cells per diameter (full run: 24
   as well for c >= 0.125; the dilute boxes at 24 are 65^3 and 52^3 cells); accepted within
   2% at >= 16, observed order from the finest two.
4. A random sphere pack (``peclet.packing.pack``: spheres rained into a periodic box) against
   the Carman-Kozeny (k = eps^3 d^2 / (180 (1 - eps)^2)) and Ergun viscous (150) terms, flow
   along y (the window wrapped; mirrored, k along y comes out ~30% too high: see
   :mod:`peclet.flow.permeability`).
5. Column sections (``column``): Poiseuille flow in an empty pipe made by a column's wall
   (the container's own side-wall tree; k = R^2 / 8 relative to the pipe's cross-section,
   R = 1 D at D/4, D/8, D/12, D/16: error and observed order); the same pipe with a sphere
   (0.8 R across) at the wrapped section's seam (k fitted away from the seam against the
   whole period's); a rained sphere column (``peclet.packing.pack``, D_t = 5 D, 150 spheres;
   quick: 4 D, 90) at D/8 (quick: D/6): k, porosity with the near-wall region, D_t / d_p,
   dP/L against Eisfeld & Schnitzlein, the seam's share, the wall's share of the drag, the
   force balance and the period-2 swing.
6. The page's 48-ring pack (``--page-pack``) at D/8, D/16 and D/24 (quick: D/8, D/12),
   Richardson-extrapolated (observed order from the three), with each run's lattice size,
   fluid nodes, memory of the solver's arrays, the process's peak resident memory and the
   iteration count.

Prints tables; ``--json`` writes every number (with ``--rungs`` a subset, the other rungs of
an existing file are kept, so rungs can be run one at a time); ``--quick`` runs reduced sizes
(tests).
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
    return {"c": c, "cells_per_d": 2 * a, "L": L, "K": float(K), "ref": ref,
            "err": float(K / ref - 1.0), "err_node_mean": float(K_nodes / ref - 1.0),
            "mass": mass, "steps": r.steps, "seconds": time.perf_counter() - t0,
            "balance": float(r.link_force[:, 0].sum() / (g * geo.n_fluid))}


def random_spheres(count=60, box=3.0, resolution=12, seed=1, tol=1e-6):
    """Spheres rained into box:``box`` (peclet.packing.pack), then the flow along y."""
    from peclet.packing import Material, pack
    res = pack("sphere", f"box:{box:g}", count=count, protocol="rain",
               material=Material(e_n=0.3, e_t=0.0, mu=0.3), seed=seed, progress=False)
    pf = permeability(res.pack, resolution=resolution, tol=tol)
    e = pf.eps
    ck = e ** 3 / (180.0 * (1 - e) ** 2)
    return {"count": count, "resolution": resolution, "eps": e, "k_D2": pf.k_D2,
            "k_carman_kozeny": ck, "ratio_ck": pf.k_D2 / ck, "kozeny": pf.kozeny,
            "ergun_ratio": pf.ergun_ratio_sauter, "d_sauter": pf.d_sauter,
            "window": pf.info["window"], "Re": pf.Re, "steps": pf.flow.steps}


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
    return {"runs": rows, "richardson": ext}


def _lone_sphere_column(n, y, r):
    """A column:n pack of one sphere of radius r on the axis at height y (the pipe rungs)."""
    from peclet.core import geom
    from peclet.packing.containers import Container
    from peclet.packing.freeze import Pack
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


def column_bed(n=5.0, count=150, resolution=8, seed=3, tol=1e-6):
    """Spheres rained into column:n, then the flow through the middle of the bed."""
    from peclet.packing import Material, RainProtocol, pack
    res = pack("sphere", f"column:{n:g}", count=count,
               protocol=RainProtocol(drop=3.0, settle_steps=3000, calm_steps=20,
                                     quench_steps=20),
               material=Material(e_n=0.3, e_t=0.0, mu=0.3), seed=seed, progress=False)
    pf = permeability(res.pack, resolution=resolution, container=res.container, tol=tol)
    s = pf.summary()
    keep = ("resolution", "k_D2", "k_D2_period", "eps", "eps_core", "D_t_over_d_p", "A_w",
            "ergun_wall_ratio", "ergun_ratio_volume", "seam_share", "seam_share_se",
            "wall_drag_share", "balance_two_step", "parity_swing", "steps", "converged",
            "window", "dims", "fluid_nodes", "Re")
    return {"count": count, "column_D": n, **{k: s[k] for k in keep}}


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


def main(argv=None):
    import json
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
    a = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    out = {}
    if a.json and os.path.isfile(a.json) and a.rungs != set(RUNGS):
        with open(a.json) as fh:
            out = json.load(fh)
    if "slit" in a.rungs:
        out["slit"] = [slit(q) for q in (0.1, 0.3, 0.5, 0.7)]
        print("1. Poiseuille slit (8 nodes), max error / u_max\n"
              + _table(out["slit"], ["q", "n", "err", "steps"]))
    if "pipe" in a.rungs:
        radii = (4.0, 8.0) if a.quick else (4.0, 8.0, 16.0)
        out["pipe"] = [pipe(R, scheme=s) for s in ("linear", "bouzidi") for R in radii]
        for i, p in enumerate(out["pipe"]):
            prev = out["pipe"][i - 1] if i else None
            p["order"] = (math.log(prev["err"] / p["err"]) / math.log(p["R"] / prev["R"])
                          if prev and prev["scheme"] == p["scheme"] else "")
        print("\n2. Poiseuille pipe, relative L2 error (linear: with the parabolic correction, "
              "exact up to the convergence tolerance; bouzidi: plain, second order)\n"
              + _table(out["pipe"], ["R", "scheme", "err", "order", "steps"]))
    if "zh" in a.rungs:
        fr = (0.125, 0.5236) if a.quick else tuple(ZICK_HOMSY)
        zh = []
        for c in fr:
            for r in ((8, 16) if a.quick or c < 0.1 else (8, 16, 24)):
                zh.append(sphere_array(c, r))
                print(f"   ZH c={c} d={r}: K={zh[-1]['K']:.4f} err={zh[-1]['err']:+.4f} "
                      f"(L = {zh[-1]['L']}, {zh[-1]['steps']} steps)", flush=True)
        for c in fr:
            rs = [z for z in zh if z["c"] == c]
            e1, e2 = abs(rs[-2]["err"]), abs(rs[-1]["err"])
            rs[-1]["order"] = math.log(e1 / e2) / math.log(rs[-1]["cells_per_d"]
                                                           / rs[-2]["cells_per_d"])
        out["zick_homsy"] = zh
        print("\n3. Zick & Homsy simple cubic arrays (K = F / 6 pi mu a U; U the flux over "
              "uncut links; err_node_mean: U from the mean node velocity instead)\n"
              + _table([{**z, "order": z.get("order", "")} for z in zh],
                       ["c", "cells_per_d", "L", "K", "ref", "err", "err_node_mean", "order",
                        "steps"]))
        ok = all(abs(z["err"]) <= 0.02 for z in zh if z["cells_per_d"] >= 16)
        out["zick_homsy_within_2pct_at_16"] = ok
        print(f"   within 2% at >= 16 cells per diameter: {ok}")
    if "random" in a.rungs:
        out["random_spheres"] = random_spheres(*((40, 3.0, 8) if a.quick else (150, 4.0, 16)))
        rs = out["random_spheres"]
        print("\n4. Random sphere pack\n" + _table([rs], ["count", "resolution", "eps",
                                                         "k_D2", "k_carman_kozeny", "ratio_ck",
                                                         "kozeny", "ergun_ratio"]))
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
        out["column_bed"] = column_bed(*((4.0, 90, 6) if a.quick else (5.0, 150, 8)))
        cb = out["column_bed"]
        print("   rained sphere column, middle of the bed\n"
              + _table([cb], ["column_D", "count", "resolution", "k_D2", "eps", "eps_core",
                              "D_t_over_d_p", "A_w", "ergun_wall_ratio", "seam_share",
                              "wall_drag_share"])
              + f"\n   force balance (two-step) {cb['balance_two_step']:.8f}, period-2 swing "
              f"{cb['parity_swing']:.2e}, k over the whole period {cb['k_D2_period']:.5g} D^2")
    if "page" in a.rungs and a.page_pack:
        out["page"] = page_pack(a.page_pack, (8, 12) if a.quick else (8, 16, 24))
        print("\n6. The page's ring pack\n" + _table(out["page"]["runs"],
              ["resolution", "k_D2", "kozeny", "ergun_ratio_sauter", "ergun_ratio_envelope",
               "steps", "lattice_cells", "fluid_nodes", "memory_MiB", "peak_rss_MiB"]))
        ext = out["page"]["richardson"]
        p = ext["p"]
        print(f"   extrapolated k = {ext['k0']:.5g} D^2 ("
              + ("order 2 assumed" if ext["assumed_p"] else f"observed order {p:.2f}"
                 if math.isfinite(p) else "not monotone: finest value")
              + f"), dP/L / Ergun (Sauter) {ext['ergun_ratio_sauter']:.4f}, "
              f"(envelope) {ext['ergun_ratio_envelope']:.4f}")
    if a.json:
        from benchmarks._report import write_json
        write_json(a.json, out)
    return 0


if __name__ == "__main__":
    sys.exit(vargs.run(main))
