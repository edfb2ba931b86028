"""The drum's forms of motion: the bed's free surface and dynamic angle, the regime criteria and
Mellmann's Froude ranges (the notes of :mod:`peclet.packing.experiments.drum`). Pure functions
of the sampled grain states: no run's numbers depend on them."""
from __future__ import annotations

import math

import numpy as np

#: Gravity (m/s^2) of the drum's scaling (the drum's own G).
G = 9.81

#: Mellmann (2001), Table 1: Froude ranges of the transverse forms of motion (fill > 0.1).
MELLMANN = {"slumping": (1e-5, 1e-3), "rolling": (1e-4, 1e-2), "cascading": (1e-3, 1e-1),
            "cataracting": (1e-1, 1.0), "centrifuging": (1.0, math.inf)}

#: Regime thresholds (see the module notes).
CENTRIFUGE_HIGH = 0.15
CENTRIFUGE_COROTATING = 0.9
CATARACT_AIRBORNE = 0.01
SLUMP_REST_SHARE = 0.2
REST_FLOWING = 0.02
CASCADE_S_SHAPE = 0.035

#: Surface points (column tops, columns 1 D wide) the free surface's line fit takes at least.
SURFACE_POINTS = 4
#: The fewest grains whose regime is defined: every regime but centrifuging describes the bed's
#: free surface, whose fit takes at least SURFACE_POINTS column tops, and a column's top is a
#: surface only over a bed beneath it (at least two grains a column): 2 x 4 = 8 grains. One
#: grain alone rests in the drum or rolls in it, which the criteria would call "slumping" or
#: "rolling"; it is no bed.
MIN_GRAINS = 2 * SURFACE_POINTS


def _surface(X, r, R, d):
    """Column tops (xs, ys) of the contiguous bed and the mask of grains above their column's
    bed (see the module notes)."""
    col = np.floor(X[:, 0] / d).astype(np.int64)
    above = np.zeros(len(X), bool)
    xs, ys = [], []
    for c in np.unique(col):
        idx = np.nonzero(col == c)[0]
        idx = idx[np.argsort(X[idx, 1], kind="stable")]
        y = X[idx, 1]
        gaps = np.diff(y)
        brk = np.nonzero(gaps > 1.5 * d)[0]
        last = brk[0] if len(brk) else len(idx) - 1
        above[idx[last + 1:]] = True
        top = y[last] + r[idx[last]]
        xc = (c + 0.5) * d
        if xc * xc + top * top <= (R - 1.5 * d) ** 2:
            xs.append(xc)
            ys.append(top)
    return np.array(xs), np.array(ys), above


def measure(X, V, r, R, omega, d=1.0, window=None):
    """One sample of the state (see the module notes): dict with ``angle`` (degrees, NaN
    without a free surface of >= 4 points), ``s_shape`` (R), ``airborne``, ``flowing``,
    ``corotating``, ``coverage``, ``points`` (surface points used) and the fit (``slope``,
    ``intercept``). ``window``: mask of the grains in the axial measuring window."""
    X = np.asarray(X, float)
    V = np.asarray(V, float)
    n = len(X)
    w = np.ones(n, bool) if window is None else np.asarray(window, bool)
    xs, ys, above = _surface(X[w], r[w], R, d)
    rad = np.hypot(X[:, 0], X[:, 1])
    out = dict(angle=math.nan, s_shape=math.nan, slope=math.nan, intercept=math.nan,
               points=int(len(xs)))
    if len(xs) >= SURFACE_POINTS:
        a, b = np.polyfit(xs, ys, 1)
        out.update(slope=float(a), intercept=float(b), angle=math.degrees(math.atan(a)))
        if len(xs) >= 6:
            c3 = np.polyfit(xs, ys, 3)
            xx = np.linspace(xs.min(), xs.max(), 64)
            dev = np.abs(np.polyval(c3, xx) - (a * xx + b)) * math.cos(math.atan(a))
            out["s_shape"] = float(dev.max() / R)
    inner = rad[w] < R - 1.5 * d
    out["airborne"] = float(np.count_nonzero(above & inner) / max(1, int(w.sum())))
    vrig = omega * np.column_stack([-X[:, 1], X[:, 0], np.zeros(n)])
    rel = np.sqrt(((V - vrig) ** 2).sum(axis=1))
    out["flowing"] = float(np.mean(rel > 0.1 * math.sqrt(G) * d)) if n else 0.0
    om_g = (X[:, 0] * V[:, 1] - X[:, 1] * V[:, 0]) / np.maximum(rad * rad, 1e-12)
    out["corotating"] = float(np.mean(np.abs(om_g - omega) < 0.1 * abs(omega))) if n else 0.0
    near = rad > R - 2.5 * d
    sect = np.floor((np.arctan2(X[near, 1], X[near, 0]) + math.pi) / (2 * math.pi) * 36)
    out["coverage"] = float(len(np.unique(np.clip(sect, 0, 35))) / 36.0)
    out["high"] = float(np.mean(X[:, 1] > 0.5 * R)) if n else 0.0
    return out


def classify(samples, grains=None):
    """The regime of the measured ``samples`` (list of :func:`measure` dicts) and the
    criteria's values (see the module notes). ``grains``: the bed's grain count, if known; a
    bed of fewer than :data:`MIN_GRAINS` is "undetermined" (criteria: ``grains`` and
    ``min_grains``), having no free surface to classify."""
    if not samples:
        return "undetermined", {}
    if grains is not None and int(grains) < MIN_GRAINS:
        return "undetermined", dict(grains=int(grains), min_grains=MIN_GRAINS)
    m = lambda k: float(np.nanmean([s[k] for s in samples])) \
        if np.any(np.isfinite([s[k] for s in samples])) else math.nan  # noqa: E731
    crit = dict(coverage=m("coverage"), corotating=m("corotating"), airborne=m("airborne"),
                high=m("high"),
                rest_share=float(np.mean([s["flowing"] < REST_FLOWING for s in samples])),
                flowing=m("flowing"), s_shape=m("s_shape"))
    if crit["high"] >= CENTRIFUGE_HIGH and crit["corotating"] >= CENTRIFUGE_COROTATING:
        return "centrifuging", crit
    if crit["airborne"] >= CATARACT_AIRBORNE:
        return "cataracting", crit
    if crit["rest_share"] >= SLUMP_REST_SHARE:
        return "slumping", crit
    if np.isfinite(crit["s_shape"]) and crit["s_shape"] >= CASCADE_S_SHAPE:
        return "cascading", crit
    return "rolling", crit


def expected_regimes(fr):
    """Mellmann's regimes whose Froude range holds ``fr`` (bounds included: a Froude number
    on a boundary, e.g. 1e-2, belongs to both neighbours)."""
    return [k for k, (lo, hi) in MELLMANN.items() if lo <= fr <= hi]


def angle_stats(times, angles, t_rev):
    """Mean, spread (standard deviation of the means over windows of 1/8 revolution, at least
    4 windows), sample standard deviation, 5th and 95th percentiles (degrees) of the finite
    ``angles``."""
    t = np.asarray(times, float)
    a = np.asarray(angles, float)
    ok = np.isfinite(a)
    if ok.sum() < 2:
        return dict(mean=math.nan, spread=math.nan, std=math.nan, p05=math.nan, p95=math.nan,
                    windows=0)
    t, a = t[ok], a[ok]
    span = max(t[-1] - t[0], 1e-12)
    nw = max(4, int(round(span / (t_rev / 8.0))))
    nw = min(nw, len(a) // 2) or 1
    edges = np.linspace(t[0], t[-1] + 1e-12, nw + 1)
    means = [a[(t >= lo) & (t < hi)].mean() for lo, hi in zip(edges[:-1], edges[1:])
             if np.any((t >= lo) & (t < hi))]
    return dict(mean=float(a.mean()), spread=float(np.std(means)), std=float(a.std()),
                p05=float(np.percentile(a, 5)), p95=float(np.percentile(a, 95)),
                windows=len(means))


# ---------------------------------------------------------------------------- the run
