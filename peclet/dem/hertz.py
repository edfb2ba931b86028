"""Hertz–Mindlin soft contacts: the force law, its restitution calibration and the explicit step.

An alternative to the impulse step of docs/architecture.md §6 for engineers who calibrate bulk
flow with real elastic moduli. Candidate contacts are found by the same detection (broad and
narrow phase, :mod:`peclet.dem.contacts`) within a skin and kept as a Verlet list while no
pair can have closed the skin (:func:`_candidates`); at every substep each candidate's
contact is recomputed exactly (:func:`contact_geometry`), every touching one (gap < 0, overlap
``delta = -gap``) exerts a force, and the bodies are advanced by an explicit integrator.

Normal force (Hertz)::

    F_n = 4/3 E* sqrt(R*) delta^(3/2) + F_d,   F_d = gamma sqrt(S_n m*) (-v_n),
    S_n = 2 E* sqrt(R* delta),                 total clamped at F_n >= 0 (no attraction)

with ``1/E* = (1 - nu_a^2)/E_a + (1 - nu_b^2)/E_b``, ``1/R* = 1/R_a + 1/R_b`` (a wall counts
as flat, R* = R of the sphere, also where it is curved) and ``1/m* = 1/m_a + 1/m_b`` (a wall or
a body of inverse mass 0 adds nothing). ``v_n`` is the normal relative velocity, positive when
separating.

Tangential force (Mindlin, no-slip)::

    S_t = 8 G* sqrt(R* delta),   1/G* = (2 - nu_a)/G_a + (2 - nu_b)/G_b,   G = E / (2 (1 + nu))
    xi <- (xi rotated into the current tangent plane) + v_t dt
    F_t = -S_t xi - gamma sqrt(S_t m*) v_t,   |F_t| <= mu F_n (else scaled onto the cone and
    xi reset to -F_t / S_t, so that the spring holds the sliding force)

``xi`` is the tangential displacement history of the contact, kept per contact key (the body
pair and the feature, :meth:`peclet.dem.contacts.WarmStart.keys_of`; a wall is body -1 - w)
while the bodies overlap, and dropped when they separate. It is stored in the world frame and
rotated into each new tangent plane keeping its length.

Damping law and why: the Tsuji et al. (1992) form (a dashpot proportional to
``sqrt(m* S_n)``, i.e. ``delta^(1/4)``), because with it the coefficient of restitution does
not depend on the impact speed. The dimensionless coefficient ``gamma`` is not taken from the
linear-spring formula used by EDEM/LIGGGHTS (``gamma = -2 sqrt(5/6) ln e / sqrt(ln^2 e +
pi^2)``), which for the Hertz law with the no-attraction clamp rebounds too fast (0.55 for
e = 0.5, 0.40 for e = 0.3, 0.25 for e = 0.1: :func:`edem_gamma`, :func:`restitution_of`): it is
computed by
:func:`damping_gamma`, which solves the dimensionless impact
``x'' = -max(0, x^(3/2) + sqrt(3/2) gamma x^(1/4) x')``, ``x(0) = 0``, ``x'(0) = 1`` (a
fixed-step RK4, h = 2e-5 against a contact of ~3.2; the rebound speed is good to ~1e-7,
measured against h / 4), independent of the engine, and finds the gamma whose rebound speed
is ``e`` (Brent's method). The same gamma damps the tangential spring (as EDEM does).
Restitution ``e_n`` and friction ``mu`` come from the contact's pair material (the impulse
engine's :class:`~peclet.dem.materials.MaterialTable`, or the wall's own values); the Walton
``e_t`` is not used by this engine. Rolling resistance: none (not implemented).

Moduli: :meth:`HertzState.set_material` per material id (the same ids as the pair table). A
wall without a material id is rigid (``1/E_wall = 0``); a wall with an id takes that id's
moduli.

Lever arms: the contact point is the narrow phase's, midway between the two surfaces, so a
sphere's torque arm is R - delta/2 (R - delta against a rigid plane would be the other common
choice; rigid-body formulas with R differ from either by O(delta / R)).

Integrator: symplectic Euler in kick-drift order (the leapfrog: the stored velocities are those
of the half step), per substep: detect, forces at the current positions, ``v += dt (F/m + g +
F_ext/m)``, ``omega += dt I_w^-1 (T + T_ext)``, ``x += dt v``, then the torque-free rotation of
:func:`peclet.dem.rigid.advance_all` (unchanged). Second order in the positions for the elastic
force; the damping sees the half-step velocity.

Step-size check: the Rayleigh time of body i, ``T_R = pi R sqrt(rho / G) / (0.1631 nu +
0.8766)`` with ``rho = m / (4/3 pi R^3)``, must satisfy ``dt <= RAYLEIGH_FRACTION * min_i T_R``
(a stability guard: an accurate impact needs tens of steps per contact time, see
``validation/chung_ooi.py``).

Composed (CSG) particles: not supported by this engine. Their manifold holds up to 16 points
per pair chosen for the impulse solve, which would make a Hertz force depend on how many
points were kept; a per-probe area weighting is future work, and :func:`check` refuses them
with a clear error.

Determinism: the force kernel writes only its own contact's slots; forces and torques are
summed into bodies serially in contact order; the history is sorted by key. Bitwise identical
at any thread count.
"""
from __future__ import annotations

import math
from functools import lru_cache
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from peclet.core.geom.kernels import MAX_STACK, STACK_COLS, eval_point
from peclet.core.validation import PecletArgumentError, check_float, check_int
from peclet.dem.materials import MAX_MATERIAL_ID

#: dt may be at most this fraction of the smallest Rayleigh time of the bodies.
RAYLEIGH_FRACTION = 0.3

#: Default skin of the candidate list (step_hertz's skin_frac), a fraction of the smallest
#: radius: larger skins rebuild less often and carry more candidates.
DEFAULT_SKIN_FRACTION = 0.1

#: Restitution coefficients the damping can reproduce (below, gamma grows without bound).
E_MIN = 0.01

#: Dimensionless RK4 step of the restitution calibration (the undamped contact lasts 3.218).
_CAL_STEP = 2e-5


# --------------------------------------------------------------------------------------------
# restitution calibration
# --------------------------------------------------------------------------------------------

@njit(cache=True)
def _rhs(x, u, g):
    # overlap x, approach speed u: x' = u, u' = -max(0, x^1.5 + g x^0.25 u)
    if x <= 0.0:
        return 0.0
    f = x ** 1.5 + g * x ** 0.25 * u
    return -f if f > 0.0 else 0.0


@njit(cache=True)
def rebound_speed(g, h):
    """Rebound speed of the dimensionless damped Hertz impact (approach speed 1) with the
    coefficient ``g`` (= sqrt(3/2) gamma) in front of ``x^(1/4) x'``, by RK4 of step ``h``;
    the exit is interpolated linearly in the last step."""
    x = 0.0
    u = 1.0
    for _ in range(100_000_000):
        k1x = u
        k1u = _rhs(x, u, g)
        k2x = u + 0.5 * h * k1u
        k2u = _rhs(x + 0.5 * h * k1x, u + 0.5 * h * k1u, g)
        k3x = u + 0.5 * h * k2u
        k3u = _rhs(x + 0.5 * h * k2x, u + 0.5 * h * k2u, g)
        k4x = u + h * k3u
        k4u = _rhs(x + h * k3x, u + h * k3u, g)
        xn = x + h / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x)
        un = u + h / 6.0 * (k1u + 2.0 * k2u + 2.0 * k3u + k4u)
        if xn <= 0.0 and un < 0.0:
            return -un
        x = xn
        u = un
    return 0.0


def _restitution(gamma):
    return float(rebound_speed(math.sqrt(1.5) * gamma, _CAL_STEP))


@lru_cache(maxsize=4096)
def damping_gamma(e):
    """The dimensionless damping ``gamma`` (>= 0) with which the clamped Hertz law rebounds at
    ``e`` times the approach speed (``e`` in [E_MIN, 1]; 1 gives 0): Brent's root of the
    calibration ODE of the module docstring, to 1e-12 relative (the ODE itself is good to
    ~1e-7)."""
    e = check_float("e_n", e, E_MIN, 1.0)
    if e == 1.0:
        return 0.0
    from scipy.optimize import brentq
    hi = 1.0
    while _restitution(hi) > e:
        hi *= 2.0
    return float(brentq(lambda g: _restitution(g) - e, 0.0, hi, xtol=1e-14, rtol=1e-12))


def edem_gamma(e):
    """The linear-spring coefficient used by EDEM/LIGGGHTS, ``2 sqrt(5/6) |beta|`` with
    ``beta = ln e / sqrt(ln^2 e + pi^2)`` (for comparison; the engine uses
    :func:`damping_gamma`)."""
    if e >= 1.0:
        return 0.0
    le = math.log(e)
    return 2.0 * math.sqrt(5.0 / 6.0) * (-le) / math.sqrt(le * le + math.pi ** 2)


def restitution_of(gamma):
    """The restitution the clamped damped Hertz law gives with ``gamma`` (calibration ODE)."""
    return _restitution(float(gamma))


def rayleigh_time(radius, density, youngs, poisson):
    """Rayleigh-wave time ``pi R sqrt(rho / G) / (0.1631 nu + 0.8766)``, ``G = E / (2 (1 +
    nu))`` (s, for SI input); arrays broadcast."""
    g = youngs / (2.0 * (1.0 + poisson))
    return math.pi * radius * np.sqrt(density / g) / (0.1631 * poisson + 0.8766)


# --------------------------------------------------------------------------------------------
# kernels
# --------------------------------------------------------------------------------------------

@njit(cache=True)
def _cross(a0, a1, a2, b0, b1, b2):
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True)
def _one_contact(i, a, b, normal, gap, ra, rb, vel, omega, vwall, estar, gstar, rstar, mstar,
                 gamma, mu, xi, dt, force, fn_out):
    # contact i of contact_forces; writes only row i
    d = -gap[i]
    if d <= 0.0:
        for e in range(3):
            force[i, e] = 0.0
            xi[i, e] = 0.0
        fn_out[i] = 0.0
        return
    ia = a[i]
    nx, ny, nz = normal[i, 0], normal[i, 1], normal[i, 2]
    cx, cy, cz = _cross(omega[ia, 0], omega[ia, 1], omega[ia, 2], ra[i, 0], ra[i, 1],
                        ra[i, 2])
    vx = vel[ia, 0] + cx
    vy = vel[ia, 1] + cy
    vz = vel[ia, 2] + cz
    ib = b[i]
    if ib >= 0:
        cx, cy, cz = _cross(omega[ib, 0], omega[ib, 1], omega[ib, 2], rb[i, 0], rb[i, 1],
                            rb[i, 2])
        vx -= vel[ib, 0] + cx
        vy -= vel[ib, 1] + cy
        vz -= vel[ib, 2] + cz
    else:
        vx -= vwall[i, 0]
        vy -= vwall[i, 1]
        vz -= vwall[i, 2]
    vn = vx * nx + vy * ny + vz * nz
    tx = vx - vn * nx
    ty = vy - vn * ny
    tz = vz - vn * nz
    sq = math.sqrt(rstar[i] * d)
    sn = 2.0 * estar[i] * sq
    st = 8.0 * gstar[i] * sq
    fn = 4.0 / 3.0 * estar[i] * sq * d - gamma[i] * math.sqrt(sn * mstar[i]) * vn
    if fn < 0.0:
        fn = 0.0
    # history into the current tangent plane, length kept (the contact frame turned)
    hx, hy, hz = xi[i, 0], xi[i, 1], xi[i, 2]
    old = math.sqrt(hx * hx + hy * hy + hz * hz)
    hn = hx * nx + hy * ny + hz * nz
    hx -= hn * nx
    hy -= hn * ny
    hz -= hn * nz
    new = math.sqrt(hx * hx + hy * hy + hz * hz)
    if new > 0.0:
        s = old / new
        hx *= s
        hy *= s
        hz *= s
    hx += tx * dt
    hy += ty * dt
    hz += tz * dt
    ct = gamma[i] * math.sqrt(st * mstar[i])
    fx = -st * hx - ct * tx
    fy = -st * hy - ct * ty
    fz = -st * hz - ct * tz
    ft = math.sqrt(fx * fx + fy * fy + fz * fz)
    lim = mu[i] * fn
    if ft > lim:
        s = lim / ft
        fx *= s
        fy *= s
        fz *= s
        hx = -fx / st
        hy = -fy / st
        hz = -fz / st
    xi[i, 0], xi[i, 1], xi[i, 2] = hx, hy, hz
    force[i, 0] = fn * nx + fx
    force[i, 1] = fn * ny + fy
    force[i, 2] = fn * nz + fz
    fn_out[i] = fn


#: Below this many contacts (bodies) the force (kick) loop runs serially: a parallel launch
#: was measured at ~0.6 ms on a loaded 2-core machine. Both paths run the same per-item
#: function, so the choice never changes a bit.
PARALLEL_MIN = 20000


@njit(cache=True)
def _forces_serial(a, b, normal, gap, ra, rb, vel, omega, vwall, estar, gstar, rstar, mstar,
                   gamma, mu, xi, dt, force, fn_out):
    for i in range(a.shape[0]):
        _one_contact(i, a, b, normal, gap, ra, rb, vel, omega, vwall, estar, gstar, rstar,
                     mstar, gamma, mu, xi, dt, force, fn_out)


@njit(cache=True, parallel=True)
def _forces_parallel(a, b, normal, gap, ra, rb, vel, omega, vwall, estar, gstar, rstar, mstar,
                     gamma, mu, xi, dt, force, fn_out):
    for i in prange(a.shape[0]):
        _one_contact(i, a, b, normal, gap, ra, rb, vel, omega, vwall, estar, gstar, rstar,
                     mstar, gamma, mu, xi, dt, force, fn_out)


def contact_forces(a, b, normal, gap, ra, rb, vel, omega, vwall, estar, gstar, rstar, mstar,
                   gamma, mu, xi, dt, force, fn_out):
    """Per contact i (each writes only row i): the Hertz–Mindlin force on body ``a[i]``
    (``force`` (nc, 3), world; b gets its opposite) and the normal force ``fn_out`` (nc,);
    ``xi`` (nc, 3) comes in as last step's world-frame tangential displacement (zero for a new
    contact) and leaves as this step's (zero where the bodies do not overlap). ``normal``
    points from b to a; ``gap`` < 0 is an overlap; ``ra``/``rb`` are the lever arms; a wall
    (b < 0) moves with ``vwall[i]``; per-contact E*, G*, R*, m*, gamma, mu."""
    run = _forces_parallel if len(a) >= PARALLEL_MIN else _forces_serial
    run(a, b, normal, gap, ra, rb, vel, omega, vwall, estar, gstar, rstar, mstar, gamma, mu,
        xi, dt, force, fn_out)


@njit(cache=True)
def accumulate(a, b, ra, rb, force, nbody, f_body, t_body):
    """Sum each contact's force and torque into its bodies, serially in contact order (the
    fixed order that makes the sums bitwise reproducible): a gets +F and ra x F, b (a body)
    -F and -(rb x F). ``f_body``/``t_body`` (N, 3) are added to."""
    for i in range(a.shape[0]):
        fx, fy, fz = force[i, 0], force[i, 1], force[i, 2]
        if fx == 0.0 and fy == 0.0 and fz == 0.0:
            continue        # a candidate that does not touch adds nothing (not even a -0.0)
        ia = a[i]
        f_body[ia, 0] += fx
        f_body[ia, 1] += fy
        f_body[ia, 2] += fz
        cx, cy, cz = _cross(ra[i, 0], ra[i, 1], ra[i, 2], fx, fy, fz)
        t_body[ia, 0] += cx
        t_body[ia, 1] += cy
        t_body[ia, 2] += cz
        ib = b[i]
        if ib >= 0:
            f_body[ib, 0] -= fx
            f_body[ib, 1] -= fy
            f_body[ib, 2] -= fz
            cx, cy, cz = _cross(rb[i, 0], rb[i, 1], rb[i, 2], fx, fy, fz)
            t_body[ib, 0] -= cx
            t_body[ib, 1] -= cy
            t_body[ib, 2] -= cz


@njit(cache=True)
def _kick_one(i, x, v, w, f_body, t_body, inv_mass, wii, g, dt):
    im = inv_mass[i]
    for e in range(3):
        acc = im * f_body[i, e]
        if im > 0.0:
            acc += g[e]
        v[i, e] += dt * acc
    t0, t1, t2 = t_body[i, 0], t_body[i, 1], t_body[i, 2]
    for e in range(3):
        w[i, e] += dt * (wii[i, e, 0] * t0 + wii[i, e, 1] * t1 + wii[i, e, 2] * t2)
    for e in range(3):
        x[i, e] += dt * v[i, e]


@njit(cache=True)
def _kick_serial(x, v, w, f_body, t_body, inv_mass, wii, g, dt):
    for i in range(x.shape[0]):
        _kick_one(i, x, v, w, f_body, t_body, inv_mass, wii, g, dt)


@njit(cache=True, parallel=True)
def _kick_parallel(x, v, w, f_body, t_body, inv_mass, wii, g, dt):
    for i in prange(x.shape[0]):
        _kick_one(i, x, v, w, f_body, t_body, inv_mass, wii, g, dt)


def kick_drift(x, v, w, f_body, t_body, inv_mass, wii, g, dt):
    """v += dt (inv_mass F + g) (g only where inv_mass > 0), omega += dt I_w^-1 T with the
    world inverse inertia ``wii`` (N, 3, 3), x += dt v. Per body (own rows only)."""
    run = _kick_parallel if len(x) >= PARALLEL_MIN else _kick_serial
    run(x, v, w, f_body, t_body, inv_mass, wii, g, dt)


@njit(cache=True)
def contact_geometry(a, b, shift, pos, radii, wall_op, wall_sign, wall_pos, wall_rot, ops, lk,
                     lr, point, normal, gap):
    """The exact contact of each candidate (sphere ``a[i]`` against sphere ``b[i]`` at image
    ``shift[i]``, or against wall ``-1 - b[i]`` at its pose), with the narrow phase's
    formulas: the centre line for two spheres, the wall's tree at the sphere's centre
    (``phi - r``, normal along the tree's gradient) for a wall; ``point`` midway between the
    surfaces, ``normal`` from b to a, ``gap`` signed (+inf where a wall's gradient vanishes).
    Serial, in candidate order."""
    st = np.empty((MAX_STACK, STACK_COLS))
    for i in range(a.shape[0]):
        ia = a[i]
        ib = b[i]
        px, py, pz = pos[ia, 0], pos[ia, 1], pos[ia, 2]
        r = radii[ia]
        if ib >= 0:
            dx = px - (pos[ib, 0] + shift[i, 0])
            dy = py - (pos[ib, 1] + shift[i, 1])
            dz = pz - (pos[ib, 2] + shift[i, 2])
            dist = math.sqrt(dx * dx + dy * dy + dz * dz)
            g = dist - r - radii[ib]
            if dist > 0.0:
                nx, ny, nz = dx / dist, dy / dist, dz / dist
            else:
                nx, ny, nz = 0.0, 1.0, 0.0
            h = r + 0.5 * g
        else:
            w = -1 - ib
            Rt = wall_rot[w]
            dx = px - wall_pos[w, 0]
            dy = py - wall_pos[w, 1]
            dz = pz - wall_pos[w, 2]
            qx = Rt[0, 0] * dx + Rt[1, 0] * dy + Rt[2, 0] * dz
            qy = Rt[0, 1] * dx + Rt[1, 1] * dy + Rt[2, 1] * dz
            qz = Rt[0, 2] * dx + Rt[1, 2] * dy + Rt[2, 2] * dz
            phi, gx, gy, gz = eval_point(ops, lk, lr, wall_op[w, 0], wall_op[w, 1], qx, qy, qz,
                                         st)
            sgn = wall_sign[w]
            g = sgn * phi - r
            nx = sgn * (Rt[0, 0] * gx + Rt[0, 1] * gy + Rt[0, 2] * gz)
            ny = sgn * (Rt[1, 0] * gx + Rt[1, 1] * gy + Rt[1, 2] * gz)
            nz = sgn * (Rt[2, 0] * gx + Rt[2, 1] * gy + Rt[2, 2] * gz)
            nn = math.sqrt(nx * nx + ny * ny + nz * nz)
            if not (nn > 0.0 and g == g):
                g = np.inf
                nn = 1.0
            nx /= nn
            ny /= nn
            nz /= nn
            h = r + 0.5 * g
        point[i, 0] = px - h * nx
        point[i, 1] = py - h * ny
        point[i, 2] = pz - h * nz
        normal[i, 0] = nx
        normal[i, 1] = ny
        normal[i, 2] = nz
        gap[i] = g


# --------------------------------------------------------------------------------------------
# per-simulation state
# --------------------------------------------------------------------------------------------

class HertzState:
    """The Hertz engine's state in a Simulation: moduli per material id and the tangential
    history (``keys`` (K,) sorted int64, ``xi`` (K, 3) world frame, for ``n_bodies`` bodies)."""

    def __init__(self):
        self.moduli = {}                       # material id -> (E, nu)
        self.keys = np.zeros(0, np.int64)
        self.xi = np.zeros((0, 3))
        self.n_bodies = -1
        self.last = None                       # the last substep's contacts and forces
        self.cand = None                       # the candidate list (see substep)

    def set_material(self, material_id, youngs, poisson):
        """Young's modulus ``youngs`` (> 0, finite; pressure units) and Poisson ratio
        ``poisson`` in (-1, 0.5) of material id ``material_id`` in [0, 1023]."""
        mid = check_int("material_id", material_id, 0, MAX_MATERIAL_ID)
        e = check_float("youngs", youngs, 0.0, lo_open=True)
        nu = check_float("poisson", poisson, -1.0, 0.5, lo_open=True, hi_open=True)
        self.moduli[mid] = (e, nu)

    def clear_history(self):
        self.keys = np.zeros(0, np.int64)
        self.xi = np.zeros((0, 3))

    def _modulus(self, mid, what):
        if mid not in self.moduli:
            raise PecletArgumentError("material ids", "declared with set_hertz_material("
                                      "material_id, youngs, poisson) before step_hertz",
                                      mid, f"{what} material id {mid} has no moduli")
        return self.moduli[mid]

    def body_moduli(self, body_ids):
        """(E, nu) per body from its material id (every id must be declared)."""
        uk, inv = np.unique(body_ids, return_inverse=True)
        tab = np.array([self._modulus(int(k), "body") for k in uk], np.float64).reshape(-1, 2)
        inv = inv.reshape(-1)
        return tab[inv, 0], tab[inv, 1]

    def wall_moduli(self, wall_ids):
        """(normal compliance (1 - nu^2)/E, shear compliance (2 - nu)/G) per wall: both zero
        for a wall without a material id (rigid)."""
        ce = np.zeros(len(wall_ids))
        cg = np.zeros(len(wall_ids))
        for w, k in enumerate(wall_ids.tolist()):
            if k >= 0:
                e, nu = self._modulus(int(k), "wall")
                ce[w] = (1.0 - nu * nu) / e
                cg[w] = (2.0 - nu) * 2.0 * (1.0 + nu) / e
        return ce, cg

    def lookup(self, keys):
        """The stored history (nc, 3) of each key, zero for a new contact."""
        out = np.zeros((len(keys), 3))
        if len(keys) and len(self.keys):
            j = np.minimum(np.searchsorted(self.keys, keys), len(self.keys) - 1)
            hit = self.keys[j] == keys
            out[hit] = self.xi[j[hit]]
        return out

    def store(self, keys, xi, touching, n_bodies):
        o = np.argsort(keys[touching], kind="stable")
        self.keys = keys[touching][o]
        self.xi = xi[touching][o]
        self.n_bodies = n_bodies

    def arrays(self):
        """(moduli (M, 3) rows id, E, nu; keys; xi; n_bodies) for a save."""
        rows = [[k, e, nu] for k, (e, nu) in sorted(self.moduli.items())]
        return (np.array(rows, np.float64).reshape(-1, 3), self.keys.copy(), self.xi.copy(),
                np.int64(self.n_bodies))


# --------------------------------------------------------------------------------------------
# the step
# --------------------------------------------------------------------------------------------

def _pair_parameters(sim, c, state, mass_inv):
    """E*, G*, R*, m*, gamma, mu per contact (each (nc,))."""
    from peclet.dem.materials import per_contact
    b = sim._bodies
    mats = sim._materials
    ids = mats.body_ids if mats.body_ids is not None else np.zeros(b.n, np.int64)
    eb, nub = state.body_moduli(ids)
    ce_body = (1.0 - nub * nub) / eb
    cg_body = (2.0 - nub) * 2.0 * (1.0 + nub) / eb
    ce_wall, cg_wall = state.wall_moduli(mats.wall_ids)
    radii = sim._radii()
    isw = c.b < 0
    bi = np.where(isw, 0, c.b)
    wi = np.where(isw, -1 - c.b, 0)
    ce = ce_body[c.a] + (np.where(isw, ce_wall[wi] if len(ce_wall) else 0.0, ce_body[bi]))
    cg = cg_body[c.a] + (np.where(isw, cg_wall[wi] if len(cg_wall) else 0.0, cg_body[bi]))
    ra = radii[c.a]
    rb = radii[bi]
    rstar = np.where(isw, ra, ra * rb / (ra + rb))
    im = mass_inv[c.a] + np.where(isw, 0.0, mass_inv[bi])
    with np.errstate(divide="ignore"):
        mstar = np.where(im > 0.0, 1.0 / np.where(im > 0.0, im, 1.0), 0.0)
    if mats.active():
        e_c, _, mu_c = mats.per_contact(c.a, c.b, sim._material, sim._geometry())
    else:
        e_c, _, mu_c = per_contact(c.b, sim._material, sim._geometry())
    ue, inv = np.unique(e_c, return_inverse=True)
    gam = np.array([damping_gamma(float(e)) for e in ue])[inv.reshape(-1)] \
        if len(ue) else np.zeros(0)
    return 1.0 / ce, 1.0 / cg, rstar, mstar, gam, np.ascontiguousarray(mu_c, dtype=np.float64)


def check(sim, state, dt):
    """Refuse what the engine cannot run: composed particles, undeclared moduli, a dt above
    ``RAYLEIGH_FRACTION`` of the smallest Rayleigh time, restitution below ``E_MIN``."""
    from peclet.dem.shapes import SceneShape
    b = sim._bodies
    scene = np.array([isinstance(s, SceneShape) for s in sim._shapes], bool)
    if b.n and np.any(scene[b.shape]):
        raise PecletArgumentError("shape ids", "sphere shapes only (the Hertz engine does not "
                                  "support composed particles yet; use step())",
                                  "a composed (scene) shape in use")
    mats = sim._materials
    ids = mats.body_ids if mats.body_ids is not None else np.zeros(b.n, np.int64)
    state.wall_moduli(mats.wall_ids)
    if not b.n:
        return
    e, nu = state.body_moduli(ids)
    m = b.inv_mass > 0
    if np.any(m):
        r = sim._radii()[m]
        rho = (1.0 / b.inv_mass[m]) / (4.0 / 3.0 * math.pi * r ** 3)
        tr = float(np.min(rayleigh_time(r, rho, e[m], nu[m])))
        if dt > RAYLEIGH_FRACTION * tr:
            raise PecletArgumentError("dt", f"<= {RAYLEIGH_FRACTION} x the smallest Rayleigh "
                                      f"time pi R sqrt(rho/G)/(0.1631 nu + 0.8766) = "
                                      f"{RAYLEIGH_FRACTION * tr:.6g}", dt)
    walls_e = sim._geometry().wall_e
    lows = [float(v) for v in np.concatenate([[sim._material.e_n], walls_e])
            if v < E_MIN]
    lows += [mt.e_n for mt in mats.pairs.values() if mt.e_n < E_MIN]
    if lows:
        raise PecletArgumentError("e_n", f"in [{E_MIN}, 1] for the Hertz engine (its damping "
                                  "cannot stop a contact dead)", min(lows))


class Candidates(NamedTuple):
    """The contacts that can touch until the next rebuild: ``a``, ``b``, ``shift``, ``feat``
    and ``keys`` as the detection gave them (task order), ``x_ref`` the positions they were
    found at, ``skin`` the detection margin, ``radii`` (N,), and ``params`` the pair
    parameters (E*, G*, R*, m*, gamma, mu) per candidate."""
    a: np.ndarray
    b: np.ndarray
    shift: np.ndarray
    feat: np.ndarray
    keys: np.ndarray
    x_ref: np.ndarray
    skin: float
    radii: np.ndarray
    params: tuple


def _candidates(sim, state, x, q, skin_frac, inv_mass):
    """The candidate list for positions ``x``: kept from the last substep while no pair can
    have closed the skin (twice the largest displacement since it was built below the skin,
    every wall static and 1-Lipschitz, no periodic axis), else rebuilt by the engine's
    detection with margin = ``skin_frac`` x the smallest radius. Every contact that touches
    is in the list either way, and its geometry is recomputed exactly at every substep
    (:func:`contact_geometry`), so the schedule of rebuilds never changes a bit."""
    from peclet.core.geom.transforms import quats_to_matrices
    from peclet.dem.contacts import WarmStart
    cand = state.cand
    geo = sim._geometry()
    if cand is not None and len(cand.x_ref) == len(x) and not sim._domain.periodic.any() \
            and not sim._wallmo.moving() and bool(np.all(geo.wall_lip)):
        d = np.sqrt(((x - cand.x_ref) ** 2).sum(axis=1))
        if 2.0 * float(d.max(initial=0.0)) < cand.skin:
            return cand
    radii = sim._radii()
    skin = skin_frac * float(radii.min())
    c = sim._detect(x, quats_to_matrices(q), skin)
    cand = Candidates(c.a, c.b, np.ascontiguousarray(c.shift), c.feat,
                      WarmStart.keys_of(c, len(sim._walls)), x.copy(), skin, radii,
                      _pair_parameters(sim, c, state, inv_mass))
    state.cand = cand
    return cand


def substep(sim, state, dt, skin_frac):
    """One explicit substep of ``dt`` (the facade has checked the arguments and the state and
    cleared ``state.cand`` at the start of the call). Commits the new state; raises StepError
    (state of the substep's start kept) on a non-finite or runaway state."""
    import time

    from peclet.dem import solver
    from peclet.dem.contacts import Contacts, lever_arms
    from peclet.dem.rigid import advance_all

    t0 = time.perf_counter()
    b = sim._bodies
    if state.n_bodies != b.n:
        state.clear_history()
    inv_mass, inv_inertia, x, q, v, w = sim._working_state()
    sim._guard(x, q, v, w)
    cand = _candidates(sim, state, x, q, skin_frac, inv_mass)
    t1 = time.perf_counter()
    nc = len(cand.a)
    point = np.empty((nc, 3))
    normal = np.empty((nc, 3))
    gap = np.empty(nc)
    geo = sim._geometry()
    contact_geometry(cand.a, cand.b, cand.shift, x, cand.radii, geo.wall_op, geo.wall_sign,
                     geo.wall_pos, geo.wall_rot, geo.ops, geo.lk, geo.lr, point, normal, gap)
    c = Contacts(cand.a, cand.b, cand.shift, point, normal, gap, cand.feat)
    keys = cand.keys
    xi = state.lookup(keys)
    estar, gstar, rstar, mstar, gam, mu = cand.params
    ra, rb = lever_arms(c, x)
    nc = len(c.a)
    vw = np.zeros((nc, 3))
    if sim._wallmo.moving():
        isw = c.b < 0
        vw[isw] = sim._wallmo.surface_velocity(-1 - c.b[isw], c.point[isw])
    force = np.empty((nc, 3))
    fn = np.empty(nc)
    contact_forces(c.a, c.b, np.ascontiguousarray(c.normal), np.ascontiguousarray(c.gap), ra,
                   rb, v, w, vw, estar, gstar, rstar, mstar, gam, mu, xi, dt, force, fn)
    fb = np.zeros((b.n, 3)) if sim._ext_force is None else sim._ext_force.copy()
    tb = np.zeros((b.n, 3)) if sim._ext_torque is None else sim._ext_torque.copy()
    accumulate(c.a, c.b, ra, rb, force, b.n, fb, tb)
    wii = solver.world_inv_inertias(q, inv_inertia)
    with np.errstate(over="ignore", invalid="ignore"):   # the guard reports it
        kick_drift(x, v, w, fb, tb, inv_mass, np.ascontiguousarray(wii), sim._gravity, dt)
    sim._guard(x, q, v, w)
    advance_all(q, w, inv_inertia, dt)
    sim._domain.wrap(x)
    sim._guard(x, q, v, w)
    # commit
    b.pos, b.quat, b.vel, b.omega = x, q, v, w
    touching = c.gap < 0.0
    state.store(keys, xi, touching, b.n)
    state.last = (c, force, fn, xi)
    sim._wallmo.advance(dt)
    sim._num_contacts = int(np.count_nonzero(touching))
    sim._step_count += 1
    sim._time += dt
    t2 = time.perf_counter()
    sim.timings["solver"] += t2 - t1
    sim.timings["total"] += t2 - t0


def last_listing(state):
    """The last substep's touching contacts, sorted by (body_a, body_b, feature): ``body_a``,
    ``body_b`` (a wall is -1 - index), ``point`` (n, 3), ``normal`` (n, 3) from b to a,
    ``depth`` (n,) overlap > 0, ``force`` (n, 3) on body a (world; b gets the opposite),
    ``normal_force`` (n,) >= 0, ``tangential_displacement`` (n, 3) the Mindlin history."""
    if state.last is None:
        z = np.zeros(0)
        return {"body_a": np.zeros(0, np.int64), "body_b": np.zeros(0, np.int64),
                "point": np.zeros((0, 3)), "normal": np.zeros((0, 3)), "depth": z,
                "force": np.zeros((0, 3)), "normal_force": z,
                "tangential_displacement": np.zeros((0, 3))}
    c, force, fn, xi = state.last
    m = c.gap < 0.0
    o = np.lexsort((c.feat[m], c.b[m], c.a[m]))
    return {"body_a": c.a[m][o], "body_b": c.b[m][o], "point": c.point[m][o],
            "normal": c.normal[m][o], "depth": -c.gap[m][o], "force": force[m][o],
            "normal_force": fn[m][o], "tangential_displacement": xi[m][o]}
