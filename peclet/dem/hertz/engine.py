"""The explicit force-based engine and the Hertz–Mindlin law it was built for.

:class:`ExplicitEngine` is the contact engine (:class:`peclet.dem.engine.ContactEngine`) of
every force law: a Verlet list of candidates within a skin, the exact contacts of spheres,
patches and distributed contacts at every substep (:mod:`.substep`), the law's forces, an
optional rolling resistance, kick-drift, guards and :meth:`World.commit`. Its per-contact state
is a :class:`~peclet.dem.hertz.state.HertzState` (the tangential history keyed by contact),
one per law in ``world.histories`` (the Hertz law's is ``world.hertz``).

:class:`HertzLaw` is the Hertz–Mindlin law of the package notes (:mod:`peclet.dem.hertz`).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from peclet.core.validation import PecletArgumentError, check_float, check_int

from .calibration import (E_MIN, RAYLEIGH_FRACTION, damping_gamma, damping_gamma_linear,
                          rayleigh_time)
from .candidates import pair_basics
from .law import PairLaw, contact_forces
from .rolling import RollLaw
from .state import HertzState
from .substep import DEFAULT_SKIN_FRACTION, substep

#: Bounds on the substeps one call can ask for.
MAX_SUBSTEPS = 10 ** 6


class HertzParams(NamedTuple):
    """The Hertz law's parameters per candidate: E*, G*, R* (a patch's own from both
    curvatures once the patches are in), m*, gamma, mu, and ``rroll`` the rolling lever (R*,
    but a distributed contact's bounding R*)."""
    estar: np.ndarray
    gstar: np.ndarray
    rstar: np.ndarray
    mstar: np.ndarray
    gam: np.ndarray
    mu: np.ndarray
    rroll: np.ndarray


class HertzLaw:
    """The Hertz–Mindlin force law (:mod:`peclet.dem.hertz`), a :class:`peclet.dem.engine.
    ForceLaw`: moduli per material id from ``world.hertz``, damping from each pair's e_n."""

    name = "hertz"
    rolling = True

    def check(self, world, dt):
        """Refuse what the law cannot run: undeclared moduli, a dt above
        ``RAYLEIGH_FRACTION`` of the smallest Rayleigh time (a composed body: its bounding
        radius, its mass spread over the bounding sphere), restitution below ``E_MIN``. A
        composed particle's unsupported contacts are refused when they touch
        (:class:`HertzPatchError`)."""
        state = world.hertz
        b = world.bodies
        mats = world.materials
        ids = mats.body_ids if mats.body_ids is not None else np.zeros(b.n, np.int64)
        state.wall_moduli(mats.wall_ids)
        if not b.n:
            return
        e, nu = state.body_moduli(ids)
        m = b.inv_mass > 0
        if np.any(m):
            r = world.radii()[m]
            rho = (1.0 / b.inv_mass[m]) / (4.0 / 3.0 * math.pi * r ** 3)
            tr = float(np.min(rayleigh_time(r, rho, e[m], nu[m])))
            if dt > RAYLEIGH_FRACTION * tr:
                raise PecletArgumentError("dt", f"<= {RAYLEIGH_FRACTION} x the smallest "
                                          "Rayleigh time pi R sqrt(rho/G)/(0.1631 nu + "
                                          f"0.8766) = {RAYLEIGH_FRACTION * tr:.6g}", dt)
        walls_e = world.geometry().wall_e
        lows = [float(v) for v in np.concatenate([[world.default_material.e_n], walls_e])
                if v < E_MIN]
        lows += [mt.e_n for mt in mats.pairs.values() if mt.e_n < E_MIN]
        if lows:
            raise PecletArgumentError("e_n", f"in [{E_MIN}, 1] for the Hertz engine (its "
                                      "damping cannot stop a contact dead)", min(lows))

    def pair_parameters(self, world, c, inv_mass):
        """:class:`HertzParams` per candidate (E* and G* from the bodies' and walls' moduli;
        a wall without a material id is rigid)."""
        state = world.hertz
        mats = world.materials
        ids = mats.body_ids if mats.body_ids is not None else np.zeros(world.bodies.n,
                                                                        np.int64)
        eb, nub = state.body_moduli(ids)
        ce_body = (1.0 - nub * nub) / eb
        cg_body = (2.0 - nub) * 2.0 * (1.0 + nub) / eb
        ce_wall, cg_wall = state.wall_moduli(mats.wall_ids)
        isw = c.b < 0
        bi = np.where(isw, 0, c.b)
        wi = np.where(isw, -1 - c.b, 0)
        ce = ce_body[c.a] + (np.where(isw, ce_wall[wi] if len(ce_wall) else 0.0, ce_body[bi]))
        cg = cg_body[c.a] + (np.where(isw, cg_wall[wi] if len(cg_wall) else 0.0, cg_body[bi]))
        rstar, mstar, e_c, mu = pair_basics(world, c, inv_mass)
        ue, inv = np.unique(e_c, return_inverse=True)
        gam = np.array([damping_gamma(float(e)) for e in ue])[inv.reshape(-1)] \
            if len(ue) else np.zeros(0)
        return HertzParams(1.0 / ce, 1.0 / cg, rstar, mstar, gam, mu, rstar)

    def modulus(self, params):
        return params.estar

    def with_patches(self, params, rows, rstar):
        r = params.rstar.copy()
        r[rows] = rstar
        return params._replace(rstar=r, rroll=r)

    def with_distributed(self, params, base, rows, dist):
        """The overlap law through the Hertz kernel: a delta_h and R*_h with the same force F
        and stiffness S (F = 4/3 E* sqrt(R*_h) delta_h^1.5, S = 2 E* sqrt(R*_h delta_h)); the
        damping of the linear law's gamma for the pair's e_n; the rolling lever the bounding
        spheres' R* (R*_h is no radius). Returns (parameters, kernel gap of ``rows``)."""
        touch, force, stiff = dist.touch, dist.force, dist.stiffness
        dh = np.where(touch, 1.5 * force / np.where(touch, stiff, 1.0), 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            rh = np.where(touch, (0.75 * force / (dist.modulus * np.where(touch, dh, 1.0)
                                                  ** 1.5)) ** 2, 0.0)
        gam_d = np.array([damping_gamma_linear(float(v)) for v in dist.e_n])
        rroll = params.rstar.copy()
        rroll[rows] = base.rstar[rows]
        rstar = params.rstar.copy()
        rstar[rows] = rh
        gam = params.gam.copy()
        gam[rows] = gam_d
        return (params._replace(rstar=rstar, gam=gam, rroll=rroll),
                np.where(touch, -dh, np.inf))

    def forces(self, rows, params, motion, dt, out):
        p = params
        contact_forces(rows, PairLaw(p.estar, p.gstar, p.rstar, p.mstar, p.gam, p.mu), motion,
                       dt, out)

    def rolling_law(self, params, mu_r, fn):
        """The rolling resistance's per-contact law (:mod:`.rolling`)."""
        return RollLaw(params.estar, params.rstar, np.ascontiguousarray(params.rroll), mu_r,
                       fn)


class ExplicitEngine:
    """The explicit engine under force ``law``: ``substeps`` (an integer in [1, 10**6]) of
    the step's dt each call of :meth:`step`, candidates within ``skin_frac`` (in (0, 10]) of
    the smallest radius. Persistence saves its history (:meth:`history`)."""

    def __init__(self, law, substeps=1, skin_frac=None):
        self.law = law
        self.name = law.name
        self.substeps = check_int("substeps", substeps, 1, MAX_SUBSTEPS)
        self.skin = DEFAULT_SKIN_FRACTION if skin_frac is None else check_float(
            "skin_frac", skin_frac, 0.0, 10.0, lo_open=True)
        self.parameters = dict(getattr(law, "parameters", {}), substeps=float(self.substeps),
                               skin_frac=self.skin)

    def state(self, world):
        """The law's contact history in ``world`` (created empty at first use)."""
        return world.histories.setdefault(self.name, HertzState())

    def step(self, world, dt):
        """``substeps`` substeps of ``dt`` (checked by the caller); the law's checks first."""
        world.check_ready()
        self.law.check(world, dt)
        state = self.state(world)
        state.cand = None          # materials, walls or bodies may have changed since
        for _ in range(self.substeps):
            if world.bodies.n == 0:
                world.tick(dt)
                continue
            substep(world, state, self.law, dt, self.skin)

    def history(self, world):
        """The contact history persistence saves: keys (K,) int64, xi (K, 3) and n (1,) the
        body count it belongs to. Empty for the Hertz law, whose history ``world.hertz``
        persistence saves under its own keys (with the moduli and rolling settings)."""
        s = self.state(world)
        if s is world.hertz:
            return {}
        return {"keys": s.keys.copy(), "xi": s.xi.copy(), "n": np.array([s.n_bodies])}

    def restore(self, world, arrays):
        """The inverse of :meth:`history` (PecletArgumentError naming the array that is not
        what :meth:`history` writes)."""
        s = self.state(world)
        if s is world.hertz and not arrays:
            return
        expect = {"keys": ("i", 1), "xi": ("f", 2), "n": ("i", 1)}
        if set(arrays) != set(expect):
            raise PecletArgumentError("history", f"the arrays {sorted(expect)}", sorted(arrays))
        for k, (kind, ndim) in expect.items():
            if arrays[k].dtype.kind != kind or arrays[k].ndim != ndim:
                raise PecletArgumentError(k, f"a {ndim}-d array of kind {kind!r}",
                                          arrays[k].dtype)
        keys, xi = arrays["keys"].astype(np.int64), arrays["xi"].astype(np.float64)
        if xi.shape != (len(keys), 3) or arrays["n"].shape != (1,) \
                or np.any(np.diff(keys) <= 0):
            raise PecletArgumentError("xi", "(K, 3) rows for K sorted unique keys", xi.shape)
        s.keys, s.xi, s.mr = keys, xi, np.zeros((len(keys), 3))
        s.n_bodies = int(arrays["n"][0])


def make(substeps=1, skin_frac=None):
    """The Hertz–Mindlin engine (registry row ``"hertz"`` of :data:`peclet.dem.engine.LAWS`):
    moduli from :meth:`Simulation.set_hertz_material`, ``substeps`` per :meth:`advance` step."""
    return ExplicitEngine(HertzLaw(), substeps, skin_frac)
