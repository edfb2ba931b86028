"""Silo discharge against Beverloo's law (issue 23, item 3).

    python validation/silo.py [--quick] [--orifices 5,6,7] [--workers 2] [--json FILE]

Protocol (every run; units: lengths in the mean grain diameter d = 1, grain density
rho_s = 1 (mass d^-3), g = 9.81 d / time^2 along -y (so sqrt(d / g) = 0.319 time units); the
mass flow rate W in mass / time):

- Grains: spheres of diameters 0.90, 0.95, 1.00, 1.05, 1.10 d drawn in equal shares (a +-10%
  spread against crystallisation on the flat floor), uniform solid spheres (m = rho_s pi
  d_i^3 / 6, I = 2/5 m r^2).
- Silo: a flat-bottomed cylinder of diameter Ds = 2.5 D0 (``silo_diameter``), axis on y,
  with a CIRCULAR orifice of diameter D0 centred in its floor. Walls are analytic walls, each a
  single leaf with an exact signed distance: the floor is a ``hollow_cylinder`` plate 0.2 d
  thick whose inner radius is D0 / 2 (so the orifice rim is an exact square edge, rounded by
  the grain radius as a real rim is, not the L-infinity corner that a CSG difference of a box
  and a cylinder would give), the side wall a ``hollow_cylinder`` tube.
- Contacts: the impulse engine (``Simulation.step``), grain-grain and grain-wall friction
  mu = 0.5, normal restitution e = 0.4, tangential restitution 0, dt = 4e-3 (about 80 steps
  per sqrt(d / g)), one Numba thread per run (bitwise the same at any count).
- Fill (``fill``): grains on a jittered staggered lattice (pitch 1.12 d) in the silo closed by a
  solid floor, enough for a bed of head + 2 d (start-up) + ``window`` d (the measured window)
  + 1 d, released at rest and settled until the kinetic energy per grain is below 1e-4 m g d
  (at most 3000 steps). The settled bed is then moved, as it lies, into the same silo with the
  orifice in its floor (the orifice opens at t = 0).
- Bulk density rho_b: the grains' volume cut exactly by the slab y in [1 d, top - 2 d] (top =
  the highest grain centre) over the silo's whole cross-section, times rho_s: the bed next to
  the walls included, as in a silo's bulk density.
- Discharge: a grain is discharged when its centre passes y = -1 d (below the plate), at that
  step's time; discharged grains are parked on a lattice far below (inverse mass 0, at rest: N
  does not change, so every other grain keeps its warm start). No grain out for 10 time units
  is reported as a clog (no rate).
- The rate W: the least-squares slope of the discharged mass M(t) over the steady window, from
  M = rho_b A * 2 d (start-up excluded: the arch and the dilated zone above the orifice form)
  to M = M_fill - rho_b A * head, head = Ds by default (the fill still one silo diameter high:
  Janssen, above that the rate does not depend on the fill height; the final emptying
  excluded); the run stops there. Steadiness: the slopes of the window's two halves (by time)
  and the largest deviation of M(t) from the line, relative to the window's mass. The rate's
  standard error: from the slopes of four equal blocks of the window.

Reference: Beverloo, Leniger & van de Velde, Chem. Eng. Sci. 15 (1961) 260, for a circular
orifice in a flat-bottomed silo, D0 >> d:

    W = C rho_b sqrt(g) (D0 - k d)^(5/2),   C = 0.58, k = 1.5 (the usual values;
    C 0.55-0.65 and k 1-3 in the literature, e.g. Nedderman, Statics and Kinematics of
    Granular Materials, 1992, ch. 10).

Printed: W ours beside Beverloo with 0.58 / 1.5 (with the same measured rho_b), C and k fitted
by least squares (a straight line through (D0, (W / (rho_b sqrt g))^(2/5)): slope C^(2/5),
intercept -k C^(2/5) d, Beverloo's own linearisation), and the ratio of consecutive orifices'
rates (each normalised by its own rho_b) beside Beverloo's ((D0a - k d)/(D0b - k d))^(5/2).
Assumptions to keep in mind: the silo is only 2.5 D0 wide (the smallest width at which the side
walls are usually said not to change the rate); the grains are frictional but rigid (impulse
contacts, no rolling resistance); the run stops once the window is measured.
Orifices: 5, 6 and 7 d by default (Beverloo's law is usually said to hold from D0 ~ 6 d; below
~5 d spheres of mu = 0.5 clog: a 4-5 d orifice may arch and stop, reported as a clog).
``--quick`` runs D0 = 5 and 6 with a 2 d window (a smoke test).
"""
from __future__ import annotations

import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

import validation as vargs  # noqa: E402  (the scripts' shared argument handling)

from peclet.core.validation import PecletArgumentError, check_float, check_int  # noqa: E402

G = 9.81
#: grain radii (d = 1 mean diameter), drawn in equal shares
RADII = (0.45, 0.475, 0.5, 0.525, 0.55)
RHO_S = 1.0
E, MU, DT = 0.4, 0.5, 4e-3
PLATE = 0.2                # floor thickness (d)
CROSS_Y = -1.0             # a grain is discharged when its centre passes this height
PARK_Y = -4.0              # ... and parked once below this one
PITCH = 1.12               # fill lattice pitch (> the largest diameter 1.1)
STARTUP = 2.0              # start-up excluded: this fill height's mass (d)
CLOG_TIME = 10.0           # no grain out for this long (time) after opening: a clog

BEVERLOO = dict(C=0.58, k=1.5, source="Beverloo, Leniger & van de Velde, Chem. Eng. Sci. 15 "
                "(1961) 260; C = 0.58, k = 1.5 as usually quoted (Nedderman 1992, ch. 10)")

DEFAULT_ORIFICES = (5.0, 6.0, 7.0)
QUICK_ORIFICES = (5.0, 6.0)
DEFAULT_WINDOW = 3.0       # fill height (d) whose mass makes the measured window
QUICK_WINDOW = 2.0


def silo_diameter(D0):
    """The silo's inner diameter (d) for an orifice of D0 (d): 2.5 D0."""
    return 2.5 * float(D0)


def beverloo(D0, rho_b, C=BEVERLOO["C"], k=BEVERLOO["k"], d=1.0, g=G):
    """Beverloo's mass flow rate (mass / time) through a circular orifice of diameter ``D0``
    (length) for grains of diameter ``d`` and bulk density ``rho_b`` (mass / length^3);
    0 when D0 <= k d."""
    return C * rho_b * math.sqrt(g) * max(float(D0) - k * d, 0.0) ** 2.5


def beverloo_ratio(D0a, D0b, k=BEVERLOO["k"], d=1.0):
    """Beverloo's W(D0a) / W(D0b) at equal bulk density: ((D0a - k d)/(D0b - k d))^(5/2)."""
    return ((float(D0a) - k * d) / (float(D0b) - k * d)) ** 2.5


def fit_beverloo(D0s, W, rho_b, d=1.0, g=G):
    """(C, k) by least squares of the straight line (W / (rho_b sqrt g))^(2/5) = C^(2/5)
    (D0 - k d) through the points (at least two orifice diameters)."""
    D0s, W, rho_b = (np.asarray(a, dtype=np.float64) for a in (D0s, W, rho_b))
    if len(D0s) < 2 or len(set(D0s.tolist())) < 2:
        raise PecletArgumentError("D0s", "at least two distinct orifice diameters", D0s)
    y = (W / (rho_b * math.sqrt(g))) ** 0.4
    slope, icpt = np.polyfit(D0s, y, 1)
    return float(slope ** 2.5), float(-icpt / (slope * d))


def sphere_slab_volume(c, r, y1, y2):
    """Volume of spheres (centres' heights ``c``, radii ``r``, arrays) between the planes
    y = y1 and y = y2 (exact, spherical caps)."""
    lo = np.clip(y1 - np.asarray(c), -r, r)
    hi = np.clip(y2 - np.asarray(c), -r, r)
    return math.pi * (r * r * (hi - lo) - (hi ** 3 - lo ** 3) / 3.0)


# ------------------------------------------------------------------------- the silo
def _wall(sim, kind, params, y_centre, invert=False):
    from peclet.core import geom

    b = geom.SceneBuilder()
    root = b.add_leaf(kind, params, translation=[0.0, y_centre, 0.0])
    ni, nr, _, _ = b.encode()
    return sim.add_analytic_wall(ni, nr, root, invert, E, MU)


def silo_sim(D0, Ds, top, dt=DT):
    """An empty silo (see the module notes) of inner diameter ``Ds`` whose floor has an orifice
    of diameter ``D0`` (None: a solid floor), the side wall reaching y = ``top``; axis on y
    through x = z = 0, floor top at y = 0. Returns the Simulation (shapes: ``RADII`` in
    order; contact material, gravity and dt set)."""
    from peclet.dem import Simulation

    R = 0.5 * Ds
    sim = Simulation(1)
    sim.set_gravity(0.0, -G, 0.0)
    sim.set_material_params(E, 0.0, MU)
    for r in RADII:
        sim.add_sphere_shape(r)
    if D0 is None:
        _wall(sim, "cone", [R + 1.0, R + 1.0, 0.5 * PLATE], -0.5 * PLATE)
    else:
        _wall(sim, "hollow_cylinder", [R + 1.0, PLATE, R + 1.0 - 0.5 * D0], -0.5 * PLATE)
    _wall(sim, "hollow_cylinder", [R + 1.0, top + PLATE, 1.0], 0.5 * (top - PLATE))
    sim.set_dt(dt)
    return sim


_FILLS = {}


def fill(Ds, height, seed=1, ke_tol=1e-4, max_steps=3000, dt=DT):
    """The settled fill of a silo of diameter ``Ds`` closed by a solid floor: grains for a
    bed about ``height`` (d) high on a jittered staggered lattice, released at rest and stepped
    until the kinetic energy per grain is below ``ke_tol`` m g d (m the mean grain mass; checked
    every 50 steps) or ``max_steps``. Returns a dict: ``pos`` (N, 3), ``vel``, ``omega``,
    ``shape`` (N,), ``m``, ``r`` (N,), ``steps``, ``seconds``, ``top`` (the side wall's
    height). Cached per (Ds, height, seed, ke_tol, max_steps) in the process: orifices in
    the same silo start from the same bed."""
    key = (float(Ds), float(height), int(seed), float(ke_tol), int(max_steps), float(dt))
    if key in _FILLS:
        return _FILLS[key]
    t0 = time.perf_counter()
    R = 0.5 * Ds
    top = 2.0 * height + 4.0             # the loose lattice is taller than the settled fill
    sim = silo_sim(None, Ds, top, dt)
    rng = np.random.default_rng(seed)
    v_mean = float(np.mean([math.pi / 6 * (2 * r) ** 3 for r in RADII]))
    count = int(round(0.6 * math.pi * R * R * height / v_mean))
    k = int(R / PITCH) + 1
    g = np.arange(-k, k + 1) * PITCH
    X, Z = np.meshgrid(g, g, indexing="ij")
    layer = np.column_stack([X.ravel(), Z.ravel()])
    pts, y, j, have = [], 0.6, 0, 0
    while have < count:
        xz = layer + 0.5 * PITCH * (j % 2)      # staggered layers
        xz = xz[(xz ** 2).sum(1) <= (R - 0.6) ** 2]
        pts.append(np.column_stack([xz[:, 0], np.full(len(xz), y), xz[:, 1]]))
        have += len(xz)
        y += PITCH
        j += 1
    P = np.concatenate(pts)[:count]
    P += rng.uniform(-0.03, 0.03, P.shape)
    sid = rng.integers(0, len(RADII), count)
    r = np.asarray(RADII)[sid]
    m = RHO_S * math.pi / 6.0 * (2.0 * r) ** 3
    _load(sim, P, np.zeros_like(P), np.zeros_like(P), sid, m, r)
    scale = count * float(m.mean()) * G
    steps = max_steps
    for s in range(1, max_steps + 1):
        sim.step()
        if s % 50 == 0 and sim.kinetic_energy() < ke_tol * scale:
            steps = s
            break
    out = dict(pos=sim.get_positions(), vel=sim.get_velocities(),
               omega=sim.get_angular_velocities(), shape=sid, m=m, r=r, steps=steps,
               seconds=time.perf_counter() - t0, top=top)
    _FILLS[key] = out
    return out


def _load(sim, P, V, W, sid, m, r):
    sim.set_positions(P)
    sim.set_shape_ids(sid)
    sim.set_inv_mass(1.0 / m)
    sim.set_inv_inertia(np.repeat((1.0 / (0.4 * m * r * r))[:, None], 3, axis=1))
    sim.set_velocities(V)
    sim.set_angular_velocities(W)


def bulk_density(pos, r, Ds):
    """rho_b (mass / d^3) of the settled fill: the spheres' volume in the slab y in
    [1, top - 2] (top: the highest centre) over the cross-section pi Ds^2 / 4, times rho_s."""
    y1, y2 = 1.0, float(pos[:, 1].max()) - 2.0
    if y2 <= y1 + 1.0:
        raise PecletArgumentError("fill", "at least 4 d high", y2 + 2.0)
    v = sphere_slab_volume(pos[:, 1], r, y1, y2).sum()
    return RHO_S * float(v) / (math.pi * 0.25 * Ds * Ds * (y2 - y1))


def _park(sim, idx, first):
    """Put grains ``idx`` at rest, immovable, on a lattice below the silo (slots from
    ``first``) where nothing reaches them."""
    s = first + np.arange(len(idx))
    P, V, W = sim.get_positions(), sim.get_velocities(), sim.get_angular_velocities()
    im, ii = sim.get_inv_mass(), sim.get_inv_inertia()
    P[idx] = np.column_stack([(s % 24) * 1.5 - 17.25, -12.0 - (s // 576) * 1.5,
                              ((s // 24) % 24) * 1.5 - 17.25])
    V[idx] = 0.0
    W[idx] = 0.0
    im[idx] = 0.0
    ii[idx] = 0.0
    sim.set_positions(P)
    sim.set_velocities(V)
    sim.set_angular_velocities(W)
    sim.set_inv_mass(im)
    sim.set_inv_inertia(ii)


def steady_rate(t, M, m_lo, m_hi):
    """The rate over the window m_lo <= M <= m_hi of the discharge curve (t, M: crossing
    times and cumulative masses, increasing). Returns a dict: ``W`` (slope, mass / time),
    ``W_se`` (standard error from four blocks' slopes), ``half_slopes`` (first, second half by
    time), ``half_diff`` (their relative difference), ``max_dev`` (largest |M - line| over the
    window's mass), ``t_window`` (start, end), ``window_grains`` (grains in the window),
    ``block_slopes``."""
    sel = (M >= m_lo) & (M <= m_hi)
    ts, Ms = t[sel], M[sel]
    if len(ts) < 16:
        raise PecletArgumentError("window", "at least 16 discharged grains", len(ts))
    W, b = np.polyfit(ts, Ms, 1)
    mid = 0.5 * (ts[0] + ts[-1])
    h = [np.polyfit(ts[s], Ms[s], 1)[0] for s in (ts <= mid, ts > mid)]
    edges = np.linspace(ts[0], ts[-1], 5)
    blocks = []
    for a, c in zip(edges[:-1], edges[1:]):
        s = (ts >= a) & (ts <= c)
        blocks.append(np.polyfit(ts[s], Ms[s], 1)[0] if s.sum() >= 3 else np.nan)
    blocks = np.array(blocks)
    return dict(W=float(W), W_se=float(np.nanstd(blocks, ddof=1) / math.sqrt(
                np.isfinite(blocks).sum())), half_slopes=[float(x) for x in h],
                half_diff=float((h[1] - h[0]) / W),
                max_dev=float(np.abs(Ms - (W * ts + b)).max() / (Ms[-1] - Ms[0])),
                t_window=[float(ts[0]), float(ts[-1])], window_grains=int(len(ts)),
                block_slopes=[float(x) for x in blocks])


def discharge(D0, window=DEFAULT_WINDOW, Ds=None, head=None, seed=1, settle_max=3000,
              max_time=200.0, dt=DT, progress=False):
    """One silo (see the module notes) with an orifice of diameter ``D0`` (d, > 1.5): the
    settled fill (:func:`fill`) moved onto the floor with the orifice, rho_b measured, the
    discharge run until the window is measured: ``window`` d of fill height after the 2 d of
    start-up, ending with ``head`` d of fill left (default Ds: Janssen). ``Ds`` (d) defaults to
    :func:`silo_diameter`. Returns a dict with the rate and its checks (see
    :func:`steady_rate`; ``W`` None if the orifice clogged: no grain out for ``CLOG_TIME``),
    the discharge curve (``times``, cumulative ``mass``), rho_b, counts and wall times."""
    D0 = check_float("D0", D0, 1.5, 100.0, lo_open=True)
    window = check_float("window", window, 0.5, 100.0)
    Ds = silo_diameter(D0) if Ds is None else check_float("Ds", Ds, D0 + 1.0, 200.0)
    head = Ds if head is None else check_float("head", head, 1.0, 200.0)
    seed = check_int("seed", seed, 0)
    dt = check_float("dt", dt, 0.0, 0.02, lo_open=True)
    t_wall = time.perf_counter()
    A = math.pi * 0.25 * Ds * Ds
    f = fill(Ds, head + STARTUP + window + 1.0, seed, max_steps=settle_max, dt=dt)
    m, r = f["m"], f["r"]
    rho_b = bulk_density(f["pos"], r, Ds)
    M_fill = float(m.sum())
    m_lo = rho_b * A * STARTUP
    m_hi = M_fill - rho_b * A * head
    if m_hi <= m_lo + 16 * float(m.max()):
        raise PecletArgumentError("window", "a fill taller than the head + start-up", window)
    t_open = time.perf_counter()
    sim = silo_sim(D0, Ds, f["top"], dt)
    _load(sim, f["pos"], f["vel"], f["omega"], f["shape"], m, r)
    n = len(m)
    crossed = np.full(n, np.nan)
    parked = np.zeros(n, bool)
    out, t, k, last, clogged = 0.0, 0.0, 0, 0.0, False
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=int(math.ceil(m_hi)), desc=f"silo D0={D0:g}", unit="mass")
    while out < m_hi:
        sim.step()
        k += 1
        t = k * dt
        y = sim.get_positions()[:, 1]
        new = np.isnan(crossed) & (y < CROSS_Y)
        if new.any():
            crossed[new] = t
            dm = float(m[new].sum())
            out += dm
            last = t
            if bar is not None:
                bar.update(int(math.floor(out)) - bar.n)
        go = np.flatnonzero(~parked & (y < PARK_Y))
        if len(go):
            _park(sim, go, int(parked.sum()))
            parked[go] = True
        if t - last > CLOG_TIME or t > max_time:
            clogged = t - last > CLOG_TIME
            break
    if bar is not None:
        bar.close()
    done = ~np.isnan(crossed)
    order = np.argsort(crossed[done], kind="stable")
    tc = crossed[done][order]
    Mc = np.cumsum(m[done][order])
    res = dict(D0=D0, Ds=Ds, head=head, dt=dt, grains=n, rho_b=rho_b, phi_b=rho_b / RHO_S,
               fill_mass=M_fill, window_mass=[m_lo, m_hi], settle_steps=f["steps"],
               settle_seconds=f["seconds"], steps=k, time=t, clogged=clogged,
               discharge_seconds=time.perf_counter() - t_open,
               seconds=time.perf_counter() - t_wall,
               beverloo=beverloo(D0, rho_b), times=tc.tolist(), mass=Mc.tolist(),
               state_hash=sim.state_hash())
    res.update(steady_rate(tc, Mc, m_lo, m_hi) if out >= m_hi else dict(W=None))
    return res


def _one(args):
    import numba

    numba.set_num_threads(1)
    D0, window, seed = args
    return discharge(D0, window=window, seed=seed)


def run(orifices=DEFAULT_ORIFICES, window=DEFAULT_WINDOW, seed=1, workers=2, progress=True):
    """Every orifice's :func:`discharge` in ``workers`` processes (one Numba thread each),
    largest first; returns the rows sorted by D0."""
    jobs = [(float(D0), window, seed) for D0 in sorted(orifices, reverse=True)]
    rows = []
    from tqdm import tqdm
    # one tick per finished orifice: the runs are separate processes
    bar = tqdm(total=len(jobs), desc="silo", unit="orifice", disable=not progress)
    with ProcessPoolExecutor(max_workers=max(1, workers)) as ex:
        for f in as_completed([ex.submit(_one, j) for j in jobs]):
            rows.append(f.result())
            bar.set_postfix_str(f"D0 = {rows[-1]['D0']:g} done")
            bar.update(1)
    bar.close()
    return sorted(rows, key=lambda r: r["D0"])


def compare(rows):
    """The fit and the ratios for rows with a measured rate: a dict with ``fit`` (C, k or
    None) and ``ratios`` [(D0a, D0b, ours, Beverloo k = 1.5, Beverloo fitted k)]."""
    ok = [r for r in rows if r.get("W")]
    fit = None
    if len({r["D0"] for r in ok}) >= 2:
        C, k = fit_beverloo([r["D0"] for r in ok], [r["W"] for r in ok],
                            [r["rho_b"] for r in ok])
        fit = dict(C=C, k=k)
    ratios = []
    for a, b in zip(ok[1:], ok[:-1]):
        ours = (a["W"] / a["rho_b"]) / (b["W"] / b["rho_b"])
        se = ours * math.hypot(a["W_se"] / a["W"], b["W_se"] / b["W"])
        ratios.append(dict(D0a=a["D0"], D0b=b["D0"], ours=ours, se=se,
                           beverloo=beverloo_ratio(a["D0"], b["D0"]),
                           beverloo_fit=(beverloo_ratio(a["D0"], b["D0"], fit["k"])
                                         if fit else None)))
    return dict(fit=fit, ratios=ratios)


def table(rows, cmp):
    lines = [f"{'D0/d':>5} {'Ds/d':>5} {'N':>6} {'phi_b':>6} {'W ours':>15} "
             f"{'W Bev 0.58/1.5':>14} {'ours/Bev':>8} {'W Bev fit':>10} {'halves':>7} "
             f"{'maxdev':>7} {'grains':>6} {'wall s':>7}"]
    lines.append("-" * len(lines[0]))
    fit = cmp["fit"]
    for r in rows:
        if not r.get("W"):
            lines.append(f"{r['D0']:5g} {r['Ds']:5g} {r['grains']:6d} {r['phi_b']:6.3f} "
                         f"{'clogged' if r['clogged'] else 'not reached':>15}")
            continue
        bf = beverloo(r["D0"], r["rho_b"], fit["C"], fit["k"]) if fit else float("nan")
        lines.append(f"{r['D0']:5g} {r['Ds']:5g} {r['grains']:6d} {r['phi_b']:6.3f} "
                     f"{r['W']:8.2f} +-{r['W_se']:5.2f} {r['beverloo']:14.2f} "
                     f"{r['W'] / r['beverloo']:8.3f} {bf:10.2f} {100 * r['half_diff']:+6.1f}% "
                     f"{100 * r['max_dev']:6.1f}% {r['window_grains']:6d} "
                     f"{r['seconds']:7.0f}")
    return "\n".join(lines)


def main(argv=None):
    p = vargs.ScriptParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true",
                   help=f"orifices {QUICK_ORIFICES}, window {QUICK_WINDOW} d (a smoke test)")
    p.add_argument("--orifices", type=vargs.real_list(1.5, 100.0, lo_open=True), default=None,
                   help="orifice diameters in d, comma-separated, each in (1.5, 100] "
                   "(default 5,6,7)")
    p.add_argument("--window", type=vargs.real(0.5, 100.0), default=None,
                   help=f"measured window as fill height in d, in [0.5, 100] "
                   f"(default {DEFAULT_WINDOW})")
    p.add_argument("--seed", type=vargs.integer(0, 2 ** 63 - 1), default=1,
                   help="generator seed >= 0 (default 1)")
    p.add_argument("--workers", type=vargs.integer(1, 64), default=2,
                   help="processes, in [1, 64] (default 2)")
    p.add_argument("--json", type=vargs.output_file, default=None,
                   help="write every number as JSON here (a file in an existing directory)")
    a = p.parse_args(argv)
    orifices = a.orifices or (QUICK_ORIFICES if a.quick else DEFAULT_ORIFICES)
    window = a.window if a.window is not None else (QUICK_WINDOW if a.quick else DEFAULT_WINDOW)
    workers = a.workers
    t0 = time.perf_counter()
    rows = run(orifices, window, a.seed, workers)
    cmp = compare(rows)
    print(f"Silo discharge: spheres d = 0.9-1.1 (mean 1), rho_s = 1, g = {G}, e = {E}, "
          f"mu = {MU} (grain and wall), dt = {DT}; flat floor, circular orifice D0, "
          f"silo Ds = 2.5 D0; window: {window:g} d of fill after 2 d of start-up, "
          f"ending with Ds of fill left")
    print(table(rows, cmp))
    print("(W in mass/time, +- the standard error of four blocks; halves: the second half's "
          "slope minus the first's, over W; maxdev: largest |M - line| over the window's mass)")
    fit = cmp["fit"]
    if fit:
        print(f"\nBeverloo fitted by least squares on (W / rho_b sqrt g)^(2/5) vs D0: "
              f"C = {fit['C']:.3f}, k = {fit['k']:.2f}   (usual: C = {BEVERLOO['C']}, "
              f"k = {BEVERLOO['k']})")
    for q in cmp["ratios"]:
        print(f"ratio W({q['D0a']:g}) / W({q['D0b']:g}) (per rho_b): ours {q['ours']:.3f} "
              f"+- {q['se']:.3f}, Beverloo (k = 1.5) {q['beverloo']:.3f}, "
              f"difference {100 * (q['ours'] / q['beverloo'] - 1):+.1f}%")
    print(f"Reference: {BEVERLOO['source']}.")
    print(f"\n{len(rows)} runs, {sum(r['grains'] for r in rows)} grains, "
          f"{sum(r['steps'] + r['settle_steps'] for r in rows)} steps, "
          f"{time.perf_counter() - t0:.0f} s wall ({workers} processes)")
    if a.json:
        from peclet.core.files import write_json
        write_json(a.json, dict(rows=rows, comparison=cmp, beverloo=BEVERLOO,
                                params=dict(radii=RADII, rho_s=RHO_S, g=G, e=E, mu=MU, dt=DT,
                                            plate=PLATE, cross_y=CROSS_Y, startup=STARTUP,
                                            window=window, seed=a.seed)))
    return 0


if __name__ == "__main__":
    sys.exit(vargs.run(main))
