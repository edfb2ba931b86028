"""The linear spring-dashpot law with tangential history (Cundall & Strack 1979).

The default law of most DEM codes (LAMMPS ``gran/hooke/history``, Yade's Cundall–Strack
law), run by the explicit engine (:class:`peclet.dem.hertz.engine.ExplicitEngine`: candidates,
exact contacts of spheres and composed particles, kick-drift) and chosen with
``Simulation.set_contact_law("linear", kn=..., kt=..., substeps=..., skin_frac=...)``.

Per contact of overlap ``delta = -gap > 0`` (lengths, forces and times in the caller's
consistent units)::

    F_n = k_n delta - c_n v_n,    c_n = 2 zeta sqrt(k_n m*),
    zeta = -ln e / sqrt(pi^2 + ln^2 e)   (zeta = 1 at e = 0),
    xi <- (xi turned into the current tangent plane) + v_t dt,   F_t = -k_t xi,
    |F_t| <= mu max(F_n, 0)  (else F_t onto the cone and xi = -F_t / k_t)

with ``v_n`` the normal relative velocity (positive when separating), ``1/m* = 1/m_a + 1/m_b``
(a wall or a fixed body adds nothing), ``e`` and ``mu`` the pair material's restitution and
friction (``Simulation.set_pair_material`` / ``set_material_params`` / the wall's own).
``F_n`` is not clamped at zero: the dashpot pulls slightly at the end of a contact, as in
LAMMPS's default, and that is what makes the coefficient of restitution exactly ``e`` at any
impact speed: the overlap obeys ``m* delta'' + c_n delta' + k_n delta = 0``, returns to zero
after ``t_c = pi / (omega_0 sqrt(1 - zeta^2))``, ``omega_0 = sqrt(k_n / m*)``, at
``exp(-zeta pi / sqrt(1 - zeta^2)) = e`` times the impact speed; the largest overlap is
``v_0 / omega_0 exp(-zeta / sqrt(1 - zeta^2) atan(sqrt(1 - zeta^2) / zeta))`` (``v_0 /
omega_0`` when e = 1). No tangential dashpot (Cundall–Strack; a sliding contact dissipates
through Coulomb friction). Rolling resistance does not apply (the Hertz law's).

A composed particle's contacts are those of the engine: one per touching patch and one per
distributed (flat, line, edge) contact, each a spring of its own along its normal at its
deepest overlap (the stiffness is per contact, as in multi-sphere DEM codes).

Step size: ``dt`` must not exceed ``DT_FRACTION`` of the shortest contact time of two of the
lightest bodies, ``pi sqrt(m_min / (2 k_n))`` (checked before a run).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from peclet.core.validation import PecletArgumentError, check_float
from peclet.dem.hertz.candidates import pair_basics
from peclet.dem.hertz.engine import ExplicitEngine

from .kernel import LinearRows, linear_forces

#: Largest dt as a fraction of the shortest undamped contact time of two of the lightest
#: bodies: about 30 steps a contact, where kick-drift is stable and e is right to ~1%.
DT_FRACTION = 1.0 / 30.0
#: The tangential stiffness by default, as a fraction of k_n: 2/7 makes the tangential
#: oscillation of a contacting sphere as fast as the normal one (rotation included).
KT_RATIO = 2.0 / 7.0
#: Bounds on the stiffnesses (force/length).
K_MAX = 1e30


def damping_ratio(e):
    """zeta in [0, 1] of the restitution ``e`` in [0, 1]: ``-ln e / sqrt(pi^2 + ln^2 e)``
    (1 at e = 0: critical damping, the bodies never separate)."""
    e = check_float("e", e, 0.0, 1.0)
    if e == 0.0:
        return 1.0
    le = math.log(e)
    return -le / math.sqrt(math.pi * math.pi + le * le)


def contact_time(kn, mstar, e=1.0):
    """The contact time ``pi / (sqrt(kn / mstar) sqrt(1 - zeta^2))`` of a linear contact of
    stiffness ``kn`` and effective mass ``mstar`` at restitution ``e`` (inf at e = 0)."""
    z = damping_ratio(e)
    if z >= 1.0:
        return math.inf
    return math.pi / (math.sqrt(kn / mstar) * math.sqrt(1.0 - z * z))


def max_overlap(v0, kn, mstar, e=1.0):
    """The largest overlap of a normal impact at speed ``v0`` (module notes)."""
    w0 = math.sqrt(kn / mstar)
    z = damping_ratio(e)
    if z == 0.0:
        return v0 / w0
    if z >= 1.0:
        return v0 / w0 * math.exp(-1.0)     # the critical limit: t* = 1 / w0
    s = math.sqrt(1.0 - z * z)
    return v0 / w0 * math.exp(-z / s * math.atan(s / z))


class LinearParams(NamedTuple):
    """Per candidate: k_n, k_t, c_n, mu (:class:`~peclet.dem.linear.kernel.LinearRows`)."""
    kn: np.ndarray
    kt: np.ndarray
    cn: np.ndarray
    mu: np.ndarray


class LinearLaw:
    """The linear spring-dashpot law of the module notes, a :class:`peclet.dem.engine.
    ForceLaw`: normal stiffness ``kn`` (> 0, force/length), tangential ``kt`` (>= 0, default
    ``KT_RATIO`` kn)."""

    name = "linear"
    rolling = False

    def __init__(self, kn, kt=None):
        self.kn = check_float("kn", kn, 0.0, K_MAX, lo_open=True)
        self.kt = KT_RATIO * self.kn if kt is None else check_float("kt", kt, 0.0, K_MAX)
        self.parameters = {"kn": self.kn, "kt": self.kt}

    def check(self, world, dt):
        b = world.bodies
        m = b.inv_mass > 0
        if np.any(m):
            tc = math.pi * math.sqrt(float(np.min(1.0 / b.inv_mass[m])) / (2.0 * self.kn))
            if dt > DT_FRACTION * tc:
                raise PecletArgumentError("dt", f"<= {DT_FRACTION:.4g} x the shortest contact "
                                          f"time pi sqrt(m_min / (2 kn)) = "
                                          f"{DT_FRACTION * tc:.6g}", dt)

    def pair_parameters(self, world, c, inv_mass):
        _, mstar, e_c, mu = pair_basics(world, c, inv_mass)
        ue, inv = np.unique(e_c, return_inverse=True)
        zeta = np.array([damping_ratio(float(e)) for e in ue])[inv.reshape(-1)] \
            if len(ue) else np.zeros(0)
        n = len(c.a)
        return LinearParams(np.full(n, self.kn), np.full(n, self.kt),
                            2.0 * zeta * np.sqrt(self.kn * mstar), mu)

    def modulus(self, params):
        return np.ones(len(params.kn))     # the distributed region's shape needs no modulus

    def with_patches(self, params, rows, rstar):
        return params

    def with_distributed(self, params, base, rows, dist):
        return params, np.where(dist.touch, -dist.depth, np.inf)

    def forces(self, rows, params, motion, dt, out):
        linear_forces(rows, LinearRows(*params), motion, dt, out)


def make(kn, kt=None, substeps=1, skin_frac=None):
    """The linear law's engine (registry row ``"linear"`` of :data:`peclet.dem.engine.LAWS`):
    stiffnesses ``kn``, ``kt`` (force/length), ``substeps`` per step of
    :meth:`Simulation.advance`, candidate skin ``skin_frac`` (see
    :meth:`Simulation.step_hertz`)."""
    return ExplicitEngine(LinearLaw(kn, kt), substeps, skin_frac)
