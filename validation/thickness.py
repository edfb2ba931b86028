"""The page's open question: is the envelope packing fraction f_env thickness-independent?

    python validation/thickness.py [--quick] [--workers 2] [--out PATH.json]

The page's Equation 2, eps(t) = 1 - f_env s(t) with s(t) = V_solid(t) / V_env, carries one
measured f_env (its t/D = 0.12 ring's) across wall thicknesses, which assumes f_env does not
depend on the wall ("a hypothesis this page does not test"). Here the pour is re-run at every
thickness and the hypothesis tested.

Rings: the page's sweep construction, :func:`peclet.packing.bed.elements.pall_ring_of_thickness`
(D = 1, height 1, four windows per row, webs scaled with the wall, as in
``analysis.wall_sweep``), at t/D = 0.02, 0.04, 0.08, 0.12, 0.16. Shell probes follow
the thinnest wall (``peclet.packing.bed.api.element_model``: even-spread spacing <= t, so 1200
probes down to t/D = 0.08 and ~15 000 at 0.02).

Protocol (:data:`FULL`), the same for every thickness and seed: 64 rings rained into a
periodic box of 4 x 4 D with a floor (``box:4``; a bed about 6 D deep, its first bulk window
about 4 D tall), ``RainProtocol(batch=1, insert_every=4,
drop=5, speed=2)``: one ring every 4 steps of dt = 2e-3 (125 rings per unit time) released at
random position and orientation 5 D above the bed's top moving down at 2 D/time, settled
until the kinetic energy per ring stays below 1e-5 m g D for 100 steps, then 200 damped quench
steps; ring-ring and ring-floor friction mu = 0.5, normal restitution e_n = 0.15 (the page's
material). Seeds 1..8 per thickness; Numba 1 thread per pack, ``--workers`` packs at once.
Cost on 2 idle cores (estimated from 80-ring calibration packs, 1 thread each: 11 ms/step at
1200 probes, 28 ms/step at t/D = 0.02 with 14 630): about 40 s a pack at 1200 probes and
110 s at t/D = 0.02, some 18 minutes for the 40 packs; proportionally longer on a shared
machine (measured: 2200 s at nice 5 beside other jobs, load average 5-8 on 2 cores).

Measured per pack (the page's Step 5 analysis over its first bulk window,
``analysis.bulk_windows``; ``samples`` Monte Carlo points): eps (voidage = 1 - solid fraction),
f_env, the doubly covered volume fraction ``double`` (points inside two rings at once) and the
deepest probe overlap (``analysis.probe_overlap``, a length in D). Per thickness: the mean over
seeds and its 95% interval (Student t, n - 1 degrees of freedom).

Prediction: s(t) = V_solid/V_env by quadrature (``analysis.wall_sweep``). f_env as Equation 2
defines it, N V_env / V_bed = (1 - eps) / s(t), per pack (column "f_env"; the envelope
fraction measured directly by Monte Carlo over the same window, "f_env (MC)", agrees with it to
the window's edge effects). eps_pred(t) = 1 - f_ref s(t), one value per seed of the reference
ring (t_ref = 0.12, the page's; the thickest if 0.12 is not studied), so at t_ref the
prediction equals the measurement by construction; the difference eps_meas(t) - eps_pred(t)
with a Welch 95% interval (the two seed samples are independent). The answer is a
significance statement: the least-squares slope of f_env against t/D over every pack (95%
interval, p-value) and the largest difference between Eq. 2 and the measured voidage.

Writes ``validation/results/thickness.json`` (atomically) and prints the table and the answer.
``--quick``: three thicknesses x 2 seeds, 24 rings in a 3 D box (a smoke run, minutes).
"""
from __future__ import annotations

import dataclasses
import math
import os
import sys
import time

import numpy as np

from peclet.core.files import write_json

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:           # run as a script: the repository, for the package below
    sys.path.insert(0, ROOT)

import validation as vargs  # noqa: E402  (the scripts' shared argument handling)

#: Confidence of every interval.
CONFIDENCE = 0.95


@dataclasses.dataclass(frozen=True)
class Study:
    """One study's sizes (see the module docstring for the protocol)."""

    thicknesses: tuple = (0.02, 0.04, 0.08, 0.12, 0.16)
    seeds: tuple = tuple(range(1, 9))
    t_ref: float = 0.12
    count: int = 64
    box: float = 4.0
    drop: float = 5.0
    mu: float = 0.5
    e_n: float = 0.15
    samples: int = 200_000
    settle_steps: int = 6000

    def protocol(self):
        from peclet.packing import RainProtocol

        return RainProtocol(batch=1, insert_every=4, drop=self.drop, speed=2.0,
                            settle_steps=self.settle_steps)


FULL = Study()
QUICK = Study(thicknesses=(0.04, 0.08, 0.12), seeds=(1, 2), count=24, box=3.0, drop=3.0,
              samples=50_000)


def ring(t):
    """The page's sweep ring of wall thickness ``t`` (D = 1)."""
    from peclet.packing.bed.elements import pall_ring_of_thickness

    return pall_ring_of_thickness(float(t))


def overlap_depth(geo):
    """Deepest probe of any ring inside another (a length in D)."""
    from peclet.packing.analysis import geometry as analysis

    f = getattr(analysis, "probe_overlap", None)
    return float((f(geo) if f is not None else analysis.contacts(geo))["max_depth"])


def one_pack(study, t, seed):
    """Pour one bed and measure it; returns a JSON-able dict."""
    from peclet.packing import Material, pack
    from peclet.packing.analysis import geometry as analysis

    t0 = time.perf_counter()
    res = pack(ring(t), f"box:{study.box:g}", count=study.count, protocol=study.protocol(),
               material=Material(e_n=study.e_n, e_t=0.0, mu=study.mu), seed=int(seed),
               threads=1, progress=False)
    t1 = time.perf_counter()
    geo = analysis.PackGeometry(res.pack)
    windows, scale = analysis.bulk_windows(res.pack)
    fr = analysis.cover_fractions(geo, windows[0], study.samples, seed=0)
    return dict(t=float(t), seed=int(seed), eps=fr["eps"], eps_se=fr["eps_se"],
                solid=1.0 - fr["eps"], f_env=fr["f_env"], f_env_se=fr["f_env_se"],
                double=fr["double"], max_depth=overlap_depth(geo), window=fr["window"],
                window_scale=scale, probes=int(len(res.element.shell)), steps=int(res.steps),
                complete=bool(res.complete), state_hash=res.state_hash(),
                seconds=dict(pack=t1 - t0, analysis=time.perf_counter() - t1))


def _one(args):
    return one_pack(*args)


def run_packs(study, workers=1, log=None):
    """Every (thickness, seed) pack, in that order; ``workers`` processes (1: this one)."""
    jobs = [(study, t, s) for t in study.thicknesses for s in study.seeds]
    out = []
    if workers <= 1:
        for j in jobs:
            out.append(_one(j))
            if log:
                log(_progress(out[-1], len(out), len(jobs)))
        return out
    import concurrent.futures as cf
    import multiprocessing as mp

    with cf.ProcessPoolExecutor(workers, mp_context=mp.get_context("spawn")) as ex:
        for k, r in enumerate(ex.map(_one, jobs), 1):
            out.append(r)
            if log:
                log(_progress(r, k, len(jobs)))
    return out


def _progress(r, k, n):
    return (f"[{k}/{n}] t/D = {r['t']:.3f} seed {r['seed']}: eps {r['eps']:.4f}, f_env "
            f"{r['f_env']:.4f}, {r['steps']} steps, {r['seconds']['pack']:.0f} s "
            f"({r['probes']} probes)")


# ---------------------------------------------------------------------- statistics
def mean_ci(x):
    """(mean, half-width of the 95% interval, n): Student t over the values ``x``."""
    from scipy.stats import t as student_t

    x = np.asarray(x, float)
    n = len(x)
    m = float(x.mean())
    if n < 2:
        return m, math.nan, n
    se = float(x.std(ddof=1)) / math.sqrt(n)
    return m, float(student_t.ppf(0.5 + CONFIDENCE / 2, n - 1)) * se, n


def welch(x, y):
    """(mean(x) - mean(y), 95% half-width, p-value): Welch's two-sample t."""
    from scipy.stats import t as student_t

    x, y = np.asarray(x, float), np.asarray(y, float)
    d = float(x.mean() - y.mean())
    if len(x) < 2 or len(y) < 2:
        return d, math.nan, math.nan
    vx, vy = x.var(ddof=1) / len(x), y.var(ddof=1) / len(y)
    se = math.sqrt(vx + vy)
    if se == 0.0:
        return d, 0.0, 1.0 if d == 0.0 else 0.0
    df = (vx + vy) ** 2 / (vx ** 2 / (len(x) - 1) + vy ** 2 / (len(y) - 1))
    half = float(student_t.ppf(0.5 + CONFIDENCE / 2, df)) * se
    p = float(2.0 * student_t.sf(abs(d) / se, df))
    return d, half, p


def slope(t, f):
    """Least-squares slope of ``f`` against ``t``: (slope, 95% half-width, p-value)."""
    from scipy.stats import linregress, t as student_t

    r = linregress(np.asarray(t, float), np.asarray(f, float))
    half = float(student_t.ppf(0.5 + CONFIDENCE / 2, len(t) - 2)) * float(r.stderr)
    return float(r.slope), half, float(r.pvalue)


def summarize(study, packs, s_of_t=None):
    """Per-thickness rows and the answer. ``s_of_t``: {t: V_solid/V_env} (default: by
    quadrature, ``analysis.wall_sweep``)."""
    from peclet.packing.analysis import geometry as analysis

    ts = list(study.thicknesses)
    t_ref = study.t_ref if study.t_ref in ts else max(ts)
    if s_of_t is None:
        s_of_t = {r["t"]: r["s"] for r in analysis.wall_sweep(ts, 0.0, make=ring, n=32,
                                                               tol=1e-6)}
    by_t = {t: [p for p in packs if p["t"] == t] for t in ts}
    for p in packs:               # Eq. 2's f_env = N V_env / V_bed = (1 - eps) / s
        p["f_eq2"] = (1.0 - p["eps"]) / float(s_of_t[p["t"]])
    f_ref = np.array([p["f_eq2"] for p in by_t[t_ref]])
    fm_ref, fh_ref, _ = mean_ci(f_ref)
    rows = []
    for t in ts:
        ps = by_t[t]
        s = float(s_of_t[t])
        eps = np.array([p["eps"] for p in ps])
        fe = np.array([p["f_eq2"] for p in ps])
        em, eh, n = mean_ci(eps)
        fm, fh, _ = mean_ci(fe)
        mm, mh, _ = mean_ci([p["f_env"] for p in ps])
        pred = 1.0 - s * f_ref                  # Eq. 2 at t, one value per reference seed
        pm, ph, _ = mean_ci(pred)
        # at t_ref the prediction is the measurement itself (paired, identical): 0 exactly
        d, dh, dp = welch(eps, pred) if t != t_ref else (float(np.mean(eps - pred)), 0.0, 1.0)
        fd, fdh, fdp = welch(fe, f_ref)
        dm, dh_, _ = mean_ci([p["double"] for p in ps])
        rows.append(dict(t=t, t_over_d=t, n=n, s=s, probes=int(ps[0]["probes"]),
                         f_env=fm, f_env_ci=fh, f_env_mc=mm, f_env_mc_ci=mh,
                         eps=em, eps_ci=eh, solid=1.0 - em,
                         eps_pred=pm, eps_pred_ci=ph, diff=d, diff_ci=dh, diff_p=dp,
                         f_env_diff=fd, f_env_diff_ci=fdh, f_env_diff_p=fdp,
                         double=dm, double_ci=dh_,
                         max_depth=float(max(p["max_depth"] for p in ps)),
                         max_depth_over_t=float(max(p["max_depth"] for p in ps)) / t,
                         steps_mean=float(np.mean([p["steps"] for p in ps])),
                         complete=all(p["complete"] for p in ps)))
    b, bh, bp = slope([p["t"] for p in packs], [p["f_eq2"] for p in packs])
    thin = [r for r in rows if r["t"] != t_ref]
    worst = max(thin, key=lambda r: abs(r["diff"])) if thin else rows[0]
    answer = dict(t_ref=t_ref, f_ref=fm_ref, f_ref_ci=fh_ref, slope=b, slope_ci=bh,
                  slope_p=bp, worst_t=worst["t"], worst_diff=worst["diff"],
                  worst_diff_ci=worst["diff_ci"], worst_diff_p=worst["diff_p"],
                  significant=bool(bp < 1 - CONFIDENCE),
                  sentence=sentence(b, bh, bp, worst, t_ref, len(packs)))
    return rows, answer


def sentence(b, bh, bp, worst, t_ref, n):
    """The answer to the page's question, from the numbers (never a fixed verdict)."""
    fit = (f"d f_env / d(t/D) = {b:+.3f} +- {bh:.3f} (95%, p = {bp:.2g}, {n} packs)")
    eq2 = (f"Eq. 2 from the t/D = {t_ref:g} ring's f_env misses the measured voidage by at "
           f"most {worst['diff']:+.4f} +- {worst['diff_ci']:.4f} (at t/D = {worst['t']:g}, "
           f"p = {worst['diff_p']:.2g})")
    if bp < 1 - CONFIDENCE:
        return (f"No: f_env depends on the wall thickness at the 95% level, {fit}, so {eq2}.")
    return (f"Yes within this study's resolution: f_env shows no significant dependence on the "
            f"wall thickness, {fit}, and {eq2}.")


# ---------------------------------------------------------------------- report
COLUMNS = ("t/D", "probes", "f_env +- 95%", "f_env (MC) +- 95%", "eps measured +- 95%",
           "eps Eq.2 (t_ref) +- 95%", "difference [95%]", "double", "deepest probe (D, /t)")


def table(rows, answer):
    """The study's table (text)."""
    out = []
    for r in rows:
        mark = " (ref)" if r["t"] == answer["t_ref"] else ""
        out.append([f"{r['t']:.3f}{mark}", str(r["probes"]),
                    f"{r['f_env']:.4f} +- {r['f_env_ci']:.4f}",
                    f"{r['f_env_mc']:.4f} +- {r['f_env_mc_ci']:.4f}",
                    f"{r['eps']:.4f} +- {r['eps_ci']:.4f}",
                    f"{r['eps_pred']:.4f} +- {r['eps_pred_ci']:.4f}",
                    f"{r['diff']:+.4f} [{r['diff'] - r['diff_ci']:+.4f}, "
                    f"{r['diff'] + r['diff_ci']:+.4f}]",
                    f"{r['double']:.2e}",
                    f"{r['max_depth']:.4f} ({r['max_depth_over_t']:.3f} t)"])
    w = [max(len(x) for x in [h] + [o[i] for o in out]) for i, h in enumerate(COLUMNS)]
    line = lambda cells: "  ".join(f"{c:<{w[i]}}" for i, c in enumerate(cells))  # noqa: E731
    return "\n".join([line(COLUMNS), "-" * (sum(w) + 2 * len(w))] + [line(o) for o in out])


def protocol_text(study):
    return (f"{study.count} page-sweep Pall rings per pack rained into a periodic box "
            f"{study.box:g} x {study.box:g} D with a floor, one ring every 4 steps (dt 2e-3) "
            f"from {study.drop:g} D above the bed at 2 D/time, settle to KE < 1e-5 m g D, "
            f"200 quench steps; mu = {study.mu:g}, e_n = {study.e_n:g}; seeds "
            f"{study.seeds[0]}..{study.seeds[-1]} ({len(study.seeds)}) per thickness; "
            f"{study.samples} Monte Carlo points in the first bulk window")


def main(argv=None):
    ap = vargs.ScriptParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a smoke run (minutes)")
    ap.add_argument("--workers", type=vargs.integer(1, 64), default=2,
                    help="packs at once, in [1, 64] (default 2)")
    ap.add_argument("--out", type=vargs.output_file, default=None,
                    help="JSON (a file in an existing directory; default validation/results/"
                    "thickness.json, thickness_quick.json with --quick)")
    a = ap.parse_args(argv)
    study = QUICK if a.quick else FULL
    here = os.path.dirname(os.path.abspath(__file__))
    out = a.out or os.path.join(here, "results",
                                "thickness_quick.json" if a.quick else "thickness.json")
    log = lambda s: print(s, file=sys.stderr, flush=True)  # noqa: E731
    log(f"thickness study: {protocol_text(study)}")
    t0 = time.perf_counter()
    packs = run_packs(study, a.workers, log)
    rows, answer = summarize(study, packs)
    print(table(rows, answer))
    print()
    print(answer["sentence"])
    print(f"\nprotocol: {protocol_text(study)}; {time.perf_counter() - t0:.0f} s in all")
    write_json(out, dict(study=dataclasses.asdict(study), protocol=protocol_text(study),
                         confidence=CONFIDENCE, rows=rows, answer=answer, packs=packs,
                         seconds=time.perf_counter() - t0, columns=list(COLUMNS)))
    print(f"wrote {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(vargs.run(main))
