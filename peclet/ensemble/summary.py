"""Ensemble statistics per sweep point, and their CSV / JSON / figure.

Per sweep point and figure of merit (eps, f_env, Z) over its n realizations with a finite value:
the mean, the standard error s / sqrt(n) (s the sample standard deviation, ddof = 1) and the
95% confidence interval of the mean, mean -+ t_{0.975, n-1} * se (Student t; undefined, NaN,
for n < 2). The realizations of a point are independent (different start-cloud seeds), which
is what the interval assumes.
"""
from __future__ import annotations

import csv
import io
import math

import numpy as np

from peclet.core import files
from peclet.core.files import write_text


__all__ = ["summarize", "write_csv", "write_json", "write_figure", "LABELS", "CONFIDENCE"]

CONFIDENCE = 0.95

#: Row key of each figure of merit -> its name in the summary (columns ``<name>_mean`` ...).
LABELS = {"eps": "eps", "f_env": "f_env", "z_mean": "Z"}
_TITLES = {"eps": "bed porosity eps", "f_env": "envelope packing fraction f_env",
           "Z": "mean coordination Z"}


def _stats(values):
    from scipy.stats import t as student_t

    v = np.asarray([x for x in values if x is not None and math.isfinite(x)], np.float64)
    n = len(v)
    mean = float(v.mean()) if n else math.nan
    if n < 2:
        return dict(n=n, mean=mean, sd=math.nan, se=math.nan, ci_lo=math.nan, ci_hi=math.nan)
    sd = float(v.std(ddof=1))
    se = sd / math.sqrt(n)
    half = float(student_t.ppf(0.5 + CONFIDENCE / 2, n - 1)) * se
    return dict(n=n, mean=mean, sd=sd, se=se, ci_lo=mean - half, ci_hi=mean + half)


def summarize(rows, swept=()):
    """One dict per sweep point (in first-seen order): the swept values, ``n`` (realizations
    of the point), ``seeds`` and for each figure F in (eps, f_env, Z): F_n, F_mean, F_sd,
    F_se, F_ci_lo, F_ci_hi.
    ``rows``: :func:`peclet.ensemble.run`'s table; ``swept``: the parameter names that define
    a point (none: one point of every row)."""
    swept = list(swept)
    groups = {}
    for r in rows:
        groups.setdefault(tuple(r[k] for k in swept), []).append(r)
    out = []
    for key, rs in groups.items():
        point = dict(zip(swept, key))
        point["n"] = len(rs)
        point["seeds"] = sorted(r["seed"] for r in rs)
        for field, name in LABELS.items():
            for stat, val in _stats([r[field] for r in rs]).items():
                point[f"{name}_{stat}"] = val
        out.append(point)
    return out


def _columns(points):
    return [k for k in points[0] if k != "seeds"]


def write_csv(path, points):
    """The summary as CSV (one row per sweep point; NaN as an empty cell), atomically."""
    cols = _columns(points)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for p in points:
        w.writerow(["" if isinstance(p[c], float) and not math.isfinite(p[c])
                    else (repr(p[c]) if isinstance(p[c], float) else p[c]) for c in cols])
    return write_text(path, buf.getvalue(), newline="")


def write_json(path, points, swept=(), extra=None):
    """The summary as JSON ({confidence, swept, points, ...extra}; NaN as null), atomically."""
    doc = dict(confidence=CONFIDENCE, interval="Student t on the mean over seeds",
               swept=list(swept), points=points, **(extra or {}))
    return files.write_json(path, doc)


def write_figure(path, points, rows, swept=()):
    """summary.png: one panel per figure of merit against the first swept parameter (one
    series per combination of the others), mean with its 95% interval as error bars, every
    realization as a faint dot. Without a sweep: the values against the seed, with the mean
    and its interval as a line and a band. Drawn through :mod:`peclet.core.figures`
    (matplotlib's global backend is left alone)."""
    from peclet.core.figures import new_figure, save_png

    swept = list(swept)
    fig = new_figure((4.0 * len(LABELS), 3.4), dpi=120)
    axes = fig.subplots(1, len(LABELS))
    for ax, (field, name) in zip(np.atleast_1d(axes), LABELS.items()):
        if swept:
            x0, rest = swept[0], swept[1:]
            series = {}
            for p in points:
                series.setdefault(tuple(p[k] for k in rest), []).append(p)
            for key, ps in series.items():
                ps = sorted(ps, key=lambda p: p[x0])
                x = np.array([p[x0] for p in ps], float)
                m = np.array([p[f"{name}_mean"] for p in ps], float)
                lo = m - np.array([p[f"{name}_ci_lo"] for p in ps], float)
                hi = np.array([p[f"{name}_ci_hi"] for p in ps], float) - m
                lab = ", ".join(f"{k}={v:g}" for k, v in zip(rest, key)) or None
                ax.errorbar(x, m, yerr=np.nan_to_num(np.vstack([lo, hi])), marker="o",
                            capsize=3, label=lab)
                sel = [r for r in rows if tuple(r[k] for k in rest) == key]
                ax.plot([r[x0] for r in sel], [r[field] for r in sel], ".", color="0.6",
                        ms=3, zorder=0)
            ax.set_xlabel(x0)
            if rest:
                ax.legend(fontsize=7)
        else:
            p = points[0]
            seeds = [r["seed"] for r in rows]
            ax.plot(seeds, [r[field] for r in rows], "o", ms=4)
            ax.axhline(p[f"{name}_mean"], color="k", lw=1)
            if math.isfinite(p[f"{name}_ci_lo"]):
                ax.axhspan(p[f"{name}_ci_lo"], p[f"{name}_ci_hi"], color="0.85", zorder=0)
            ax.set_xlabel("seed")
        ax.set_title(_TITLES[name], fontsize=9)
        ax.grid(alpha=0.3)
    fig.suptitle(f"ensemble: mean and {CONFIDENCE:.0%} interval over seeds", fontsize=10)
    fig.tight_layout()
    return save_png(fig, path)
