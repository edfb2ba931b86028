"""Pressure drop against Reynolds number, from creeping flow into the inertial regime.

**Reynolds number** (stated once, used everywhere): the plain particle Reynolds number
``Re = rho U D / mu`` with U the superficial velocity and D the element's diameter (the pack's
length unit: the sphere diameter for spheres, the outer diameter for rings); the modified
``Re / (1 - eps)`` of Ergun-style papers is reported beside it (``Re_mod``).

**How each point is run.** The existing TRT solver (:func:`peclet.flow.solver.solve`), driven
by a body force, on one geometry (:func:`peclet.flow.setup.prepare`) for every point, in
increasing Re. In lattice units (cell h = D / res, rho0 = 1) Re = U res / nu, so a point is a
choice of the viscosity nu and the force g:

- **Mach bound**: max |u| over the fluid nodes < ``mach`` c_s (default 0.3, c_s = 1/sqrt 3).
  The solver's incompressible equilibrium (He & Luo) keeps the compressibility error of dP/L
  far below Ma^2: measured on a grown 40-sphere cell at D/8, Re 4.6, the same point at
  max|u| = 0.071, 0.14, 0.28 and 0.57 c_s gave f = 1507.94, 1508.01, 1508.30, 1509.49
  (2.4e-4 at 0.28 c_s, about 3e-3 Ma^2). The ratio r = max|u| / U is taken from the previous
  point (10 before the first), and U is capped at 0.75 mach c_s / r (room for the force's
  miss of the target Re and the ratio's growth with Re); a run that still exceeds the bound
  is stopped as ``mach``;
- **viscosity**: nu = min(1/6, U_cap res / Re) (the largest the bound allows: the fastest
  convergence), with tau+ = 3 nu + 1/2 and the magic product Lambda = 1/4 fixing tau- (the
  TRT's most stable choice; measured on a grown 40-sphere cell at D/6, Re 2.5, nu = 0.0089:
  Lambda = 3/16, 1/12 and 0.01 diverged within 200 steps, 1/4 converged in 1011 steps; 1/2,
  1 and 2 diverged where 1/4 did). Lambda enters the wall rule's error in a pack: at D/8 on a
  grown 40-sphere cell the creeping k is 6.79e-4 D^2 with 1/4 and 6.43e-4 with 3/16
  (:func:`~peclet.flow.permeability.permeability`'s choice), 5.6 % apart, so at coarse
  resolutions the curve's low-Re f is not permeability()'s: compare curves at one
  resolution, and take k from the grid study. The wall rule is the corrected linear one
  (``scheme``): plain Bouzidi stayed stable one Re step further but its creeping f moved by
  8 % with nu (1221 at nu = 1/6, 1321 at 0.073, Re <= 1), which a curve over several nu
  cannot have. nu below
  ``nu_min`` (default 2e-3, tau+ = 0.506) is refused: the point stops with status ``mach``
  ("needs nu < nu_min at this resolution: raise the resolution") and so do all above it;
- **force**: from the Forchheimer form fitted to the points so far (the first from a
  Carman-Kozeny k and Ergun's inertial term), so the achieved Re lands near the target; the
  achieved Re is what is reported;
- **start**: the previous point's field, its velocities scaled by the ratio of target
  velocities and its pressure deviations by the ratio of forces (the first point starts at rest);
- **steady state**: the solver's own criterion (relative change of the mean velocity and its
  geometric tail < ``tol``, force balance < 1e-4; peclet.flow.solver). Honest stops, each a
  status with its reason and no dP/L: ``oscillating`` (over the last 12 checks the mean
  velocity's change alternates in sign at least 6 times and its amplitude does not halve
  while above 10 tol: an unsteady flow or an unstable run), ``budget`` (``max_steps``
  reached), ``diverged`` (non-finite populations), ``mach`` (max|u| above the bound after the
  run, or the bound unreachable with nu >= nu_min). Only ``steady`` points enter the fit.

**Resolution limit** (measured; the wall rule is not the limit). The runs are steady up to a
cell Reynolds number max|u| / nu of ~10-35 and diverge above it: at D/8 a grown 40-sphere cell
was steady to Re 4.9 and diverged at Re 8; 90 spheres in column:4 were steady to Re 8.5 at D/8
and 17.7 at D/12 and diverged at Re 30 at both. Since max|u| / U is ~11-14 in these beds
(set by the bed, not the lattice) and Re = U N / nu, the cell Reynolds number is ~(11-14) Re /
N whatever the Mach number: Re 100 needs ~1100-1400 / N, beyond the stable range below D/40.
What was measured, one change at a time (scratch stepping at fixed Re, nu and force, from
rest), on the column at D/8, Re 30, nu = 2.66e-3 (tau+ 0.508):

- the wall rule: halfway bounce-back on every cut link (``scheme="bounce_back"``), plain
  Bouzidi and the corrected linear rule all diverged (at D/12, Re 30 bounce-back ran 2000
  steps, not converged, where the corrected rule diverged by step 600); on the column the
  growth starts at the wrapped window's seam near the column wall (a slot between spheres cut
  flat by the window, a jet of max|u| ~ 0.1), a smooth local runaway (|u| +0.4 % per step, a
  transverse component appearing), not a period-2 or checkerboard mode; at D/12, Re 30 the
  corrected rule diverged from a seam node with 8 cut links. On the grown cell (no seam) the
  growth started at sliver nodes (10-11 cut links, measured before): giving every node with >=
  7 (or >= 9) cut links halfway bounce-back ran Re 8 at D/8 for 6000 steps without diverging
  (not converged), but moved the creeping f by -7 % (1472 to 1370 with 9: at D/8 a quarter of
  that bed's fluid nodes have >= 9 cut links), and at D/12 on the column (22 % of nodes with >=
  7) it still diverged at Re 100. Capping the parabolic correction's coefficient at 1 gave a
  'steady' Re 8 with max|u| = 0.68 c_s at one node (not a fix), at 1.5 it diverged; switching
  only the links whose opposite is also cut to bounce-back did not help;
- the magic product (bounce-back walls, D/8, Re 30): 1/2 diverged by step 500, 1/4 at step 941,
  3/16 by 1500, 1/12 by 3500; 0.01 ran its 1500 steps. At D/12, Re 100 (nu = 1.42e-3) bounce-
  back diverged by step 500 with 1/4, by 1000 with 1/12 and by 2000 with 0.01. With the
  interpolated rules small products diverge sooner (1/12: by step 500 at D/8, Re 30): the
  correction's coefficients grow as 1 / (2 Lambda + tau+ - 1/2);
- the collision's symmetric ghost moments: projecting the symmetric non-equilibrium onto its
  second-order Hermite part (the stress; a regularised TRT) left the creeping f unchanged to 5
  digits and did not delay the divergence;
- the Mach number: halving it (nu halved at the same Re) did not save the corrected rule.

So the scheme's stable cell Reynolds number, not its wall rule, bounds the curve: Re 100
needs a finer lattice (about D/40 on these beds) or a collision operator with a wider stable
range (regularised in its third moments, cumulant or entropic), which this solver does not
have. The curve reports ``diverged`` with the predicted cell Reynolds number and stops.

**Forchheimer fit** (:func:`forchheimer_fit`): dP/L = (mu / k) U + beta rho U^2, in the
dimensionless form ``Pi = (dP/L) D^3 / (rho nu^2) = Re / k + beta Re^2`` (k in D^2, beta in
1/D), by weighted least squares with weights 1 / Pi^2 (relative residuals: each point's error is
a fraction of its value); standard errors from the weighted residual variance (n - 2 degrees
of freedom; NaN with 2 points). dP/L in the rows is dimensionless the same way, and
``f = Pi / Re = (dP/L) D^2 / (mu U)`` (D^2 over the apparent permeability) is the friction
factor the figure plots.

**References** (peclet.flow.correlations): Ergun (150, 1.75) with the Sauter diameter, and for
spheres Eisfeld & Schnitzlein (2001) with d_p the volume-equivalent diameter and, in a column,
its wall terms (a box or periodic pack: their unconfined limit, D_t -> inf).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from peclet.core.validation import PecletArgumentError, check_float, check_int

from .correlations import ergun, eisfeld_schnitzlein
from .setup import drive, prepare, superficial
from .solver import solve

__all__ = ["CurvePoint", "Curve", "pressure_drop_curve", "forchheimer_fit", "parse_reynolds",
           "MACH_DEFAULT", "NU_MIN_DEFAULT", "oscillation_stop"]

CS = 1.0 / math.sqrt(3.0)
#: Default bound on max |u| / c_s.
MACH_DEFAULT = 0.3
#: Default lowest viscosity (lattice units): tau+ = 0.506.
NU_MIN_DEFAULT = 2e-3
NU_MAX = 1.0 / 6.0
#: The TRT magic product of the curve's runs (module docstring).
MAGIC_CURVE = 0.25
#: The wall rule of the curve's runs (module docstring).
SCHEME_CURVE = "linear"


@dataclass
class CurvePoint:
    """One Reynolds number: Re_target, Re (achieved, NaN unless steady), Re_mod = Re / (1 -
    eps), U_lattice, dpdl (Pi, dimensionless: module docstring; NaN unless steady), f = Pi / Re,
    iterations (solver steps), status ("steady", "oscillating", "budget", "diverged",
    "mach", "not run"), reason (words), mach (max|u| / c_s of the run), cell_re (max|u| / nu,
    the cell Reynolds number: of the run, or predicted for a run that diverged), nu, tau,
    force (lattice), ergun (Pi of Ergun at this Re, Sauter d), es (Pi of Eisfeld &
    Schnitzlein, spheres only, else NaN)."""
    Re_target: float
    Re: float = math.nan
    Re_mod: float = math.nan
    U_lattice: float = math.nan
    dpdl: float = math.nan
    f: float = math.nan
    iterations: int = 0
    status: str = "not run"
    reason: str = ""
    mach: float = math.nan
    cell_re: float = math.nan
    nu: float = math.nan
    tau: float = math.nan
    force: float = math.nan
    ergun: float = math.nan
    es: float = math.nan


@dataclass
class Curve:
    """The rows, the fit (:func:`forchheimer_fit`, None with fewer than 2 steady points), and
    the bed: eps, d_sauter, d_volume (D), D_t (D, inf without a column), spheres (bool),
    resolution (cells per D), info (the domain's parameters and dP/L source)."""
    points: list
    fit: dict
    eps: float
    d_sauter: float
    d_volume: float
    D_t: float
    spheres: bool
    resolution: float
    mach_bound: float
    nu_min: float
    info: dict = field(default_factory=dict)

    def summary(self):
        """JSON-ready dict."""
        from dataclasses import asdict
        return {"points": [asdict(p) for p in self.points], "fit": self.fit, "eps": self.eps,
                "d_sauter": self.d_sauter, "d_volume": self.d_volume, "D_t": self.D_t,
                "spheres": self.spheres, "resolution": self.resolution,
                "mach_bound": self.mach_bound, "nu_min": self.nu_min,
                "reynolds": "Re = rho U D / mu (D the element diameter); Re_mod = Re / (1 - eps)",
                "dpdl_units": "Pi = (dP/L) D^3 / (rho nu^2); f = Pi / Re = (dP/L) D^2 / (mu U)",
                **{k: v for k, v in self.info.items() if not isinstance(v, np.ndarray)}}


def parse_reynolds(text, name="reynolds"):
    """``lo:hi:n`` (n log-spaced values from lo to hi) or a comma list -> sorted tuple; each in
    (0, 1000], n in [1, 50]."""
    t = str(text).strip()
    try:
        if ":" in t:
            lo, hi, n = t.split(":")
            lo, hi, n = float(lo), float(hi), int(n)
            if not (0.0 < lo <= hi <= 1000.0 and 1 <= n <= 50):
                raise ValueError
            vals = np.geomspace(lo, hi, n) if n > 1 else np.array([lo])
        else:
            vals = np.array([float(v) for v in t.split(",") if v.strip()])
            if len(vals) == 0 or len(vals) > 50:
                raise ValueError
    except ValueError:
        raise PecletArgumentError(name, "lo:hi:n (n log-spaced Reynolds numbers, 0 < lo <= hi "
                                  "<= 1000, n in [1, 50]) or a comma list", text) from None
    if not np.all(np.isfinite(vals) & (vals > 0.0) & (vals <= 1000.0)):
        raise PecletArgumentError(name, "Reynolds numbers in (0, 1000]", text)
    return tuple(sorted(set(float(v) for v in vals)))


def forchheimer_fit(Re, Pi):
    """Weighted least squares of Pi = Re / k + beta Re^2 (module docstring) over the points
    (Re, Pi) (> 0). Returns {"k_D2", "k_se", "beta_D", "beta_se" (beta in 1/D), "A", "B" (Pi
    = A Re + B Re^2), "points", "rms_rel" (rms relative residual), "Re_F" (A / B, where the
    inertial term equals the viscous one)}, or None with fewer than 2 points."""
    Re = np.asarray(Re, np.float64)
    Pi = np.asarray(Pi, np.float64)
    if len(Re) < 2:
        return None
    X = np.column_stack([Re, Re * Re]) / Pi[:, None]      # rows scaled by 1 / Pi
    y = np.ones_like(Re)
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    res = y - X @ coef
    n = len(Re)
    A, B = float(coef[0]), float(coef[1])
    cov = (np.linalg.inv(X.T @ X) * float(res @ res) / (n - 2)) if n > 2 \
        else np.full((2, 2), math.nan)
    se_A, se_B = math.sqrt(max(cov[0, 0], 0.0)), math.sqrt(max(cov[1, 1], 0.0))
    return {"k_D2": 1.0 / A, "k_se": se_A / A ** 2, "beta_D": B, "beta_se": se_B, "A": A,
            "B": B, "points": n, "rms_rel": float(math.sqrt(res @ res / n)),
            "Re_F": A / B if B > 0 else math.inf}


def oscillation_stop(tol, checks=12):
    """The ``stop`` callable of :func:`~peclet.flow.solver.solve` that ends a run whose mean
    velocity oscillates without settling (module docstring)."""
    def stop(hist):
        if len(hist) < checks + 1:
            return ""
        U = np.array([h[1] for h in hist[-(checks + 1):]])
        dU = np.diff(U) / max(abs(U[-1]), 1e-300)
        flips = int(np.count_nonzero(np.sign(dU[1:]) != np.sign(dU[:-1])))
        half = checks // 2
        late, early = np.abs(dU[half:]).max(), np.abs(dU[:half]).max()
        if flips >= half and late > 0.5 * early and late > 10.0 * tol:
            return (f"oscillating residual: the mean velocity's change flipped sign {flips} "
                    f"times in the last {checks} checks, amplitude {late:.2e} (relative) not "
                    "decaying")
        return ""
    return stop


def _references(Re, st, d_v, D_t, spheres):
    """(Ergun Pi with the Sauter diameter, Eisfeld & Schnitzlein Pi or NaN) at Re."""
    e = st.eps
    er = float(ergun(Re, e, st.d_s, 1.0)[0])
    es = float(eisfeld_schnitzlein(Re, e, d_v, D_t, 1.0)[0]) if spheres else math.nan
    return er, es


def pressure_drop_curve(pack, reynolds, resolution=8, axis="y", window=None, y_mode="wrap",
                        container=None, mach=MACH_DEFAULT, nu_min=NU_MIN_DEFAULT, tol=1e-6,
                        max_steps=200_000, seam_margin=1.0, progress=None, magic=MAGIC_CURVE,
                        scheme=SCHEME_CURVE):
    """dP/L against Re for ``pack`` (a Pack or any pack file; the domain as
    :func:`peclet.flow.permeability.permeability`): one steady solve per Reynolds number of
    ``reynolds`` (an iterable, or a text for :func:`parse_reynolds`), in increasing order, at
    ``resolution`` cells per D. mach: the bound on max|u| / c_s, in (0, 0.3]; nu_min: the
    lowest viscosity, in [1e-4, 1/6]; tol, max_steps: per point (the solver's). Returns a
    :class:`Curve` (module docstring)."""
    if isinstance(reynolds, str):
        reynolds = parse_reynolds(reynolds)
    Res = sorted(check_float("reynolds", r, 0.0, 1000.0, lo_open=True) for r in reynolds)
    if not Res:
        raise PecletArgumentError("reynolds", "at least one Reynolds number", reynolds)
    mach = check_float("mach", mach, 0.0, 0.3, lo_open=True)
    nu_min = check_float("nu_min", nu_min, 1e-4, NU_MAX)
    max_steps = check_int("max_steps", max_steps, 100)
    st = prepare(pack, resolution, axis, window, y_mode, container)
    res, e = st.res, st.eps
    if not e < 1.0:
        raise PecletArgumentError("pack", "a bed with solid in the domain", f"eps = {e}")
    pk = st.pack
    d_v = (6.0 * float(pk.ring_volume) / math.pi) ** (1.0 / 3.0)
    D_t = 2.0 * float(st.column.radius) if st.column is not None else math.inf
    spheres = abs(st.d_s - d_v) < 0.02 * d_v          # Sauter = volume diameter: a sphere
    # the force model Pi = A Re + B Re^2 (D units): Carman-Kozeny and Ergun's inertial term
    A = 180.0 * (1.0 - e) ** 2 / (e ** 3 * st.d_s ** 2)
    B = 1.75 * (1.0 - e) / (e ** 3 * st.d_s)
    ratio = 10.0
    prev = None
    points = []
    stopped = ""
    for Re_t in Res:
        p = CurvePoint(Re_target=Re_t)
        points.append(p)
        if stopped:
            p.reason = stopped
            continue
        U_cap = 0.75 * mach * CS / ratio
        nu = min(NU_MAX, U_cap * res / Re_t)
        if nu < nu_min:
            p.status = "mach"
            p.reason = stopped = (f"Re {Re_t:g} needs nu = {nu:.2e} < nu_min = {nu_min:g} to "
                                  f"keep max|u| < {mach:g} c_s at D/{res:g} (max|u| / U = "
                                  f"{ratio:.3g}): raise the resolution")
            continue
        U_t = Re_t * nu / res
        g = (A * Re_t + B * Re_t * Re_t) * nu * nu / res ** 3
        F = np.zeros(3)
        F[st.ax] = g
        init = None
        if prev is not None:
            rho0, u0, U0, g0 = prev
            init = (1.0 + (rho0 - 1.0) * (g / g0), u0 * (U_t / U0))
        p.nu, p.tau, p.force = nu, 3.0 * nu + 0.5, g
        try:
            fr = solve(st.geo, F, nu=nu, magic=magic, scheme=scheme, tol=tol,
                       max_steps=max_steps,
                       progress=progress, init=init, stop=oscillation_stop(tol))
        except FloatingPointError as exc:
            p.cell_re = ratio * U_t / nu
            p.status = "diverged"
            p.reason = (f"{exc}: under-resolved (predicted cell Reynolds number max|u| / nu = "
                        f"{p.cell_re:.3g}; raise the resolution)")
            stopped = f"the run at Re {Re_t:g} diverged"
            continue
        p.iterations = fr.steps
        U = superficial(st, fr)
        umax = float(np.sqrt((fr.u * fr.u).sum(axis=1)).max())
        p.mach = umax / CS
        p.cell_re = umax / nu
        p.U_lattice = U
        if U > 0.0:
            ratio = umax / U
        if fr.stopped:
            p.status, p.reason = "oscillating", fr.stopped
        elif not fr.converged:
            p.status = "budget"
            p.reason = (f"not converged in {max_steps} steps (last relative change "
                        f"{fr.residual:.2e}, force balance {fr.balance:.6f})")
        elif p.mach > mach:
            p.status = "mach"
            p.reason = f"max|u| = {p.mach:.3f} c_s exceeds the bound {mach:g} c_s"
        elif not U > 0.0:
            p.status, p.reason = "diverged", f"no flow along {axis}: U = {U}"
        else:
            dpdl, up = drive(st, fr, g, U, nu, seam_margin)
            st.info.update(up)
            p.status = "steady"
            p.Re = U * res / nu
            p.Re_mod = p.Re / (1.0 - e)
            p.dpdl = dpdl * res ** 3 / (nu * nu)
            p.f = p.dpdl / p.Re
            p.ergun, p.es = _references(p.Re, st, d_v, D_t, spheres)
            prev = (fr.rho, fr.u, U, g)
            ok = [q for q in points if q.status == "steady"]
            fit = forchheimer_fit([q.Re for q in ok], [q.dpdl for q in ok])
            if fit is not None and fit["A"] > 0 and fit["B"] > 0:
                A, B = fit["A"], fit["B"]
            else:
                A = p.f - B * p.Re          # keep the inertial guess, match this point
        if p.status in ("oscillating", "budget"):
            stopped = f"the flow stopped being steady at Re {Re_t:g} ({p.status})"
    ok = [q for q in points if q.status == "steady"]
    fit = forchheimer_fit([q.Re for q in ok], [q.dpdl for q in ok])
    info = dict(st.info)
    info.update({"axis": axis, "magic": magic, "scheme": scheme, "tol": tol, "max_steps": max_steps,
                 "fluid_nodes": st.geo.n_fluid, "thinnest_wall_D": st.t_wall})
    return Curve(points=points, fit=fit, eps=e, d_sauter=st.d_s, d_volume=d_v, D_t=D_t,
                 spheres=spheres, resolution=res, mach_bound=mach, nu_min=nu_min, info=info)
