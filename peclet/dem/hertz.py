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
``e_t`` is not used by this engine. Rolling resistance: optional, off by default (below).

Rolling resistance (``Simulation.set_rolling_friction``, ``mu_r`` in [0, 1] per pair of
material ids, else one value for every pair; a wall without a material id takes that value;
0 by default). The elastic-plastic spring-dashpot of Ai, Chen, Rotter & Ooi (Powder Technol.
206, 2011, model type C, "EPSD")::

    k_r = 2.25 S_n mu_r^2 R*^2                 S_n = 2 E* sqrt(R* delta): the current normal
                                               stiffness of the kernel
    dtheta = (omega_a - omega_b) projected onto the tangent plane x dt  (a wall: its omega)
    M_r <- (M_r rotated into the current tangent plane) - k_r dtheta
    |M_r| <= mu_r R* F_n                       (else scaled onto it: fully mobilised)
    M = M_r - C_r omega_r while |M_r| < mu_r R* F_n (no dashpot once mobilised, Ai's f = 0),
        C_r = 2 ROLLING_DAMPING sqrt(I_r k_r), 1/I_r = sum over the bodies of 1 / (I + m l^2)
        (l the lever arm; I from the mean principal inverse moment: exact for a sphere), |M|
        kept within mu_r R* F_n

``M`` acts on body a, ``-M`` on body b, nothing on a wall; F_n is the contact's normal force
this step (dashpot included, >= 0). Why type C: the constant-torque model (Ai's type A) and
the viscous ones (B, D) have no torque at rest, so they cannot hold a sphere on a slope and make
a stopped sphere jitter; the spring of type C holds it (a sphere stays on an incline while
tan(theta) <= mu_r) and its plastic limit gives the constant torque mu_r R* F_n while it rolls
(a deceleration of 5/7 mu_r g on a floor). k_n is the tangent stiffness S_n because the spring
is incremental, like the Mindlin spring; k_r only sets how fast the torque reaches its limit
and the rolling deflection at rest, never the limit. The dashpot is kept: without it a sphere
stopped by the plastic torque rocks elastically for ever (amplitude mu_r R* F_n / k_r).
ROLLING_DAMPING is our choice, not a value from the paper. Departures: the total is capped at
the plastic torque (so a contact that starts on a fast-spinning body cannot brake harder than
the limit through its dashpot); the twist about n is not resisted. ``M_r`` is kept per contact
key with the Mindlin history (carried, dropped and saved with it). R*: for spheres the pair's
(a sphere's radius against a wall, also a curved one); for a composed particle's patch the
patch's R* (the normal law's); for a distributed contact, whose kernel R*_h is no radius,
the R* of the two bounding spheres (the bounding radius against a wall; the usual convention
for non-spherical particles: state it when quoting mu_r for such particles). The rolling kernel
runs only when some candidate has mu_r > 0: with mu_r = 0 everywhere the arithmetic is the
engine's without it, bit for bit.

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

Composed (CSG) particles: ONE Hertz contact per touching patch, with R* from the local
principal curvatures of both surfaces at the contact point. Why not the impulse manifold or a
per-probe area weighting: the manifold's up-to-16 points per pair are chosen for the impulse
solve, so a force summed over them would depend on how many were kept; and a Hertz patch
(contact radius ``sqrt(R* delta)``, ~1 % of R) is far smaller than the probe spacing (~10 % of
R for ~1000 probes), so a per-probe sum would not converge at any affordable probe count. The
law, per patch::

    point x: the unit gradients of the two fields opposite and the two distance estimates
             d = phi / |grad phi| equal (midway), found by Newton's method (tangential step
             from the summed Hessians, normal step to the mid-surface); gap = d_a + d_b
    K_s = P H P / |grad phi| at x (H: central differences of the exact gradient, step
          FD_STEP x the pair's scale; closed form for an analytic sphere), carried to the
          surface by K (I - d K)^-1; relative curvature K_a + K_b, principal radii R' <= R''
    R* = sqrt(R' R'') / F2^3 (exact elliptical Hertz, Johnson 1985 §4.2: F2 tabulated in
         ln(R''/R'), :func:`elliptic_table`; 1 for a circular contact), then the sphere law

Walls enter with their own curvature here (the sphere path above keeps its flat-wall
convention, for its bits: an O(R / R_wall) difference on curved walls). Patches are seeded at
each rebuild of the candidate list (:func:`seed_patches`: the detection's points and every probe
within the skin, deepest first; a seed starts a Newton solve unless it lies in the footprint
of a patch already found, and solves ending on a known patch are merged), then each patch is
solved again at every substep from its last point (:func:`patch_geometry`), so the force does
not depend on the probe count. Key: the pair and the probe nearest the patch point (of a, or
of b offset by FEATURE_DIR when a is an analytic sphere), fixed between rebuilds; at a rebuild
each stored history goes to the nearest new patch of its pair within twice the probe spacing
plus the skin, so the Mindlin history follows the patch (save and load keep it: it needs only
the keys). Assumptions: each touching patch is smooth and convex (K_a + K_b positive
definite), delta << R' and a non-conforming, isolated patch (contact radius << R', patches far
apart compared with their size). Limits: a patch is only found if some probe lies within the
skin (the rebuild keeps half the skin for the probes' spacing), and rotation counts in the
rebuild test; the Newton start depends on when the list was rebuilt, so unlike spheres a
composed run's bits depend on the call pattern (not on the thread count); the Mindlin spring
uses the circular ``8 G* sqrt(R* delta)`` also for an elliptical patch; Rayleigh's dt check
uses the bounding radius with the body's mass spread over its bounding sphere.

Distributed contacts (flat, line, edge, corner). Where the patch law fails on a touching
patch (no positive relative curvature: a face on a face or a wall, a cylinder on its side,
an edge or a corner; R''/R' > RATIO_LIMIT; delta > DELTA_LIMIT x R'; a probe inside the other
body where no patch solves; more than MAX_PATCHES patches), or a pair with such a failed seed
has no touching Hertz patch, the whole pair gets ONE distributed contact instead
(:func:`distributed_geometry`, every substep). Pairs that the patch law holds are untouched
(bit for bit). The law::

    normal n: the other body's outward unit normal at the deepest probe (of a in b or b in a)
    region:   the overlap of the two bodies seen along n, sampled on a DIST_GRID^2 grid in the
              plane normal to n, zoomed onto the region (a coarse look, then boxes around the
              inside nodes along their principal axes; a region thinner than the spacing, a
              line, is found from a quadratic model of m and a row of nodes put through it),
              each inside node's cell cut at the region's boundary by bisection; inside means
              m = min_s max(phi_a, phi_b) < 0 along the node's normal line (1-Lipschitz, so a
              node with m > half the cell diagonal rules its cell out)
    fallback: when the search neither finds an overlap nor rules one out on its first, whole
              box: along a second normal (the deepest probe whose normal is more than
              DIST_DISTINCT from the first's), and, for a contact that touched in the last
              substep, along both on a grid DIST_FALLBACK times finer; of the first two that
              find the overlap, the one with the shorter largest chord (the direction of
              least penetration). A search that finds its overlap at once is unchanged.
    overlap:  d(x) = the chord of the intersection along n at x (Newton to both surfaces);
              V = sum d w, A = sum w over the cells (w their areas), J their second moments
    law:      p(x) = k d(x),  k = pi a E* / (K(e) A),  F = k V,  S = k A
              a, b the ellipse of area A with J's principal ratio (a / b = sqrt(J1 / J2)),
              e^2 = 1 - b^2 / a^2, K the complete elliptic integral of the first kind

k makes the region's rigid flat punch exact for an ellipse: F = pi a E* delta / K(e) (the flat
elliptical punch; a circle, K = pi / 2, gives F = 2 a E* delta, Johnson 1985 §3.8). Accuracy
against closed forms (E* the pair's, the bodies taken as half-spaces): a square punch 0.6 %
softer than Gazetas' rigid-footing fit (the equal-area disc has the least stiffness of all
plane shapes of its area, Polya-Szego); a cylinder of length L on its side: F = k V gives
F ~ 1.18 E* L delta / ln(2 L / b_g) (b_g = sqrt(2 R delta)), 4-6 % softer than Lundberg's
finite line contact delta = 2 F / (pi L E*) (1.8864 + ln(L / 2 b)) (chosen over Johnson §4.3's
two-dimensional approach, which needs a datum, and over the "simple" F = pi/4 E* L delta of
two-dimensional DEM, ~3.5x stiffer than either at these loads); a cone / corner 4.7 % stiffer
than Sneddon's F = (2 / pi) E* cot(theta) delta^2; a sphere 6 % stiffer than Hertz (such
patches take the exact Hertz path anyway). It acts at the pressure centroid of the region,
along n (exact torque for one plane region). Through the same force kernel: delta_h = 3 F /
(2 S) and R*_h with 4/3 E* sqrt(R*_h) delta_h^1.5 = F, so that the kernel's S_n = S, the
Mindlin spring is S_t = 4 (G* / E*) S (Mindlin's ratio), truncated at Coulomb as before, and
the Tsuji dashpot gamma sqrt(S m*) uses gamma from :func:`damping_gamma_linear` (the same
calibration for the linear law x'' = -max(0, x + gamma x'): exact e for a flat punch; for a
line contact F is linear up to the log; for a corner, F ~ delta^2, the rebound differs from e).
Key: the pair and DIST_FEATURE (one per pair, stable across rebuilds; the history carries
over). ``hertz_contacts`` lists the contact with depth = the largest chord. Limits: one
region and one normal per pair (two separate regions of a pair are lumped into one ellipse,
their couple about n lost); the normal is a probe's, so it can jump between neighbouring
probes on a curved surface, and where two rims or edges cross the overlap lies between the
probes (none inside), the nearest probe outside it sets n, and n can turn by tens of degrees
in a substep (the largest chord then reads up to ~2x longer: the fallback's choice of the
shorter chord covers only the fallback); a new region found at no grid node within
DIST_ZOOMS zooms exerts no force until it grows (a touching one gets the fallback); a switch between the patch law and the distributed law is a jump of a
few % in force and restarts the Mindlin history. Refused with :class:`HertzPatchError` (a
PecletArgumentError naming both bodies; the state of the failing substep's start kept): a
distributed contact whose largest chord exceeds DIST_DEEP_LIMIT x the smaller bounding radius.
Rolling resistance acts on it with the bounding spheres' R* (see "Rolling resistance").

Determinism: the force and rolling kernels write only their own contact's slots; forces and
torques are summed into bodies serially in contact order (the rolling torques after the
forces'); the history is sorted by key. Bitwise identical
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
def _rhs(x, u, g, linear):
    # overlap x, approach speed u: x' = u, u' = -max(0, x^1.5 + g x^0.25 u) (Hertz), or
    # u' = -max(0, x + g u) (linear: the distributed contact's calibration)
    if x <= 0.0:
        return 0.0
    f = x + g * u if linear else x ** 1.5 + g * x ** 0.25 * u
    return -f if f > 0.0 else 0.0


@njit(cache=True)
def rebound_speed(g, h, linear):
    """Rebound speed of the dimensionless damped impact (approach speed 1) with the
    coefficient ``g`` of the damping term (Hertz: ``g`` = sqrt(3/2) gamma in front of
    ``x^(1/4) x'``; ``linear``: in front of ``x'`` of ``x'' = -max(0, x + g x')``), by RK4 of
    step ``h``; the exit is interpolated linearly in the last step."""
    x = 0.0
    u = 1.0
    for _ in range(100_000_000):
        k1x = u
        k1u = _rhs(x, u, g, linear)
        k2x = u + 0.5 * h * k1u
        k2u = _rhs(x + 0.5 * h * k1x, u + 0.5 * h * k1u, g, linear)
        k3x = u + 0.5 * h * k2u
        k3u = _rhs(x + 0.5 * h * k2x, u + 0.5 * h * k2u, g, linear)
        k4x = u + h * k3u
        k4u = _rhs(x + h * k3x, u + h * k3u, g, linear)
        xn = x + h / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x)
        un = u + h / 6.0 * (k1u + 2.0 * k2u + 2.0 * k3u + k4u)
        if xn <= 0.0 and un < 0.0:
            return -un
        x = xn
        u = un
    return 0.0


def _restitution(gamma):
    return float(rebound_speed(math.sqrt(1.5) * gamma, _CAL_STEP, False))


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
def _into_plane(hx, hy, hz, nx, ny, nz):
    """A contact's history vector (hx, hy, hz) turned into the plane normal to the unit n,
    its length kept (a zero projection stays zero): the contact frame turned since the
    history was stored. Serves the Mindlin and the rolling histories alike."""
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
    return hx, hy, hz


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
    hx, hy, hz = _into_plane(xi[i, 0], xi[i, 1], xi[i, 2], nx, ny, nz)
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
        _one_contact(np.int64(i), a, b, normal, gap, ra, rb, vel, omega, vwall, estar, gstar,
                     rstar, mstar, gamma, mu, xi, dt, force, fn_out)


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


# --------------------------------------------------------------------------------------------
# rolling resistance (elastic-plastic spring-dashpot, Ai et al. 2011 type C)
# --------------------------------------------------------------------------------------------

#: Largest rolling friction coefficient accepted (mu_r is a lever arm over R*: beyond 1 the
#: plastic torque would need a lever longer than the contact's radius).
MU_R_MAX = 1.0

#: Critical-damping ratio of the rolling dashpot (Ai et al.'s eta_r). Our choice, not a value
#: taken from the paper: at 0.3 the elastic rocking left when a rolling body stops loses ~86 % of
#: its amplitude per cycle, and the explicit dashpot stays far inside its stability limit
#: (2 eta_r Omega_r dt << 2 whenever dt resolves the normal contact).
ROLLING_DAMPING = 0.3


@njit(cache=True)
def _contact_inv_moment(im, ii, r2):
    # 1 / (I + m r^2) of one body about the contact point (the rolling dashpot's inertia);
    # a fixed or rotation-locked body turns nothing: 0
    if im <= 0.0 or ii <= 0.0:
        return 0.0
    return ii * im / (im + ii * r2)


@njit(cache=True)
def _one_rolling(i, a, b, normal, gap, ra, rb, omega, wom, estar, rstar, rroll, mu_r, fn,
                 inv_mass, inv_rot, dt, mr, torque):
    # contact i of rolling_torques; writes only row i
    d = -gap[i]
    m = mu_r[i]
    lim = m * rroll[i] * fn[i]
    if d <= 0.0 or not lim > 0.0:
        for e in range(3):
            torque[i, e] = 0.0
            mr[i, e] = 0.0
        return
    ia = a[i]
    ib = b[i]
    nx, ny, nz = normal[i, 0], normal[i, 1], normal[i, 2]
    wx, wy, wz = omega[ia, 0], omega[ia, 1], omega[ia, 2]
    if ib >= 0:
        wx -= omega[ib, 0]
        wy -= omega[ib, 1]
        wz -= omega[ib, 2]
    else:
        wx -= wom[i, 0]
        wy -= wom[i, 1]
        wz -= wom[i, 2]
    # only rolling is resisted: the twist about n is not part of this model
    wn = wx * nx + wy * ny + wz * nz
    wx -= wn * nx
    wy -= wn * ny
    wz -= wn * nz
    # k_n is the kernel's S_n (for a distributed contact the overlap law's S)
    kn = 2.0 * estar[i] * math.sqrt(rstar[i] * d)
    r = rroll[i]
    kr = 2.25 * kn * m * m * r * r
    # history into the current tangent plane, length kept (as the Mindlin history)
    hx, hy, hz = _into_plane(mr[i, 0], mr[i, 1], mr[i, 2], nx, ny, nz)
    hx -= kr * wx * dt
    hy -= kr * wy * dt
    hz -= kr * wz * dt
    h = math.sqrt(hx * hx + hy * hy + hz * hz)
    tx, ty, tz = hx, hy, hz
    if h >= lim:
        # fully mobilised: the spring holds the plastic torque, the dashpot is off (Ai's f = 0)
        s = lim / h
        hx *= s
        hy *= s
        hz *= s
        tx, ty, tz = hx, hy, hz
    else:
        ja = _contact_inv_moment(inv_mass[ia], inv_rot[ia],
                                 ra[i, 0] * ra[i, 0] + ra[i, 1] * ra[i, 1] + ra[i, 2] * ra[i, 2])
        jb = 0.0
        if ib >= 0:
            jb = _contact_inv_moment(inv_mass[ib], inv_rot[ib], rb[i, 0] * rb[i, 0]
                                     + rb[i, 1] * rb[i, 1] + rb[i, 2] * rb[i, 2])
        j = ja + jb
        if j > 0.0:
            cr = 2.0 * ROLLING_DAMPING * math.sqrt(kr / j)
            tx -= cr * wx
            ty -= cr * wy
            tz -= cr * wz
            # spring plus dashpot never beyond the plastic torque
            t = math.sqrt(tx * tx + ty * ty + tz * tz)
            if t > lim:
                s = lim / t
                tx *= s
                ty *= s
                tz *= s
    mr[i, 0], mr[i, 1], mr[i, 2] = hx, hy, hz
    torque[i, 0], torque[i, 1], torque[i, 2] = tx, ty, tz


@njit(cache=True)
def _rolling_serial(a, b, normal, gap, ra, rb, omega, wom, estar, rstar, rroll, mu_r, fn,
                    inv_mass, inv_rot, dt, mr, torque):
    for i in range(a.shape[0]):
        _one_rolling(i, a, b, normal, gap, ra, rb, omega, wom, estar, rstar, rroll, mu_r, fn,
                     inv_mass, inv_rot, dt, mr, torque)


@njit(cache=True, parallel=True)
def _rolling_parallel(a, b, normal, gap, ra, rb, omega, wom, estar, rstar, rroll, mu_r, fn,
                      inv_mass, inv_rot, dt, mr, torque):
    for i in prange(a.shape[0]):
        _one_rolling(np.int64(i), a, b, normal, gap, ra, rb, omega, wom, estar, rstar, rroll,
                     mu_r, fn, inv_mass, inv_rot, dt, mr, torque)


def rolling_torques(a, b, normal, gap, ra, rb, omega, wom, estar, rstar, rroll, mu_r, fn,
                    inv_mass, inv_rot, dt, mr, torque):
    """Per contact i (each writes only row i): the rolling resistance torque on body ``a[i]``
    (``torque`` (nc, 3), world; b gets its opposite, a wall nothing). ``mr`` (nc, 3) comes in
    as last step's spring torque (zero for a new contact) and leaves as this step's (zero where
    the bodies do not touch or do not press). ``wom`` the angular velocity of a wall b,
    ``rstar`` the kernel's R* (with ``gap`` and ``estar``: the normal stiffness), ``rroll``
    the rolling radius, ``fn`` the normal force of :func:`contact_forces` this step,
    ``inv_rot`` (N,) the bodies' mean principal inverse moment (the dashpot's inertia)."""
    run = _rolling_parallel if len(a) >= PARALLEL_MIN else _rolling_serial
    run(a, b, normal, gap, ra, rb, omega, wom, estar, rstar, rroll, mu_r, fn, inv_mass,
        inv_rot, dt, mr, torque)


@njit(cache=True)
def accumulate_torques(a, b, torque, t_body):
    """Add each contact's rolling torque to its bodies, serially in contact order: a gets +T,
    b (a body) -T, a wall nothing."""
    for i in range(a.shape[0]):
        tx, ty, tz = torque[i, 0], torque[i, 1], torque[i, 2]
        if tx == 0.0 and ty == 0.0 and tz == 0.0:
            continue
        ia = a[i]
        t_body[ia, 0] += tx
        t_body[ia, 1] += ty
        t_body[ia, 2] += tz
        ib = b[i]
        if ib >= 0:
            t_body[ib, 0] -= tx
            t_body[ib, 1] -= ty
            t_body[ib, 2] -= tz


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
        _kick_one(np.int64(i), x, v, w, f_body, t_body, inv_mass, wii, g, dt)


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
# composed (CSG) particles: one Hertz patch per touching region
# --------------------------------------------------------------------------------------------

#: Newton iterations of a patch solve before it counts as not converged.
PATCH_MAX_ITER = 40
#: A patch solve has converged when its step is below this fraction of the pair's length scale
#: (the smaller bounding radius of its bodies).
PATCH_TOL = 1e-10
#: The central-difference step of the Hessians, as a fraction of the pair's length scale.
FD_STEP = 1e-5
#: A touching patch is refused when its overlap exceeds this fraction of its smaller principal
#: radius of relative curvature (the patch law assumes delta << R).
DELTA_LIMIT = 0.1
#: A touching patch is refused when its principal radii of relative curvature differ by more
#: than this ratio (a line-like contact: a cylinder on its side, an edge).
RATIO_LIMIT = 100.0
#: At most this many patches per body pair.
MAX_PATCHES = 16
#: Two patch solves of a pair that end closer than this fraction of the length scale found
#: the same patch.
SAME_PATCH = 1e-7
#: Feature ids of the seeds whose patch solve failed (kept to watch their probe) carry this bit.
FAILED_FEATURE = 1 << 25

#: Patch status codes (the kernels' ``status`` arrays; anything but OK on a touching patch is
#: refused by :func:`_raise_patch_error`).
PATCH_OK = 0
PATCH_NO_CONVERGENCE = 1
PATCH_NOT_CONVEX = 2
PATCH_DEEP = 3
PATCH_LINE = 4
PATCH_PROBE_INSIDE = 5
PATCH_TOO_MANY = 6

_PATCH_REASONS = {
    PATCH_NO_CONVERGENCE: "the contact point's Newton solve did not converge on a touching "
                          "patch",
    PATCH_NOT_CONVEX: "the touching patch has no positive relative curvature (a flat, "
                      "conforming, concave or line contact: a face, an edge, a cylinder's side)",
    PATCH_DEEP: f"the overlap exceeds {DELTA_LIMIT} x the smaller local radius of relative "
                "curvature (a sharp feature, or far too soft: the patch law needs delta << R)",
    PATCH_LINE: f"the principal radii of relative curvature differ by more than {RATIO_LIMIT:g}x "
                "(a line-like contact)",
    PATCH_PROBE_INSIDE: "a probe of one body is inside the other where no convex Hertz patch "
                        "forms (a flat face, a line along a cylinder, an edge or a corner "
                        "touching)",
    PATCH_TOO_MANY: f"more than {MAX_PATCHES} separate patches for one body pair",
}


class HertzPatchError(PecletArgumentError):
    """A composed particle's contact that the Hertz patch law cannot represent (see the module
    docstring, "Composed"). ``body_a``, ``body_b`` (a wall is -1 - index) and ``reason``."""

    def __init__(self, body_a, body_b, reason):
        self.body_a = int(body_a)
        self.body_b = int(body_b)
        self.reason = reason
        other = f"body {body_b}" if body_b >= 0 else f"wall {-1 - body_b}"
        super().__init__("shapes", "composed particles whose touching patches are smooth and "
                         f"convex (positive relative curvature, R''/R' <= {RATIO_LIMIT:g}, "
                         f"overlap <= {DELTA_LIMIT} R') for step_hertz",
                         f"body {body_a} against {other}", reason)


@lru_cache(maxsize=1)
def elliptic_table():
    """(t (K,), c (K,)): the elliptical Hertz correction ``c = F2^-3`` at ``t = ln(R''/R')``,
    R'' >= R' the principal radii of relative curvature, on a uniform grid of t in [0,
    ln RATIO_LIMIT]. Exact elliptical Hertz theory (Johnson, Contact Mechanics, 1985, §4.2)
    gives ``F = 4/3 E* sqrt(R_e / F2^3) delta^(3/2)`` with ``R_e = sqrt(R' R'')``; F2 (<= 1,
    0.993 at a ratio 2, 0.93 at 10, 0.79 at 100) is found here from the ellipse's
    eccentricity (complete elliptic integrals, Brent's method)."""
    from scipy.optimize import brentq
    from scipy.special import ellipe, ellipk

    def ratio(m):       # B / A of the contact ellipse of eccentricity^2 m
        k, e = ellipk(m), ellipe(m)
        return (e / (1.0 - m) - k) / (k - e)

    t = np.linspace(0.0, math.log(RATIO_LIMIT), 401)
    c = np.ones_like(t)
    for i in range(1, len(t)):
        lam = math.exp(t[i])
        m = brentq(lambda m: ratio(m) - lam, 1e-12, 1.0 - 1e-15, xtol=1e-15, rtol=1e-14)
        k, e = ellipk(m), ellipe(m)
        b = math.sqrt(1.0 - m)                  # a = 1, p0 = 1, E* = 1
        fa = b / m * (k - e)
        fb = b / m * (e / (1.0 - m) - k)
        force = 2.0 / 3.0 * math.pi * b
        delta = b * k
        re = 1.0 / (2.0 * math.sqrt(fa * fb))
        f2 = delta / (9.0 * force * force / (16.0 * re)) ** (1.0 / 3.0)
        c[i] = f2 ** -3.0
    return t, c


@njit(cache=True)
def _field(kind, rad, xt, Rt, o0, o1, sgn, ops, lk, lr, px, py, pz, st):
    """phi and its world gradient at (px, py, pz) of one side of a contact: ``kind`` 0 an
    analytic sphere of radius ``rad`` centred at ``xt``; 1 the tree program rows [o0, o1)
    placed at ``xt`` with rotation ``Rt`` (tree -> world), its value times ``sgn``."""
    dx = px - xt[0]
    dy = py - xt[1]
    dz = pz - xt[2]
    if kind == 0:
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        if d > 0.0:
            return d - rad, dx / d, dy / d, dz / d
        return -rad, 1.0, 0.0, 0.0
    qx = Rt[0, 0] * dx + Rt[1, 0] * dy + Rt[2, 0] * dz
    qy = Rt[0, 1] * dx + Rt[1, 1] * dy + Rt[2, 1] * dz
    qz = Rt[0, 2] * dx + Rt[1, 2] * dy + Rt[2, 2] * dz
    phi, gx, gy, gz = eval_point(ops, lk, lr, o0, o1, qx, qy, qz, st)
    return (sgn * phi, sgn * (Rt[0, 0] * gx + Rt[0, 1] * gy + Rt[0, 2] * gz),
            sgn * (Rt[1, 0] * gx + Rt[1, 1] * gy + Rt[1, 2] * gz),
            sgn * (Rt[2, 0] * gx + Rt[2, 1] * gy + Rt[2, 2] * gz))


@njit(cache=True)
def _hessian(kind, rad, xt, Rt, o0, o1, sgn, ops, lk, lr, px, py, pz, h, st, H):
    """The Hessian (3, 3) of one side's phi at p into ``H``: closed form for a sphere,
    otherwise central differences (step ``h``) of the exact gradient, symmetrised."""
    if kind == 0:
        dx = px - xt[0]
        dy = py - xt[1]
        dz = pz - xt[2]
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        u = (dx / d, dy / d, dz / d)
        for r in range(3):
            for c in range(3):
                H[r, c] = ((1.0 if r == c else 0.0) - u[r] * u[c]) / d
        return
    for c in range(3):
        ex = h if c == 0 else 0.0
        ey = h if c == 1 else 0.0
        ez = h if c == 2 else 0.0
        _, p0, p1, p2 = _field(kind, rad, xt, Rt, o0, o1, sgn, ops, lk, lr, px + ex, py + ey,
                               pz + ez, st)
        _, m0, m1, m2 = _field(kind, rad, xt, Rt, o0, o1, sgn, ops, lk, lr, px - ex, py - ey,
                               pz - ez, st)
        H[0, c] = (p0 - m0) / (2.0 * h)
        H[1, c] = (p1 - m1) / (2.0 * h)
        H[2, c] = (p2 - m2) / (2.0 * h)
    for r in range(3):
        for c in range(r + 1, 3):
            s = 0.5 * (H[r, c] + H[c, r])
            H[r, c] = s
            H[c, r] = s


@njit(cache=True)
def _tangents(nx, ny, nz):
    """A unit basis (t1, t2) of the plane normal to the unit n (deterministic)."""
    ax, ay, az = abs(nx), abs(ny), abs(nz)
    if ax <= ay and ax <= az:
        ux, uy, uz = 0.0, -nz, ny
    elif ay <= az:
        ux, uy, uz = nz, 0.0, -nx
    else:
        ux, uy, uz = -ny, nx, 0.0
    un = math.sqrt(ux * ux + uy * uy + uz * uz)
    ux /= un
    uy /= un
    uz /= un
    vx, vy, vz = _cross(nx, ny, nz, ux, uy, uz)
    return ux, uy, uz, vx, vy, vz


@njit(cache=True)
def _tt(H, ux, uy, uz, vx, vy, vz):
    """u^T H v."""
    return (ux * (H[0, 0] * vx + H[0, 1] * vy + H[0, 2] * vz)
            + uy * (H[1, 0] * vx + H[1, 1] * vy + H[1, 2] * vz)
            + uz * (H[2, 0] * vx + H[2, 1] * vy + H[2, 2] * vz))


@njit(cache=True)
def _surface_curvature(H, gn, s, t):
    """The 2x2 curvature (k11, k12, k22) of a side's surface in the tangent basis ``t``
    (6,), from its Hessian ``H`` at a point at signed distance ``s`` from the surface with
    gradient norm ``gn``: the level set's shape operator P H P / |grad|, carried to the surface
    by the parallel-surface relation K_surface = K (I - s K)^-1 (exact for a distance field)."""
    k11 = _tt(H, t[0], t[1], t[2], t[0], t[1], t[2]) / gn
    k12 = _tt(H, t[0], t[1], t[2], t[3], t[4], t[5]) / gn
    k22 = _tt(H, t[3], t[4], t[5], t[3], t[4], t[5]) / gn
    a11 = 1.0 - s * k11
    a12 = -s * k12
    a22 = 1.0 - s * k22
    det = a11 * a22 - a12 * a12
    i11 = a22 / det
    i12 = -a12 / det
    i22 = a11 / det
    c11 = k11 * i11 + k12 * i12
    c12 = 0.5 * ((k11 * i12 + k12 * i22) + (k12 * i11 + k22 * i12))
    c22 = k12 * i12 + k22 * i22
    return c11, c12, c22


@njit(cache=True)
def _solve_patch(ka, rada, xa, Ra, oa0, oa1, kb, radb, xb, Rb, ob0, ob1, sb, ops, lk, lr,
                 scale, x0, y0, z0, ctab_t, ctab_c, st, Ha, Hb, out):
    """The contact of one patch between side a (a body: sphere or tree, sign +1) and side b (a
    body, or a wall with sign ``sb``), by Newton's method from (x0, y0, z0): the point where
    the two unit gradients are opposite and the two distance estimates phi/|grad phi| are
    equal (midway between the surfaces; for exact distance fields the stationary point of
    d_a + d_b on that mid-surface). Writes ``out`` = (point (3), normal from b to a (3), gap
    d_a + d_b, R* (the elliptical-Hertz radius), R' <= R'' the principal radii of relative
    curvature at the surfaces) and returns a status: PATCH_OK, PATCH_NO_CONVERGENCE,
    PATCH_NOT_CONVEX (the relative curvature is not positive definite) or PATCH_LINE (R''/R'
    beyond RATIO_LIMIT); ``out[6]`` always holds the gap at the last point evaluated."""
    h = FD_STEP * scale
    tol = PATCH_TOL * scale
    cap = 0.25 * scale
    x, y, z = x0, y0, z0
    t = np.empty(6)
    for it in range(PATCH_MAX_ITER):
        pa, gax, gay, gaz = _field(ka, rada, xa, Ra, oa0, oa1, 1.0, ops, lk, lr, x, y, z, st)
        pb, gbx, gby, gbz = _field(kb, radb, xb, Rb, ob0, ob1, sb, ops, lk, lr, x, y, z, st)
        na = math.sqrt(gax * gax + gay * gay + gaz * gaz)
        nb = math.sqrt(gbx * gbx + gby * gby + gbz * gbz)
        if not (na > 0.0 and nb > 0.0):
            out[6] = np.inf
            return PATCH_NO_CONVERGENCE
        da = pa / na
        db = pb / nb
        out[6] = da + db
        nx = gbx / nb - gax / na
        ny = gby / nb - gay / na
        nz = gbz / nb - gaz / na
        nn = math.sqrt(nx * nx + ny * ny + nz * nz)
        if not (nn > 0.0):
            return PATCH_NO_CONVERGENCE
        nx /= nn
        ny /= nn
        nz /= nn
        t[0], t[1], t[2], t[3], t[4], t[5] = _tangents(nx, ny, nz)
        _hessian(ka, rada, xa, Ra, oa0, oa1, 1.0, ops, lk, lr, x, y, z, h, st, Ha)
        _hessian(kb, radb, xb, Rb, ob0, ob1, sb, ops, lk, lr, x, y, z, h, st, Hb)
        m11 = (_tt(Ha, t[0], t[1], t[2], t[0], t[1], t[2]) / na
               + _tt(Hb, t[0], t[1], t[2], t[0], t[1], t[2]) / nb)
        m12 = (_tt(Ha, t[0], t[1], t[2], t[3], t[4], t[5]) / na
               + _tt(Hb, t[0], t[1], t[2], t[3], t[4], t[5]) / nb)
        m22 = (_tt(Ha, t[3], t[4], t[5], t[3], t[4], t[5]) / na
               + _tt(Hb, t[3], t[4], t[5], t[3], t[4], t[5]) / nb)
        det = m11 * m22 - m12 * m12
        if not (m11 > 0.0 and det > 0.0):
            return PATCH_NOT_CONVEX
        # tangential residual: the sum of the unit gradients (zero when they are opposite)
        sx = gax / na + gbx / nb
        sy = gay / na + gby / nb
        sz = gaz / na + gbz / nb
        r1 = t[0] * sx + t[1] * sy + t[2] * sz
        r2 = t[3] * sx + t[4] * sy + t[5] * sz
        a1 = -(m22 * r1 - m12 * r2) / det
        a2 = -(m11 * r2 - m12 * r1) / det
        s = (da - db) / nn                     # along n: equal distances (midway)
        dx = s * nx + a1 * t[0] + a2 * t[3]
        dy = s * ny + a1 * t[1] + a2 * t[4]
        dz = s * nz + a1 * t[2] + a2 * t[5]
        step = math.sqrt(dx * dx + dy * dy + dz * dz)
        if step <= tol:
            # converged at (x, y, z): the geometry of this evaluation
            c11, c12, c22 = _surface_curvature(Ha, na, da, t)
            e11, e12, e22 = _surface_curvature(Hb, nb, db, t)
            k11 = c11 + e11
            k12 = c12 + e12
            k22 = c22 + e22
            half = 0.5 * (k11 + k22)
            rad = math.sqrt(0.25 * (k11 - k22) ** 2 + k12 * k12)
            kmax = half + rad
            kmin = half - rad
            out[0], out[1], out[2] = x, y, z
            out[3], out[4], out[5] = nx, ny, nz
            if not (kmin > 0.0):
                return PATCH_NOT_CONVEX
            out[8] = 1.0 / kmax
            out[9] = 1.0 / kmin
            lam = kmax / kmin
            if not (lam <= RATIO_LIMIT):
                return PATCH_LINE
            # elliptical Hertz: R* = sqrt(R' R'') / F2^3, F2^-3 interpolated in ln(R''/R')
            tl = math.log(lam)
            nt = ctab_t.shape[0]
            f = tl / ctab_t[nt - 1] * (nt - 1)
            j = min(int(f), nt - 2)
            w = f - j
            out[7] = ((1.0 - w) * ctab_c[j] + w * ctab_c[j + 1]) / math.sqrt(kmax * kmin)
            return PATCH_OK
        if step > cap:
            dx *= cap / step
            dy *= cap / step
            dz *= cap / step
        x += dx
        y += dy
        z += dz
    return PATCH_NO_CONVERGENCE


@njit(cache=True)
def _side(body, shift, pos, rot, shape_of, shape_kind, shape_rad, shape_op, wall_op,
          wall_sign, wall_pos, wall_rot, xt):
    """One side of a contact: (kind, radius, rotation, program start, end, sign), its centre
    written into ``xt``; a body (b's image ``shift`` added) or, for body < 0, wall -1 - body."""
    if body >= 0:
        s = shape_of[body]
        for e in range(3):
            xt[e] = pos[body, e] + shift[e]
        return (shape_kind[s], shape_rad[s], rot[body], shape_op[s, 0], shape_op[s, 1], 1.0)
    w = -1 - body
    for e in range(3):
        xt[e] = wall_pos[w, e]
    return np.int64(1), np.inf, wall_rot[w], wall_op[w, 0], wall_op[w, 1], wall_sign[w]


@njit(cache=True)
def _sides(ia, ib, shift, pos, rot, shape_of, shape_kind, shape_rad, shape_op, wall_op,
           wall_sign, wall_pos, wall_rot, xa, xb):
    """Both sides of the contact of ``ia`` with ``ib`` (b's image ``shift``): :func:`_side`'s
    (kind, radius, rotation, program start, end) of a, then b's with its sign; the centres
    written into ``xa`` and ``xb``."""
    ka, rada, Ra, oa0, oa1, _ = _side(ia, np.zeros(3), pos, rot, shape_of, shape_kind,
                                      shape_rad, shape_op, wall_op, wall_sign, wall_pos,
                                      wall_rot, xa)
    kb, radb, Rb, ob0, ob1, sb = _side(ib, shift, pos, rot, shape_of, shape_kind, shape_rad,
                                       shape_op, wall_op, wall_sign, wall_pos, wall_rot, xb)
    return ka, rada, Ra, oa0, oa1, kb, radb, Rb, ob0, ob1, sb


@njit(cache=True)
def _patch_one(i, a, b, shift, mode, u, pos, rot, shape_of, shape_kind, shape_rad, shape_op,
               wall_op, wall_sign, wall_pos, wall_rot, ops, lk, lr, ctab_t, ctab_c, point,
               normal, gap, rstar, radii2, unew, status):
    """Patch i of :func:`patch_geometry` (writes only row i)."""
    st = np.empty((MAX_STACK, STACK_COLS))
    Ha = np.empty((3, 3))
    Hb = np.empty((3, 3))
    out = np.empty(10)
    xa = np.empty(3)
    xb = np.empty(3)
    ia = a[i]
    ib = b[i]
    ka, rada, Ra, oa0, oa1, kb, radb, Rb, ob0, ob1, sb = _sides(
        ia, ib, shift[i], pos, rot, shape_of, shape_kind, shape_rad, shape_op, wall_op, wall_sign,
        wall_pos, wall_rot, xa, xb)
    scale = min(rada, radb)
    # the tracked point: in a's home frame (mode 0, 1) or b's (mode 2)
    xo, Ro = (xb, Rb) if mode[i] == 2 else (xa, Ra)
    px = xo[0] + Ro[0, 0] * u[i, 0] + Ro[0, 1] * u[i, 1] + Ro[0, 2] * u[i, 2]
    py = xo[1] + Ro[1, 0] * u[i, 0] + Ro[1, 1] * u[i, 1] + Ro[1, 2] * u[i, 2]
    pz = xo[2] + Ro[2, 0] * u[i, 0] + Ro[2, 1] * u[i, 1] + Ro[2, 2] * u[i, 2]
    for e in range(3):
        unew[i, e] = u[i, e]
        point[i, e] = 0.0
        normal[i, e] = 0.0
    gap[i] = np.inf
    rstar[i] = 0.0
    radii2[i, 0] = 0.0
    radii2[i, 1] = 0.0
    status[i] = PATCH_OK
    if mode[i] != 0:
        # a seed whose patch solve failed: its probe (on a's surface, mode 1, or b's, mode 2)
        # must stay out of the other body
        if mode[i] == 1:
            ph, gx, gy, gz = _field(kb, radb, xb, Rb, ob0, ob1, sb, ops, lk, lr, px, py, pz, st)
        else:
            ph, gx, gy, gz = _field(ka, rada, xa, Ra, oa0, oa1, 1.0, ops, lk, lr, px, py, pz,
                                    st)
        if ph < 0.0:
            status[i] = PATCH_PROBE_INSIDE
        return
    res = _solve_patch(ka, rada, xa, Ra, oa0, oa1, kb, radb, xb, Rb, ob0, ob1, sb, ops, lk,
                       lr, scale, px, py, pz, ctab_t, ctab_c, st, Ha, Hb, out)
    if res != PATCH_OK:
        if out[6] < 0.0:
            status[i] = res                 # touching, and not a Hertz patch
        return
    for e in range(3):
        point[i, e] = out[e]
        normal[i, e] = out[3 + e]
    gap[i] = out[6]
    rstar[i] = out[7]
    radii2[i, 0] = out[8]
    radii2[i, 1] = out[9]
    if out[6] < 0.0 and -out[6] > DELTA_LIMIT * out[8]:
        status[i] = PATCH_DEEP
    dx = out[0] - xa[0]
    dy = out[1] - xa[1]
    dz = out[2] - xa[2]
    for e in range(3):
        unew[i, e] = Ra[0, e] * dx + Ra[1, e] * dy + Ra[2, e] * dz


@njit(cache=True)
def _patch_dedupe(first, a, b, shape_of, shape_rad, point, gap, status):
    """A patch whose solve ended on an earlier patch of its pair (``first[i]``: the pair's
    first row) is the same patch: its gap becomes +inf. Serial, in row order."""
    for i in range(a.shape[0]):
        if not (gap[i] < np.inf):
            continue
        scale = shape_rad[shape_of[a[i]]]
        if b[i] >= 0:
            scale = min(scale, shape_rad[shape_of[b[i]]])
        tol2 = (SAME_PATCH * scale) ** 2
        for j in range(first[i], i):
            if gap[j] < np.inf:
                d2 = 0.0
                for e in range(3):
                    d2 += (point[i, e] - point[j, e]) ** 2
                if d2 <= tol2:
                    gap[i] = np.inf
                    status[i] = PATCH_OK
                    break


@njit(cache=True)
def _patches_serial(a, b, shift, mode, u, pos, rot, shape_of, shape_kind, shape_rad,
                    shape_op, wall_op, wall_sign, wall_pos, wall_rot, ops, lk, lr, ctab_t,
                    ctab_c, point, normal, gap, rstar, radii2, unew, status):
    for i in range(a.shape[0]):
        _patch_one(i, a, b, shift, mode, u, pos, rot, shape_of, shape_kind, shape_rad,
                   shape_op, wall_op, wall_sign, wall_pos, wall_rot, ops, lk, lr, ctab_t,
                   ctab_c, point, normal, gap, rstar, radii2, unew, status)


@njit(cache=True, parallel=True)
def _patches_parallel(a, b, shift, mode, u, pos, rot, shape_of, shape_kind, shape_rad,
                      shape_op, wall_op, wall_sign, wall_pos, wall_rot, ops, lk, lr, ctab_t,
                      ctab_c, point, normal, gap, rstar, radii2, unew, status):
    for i in prange(a.shape[0]):
        _patch_one(i, a, b, shift, mode, u, pos, rot, shape_of, shape_kind, shape_rad,
                   shape_op, wall_op, wall_sign, wall_pos, wall_rot, ops, lk, lr, ctab_t,
                   ctab_c, point, normal, gap, rstar, radii2, unew, status)


#: Below this many patches the patch solves run serially (same bits either way).
PATCH_PARALLEL_MIN = 256


def patch_geometry(a, b, shift, mode, u, first, pos, rot, shape_of, geo):
    """The exact contact of every composed patch (rows of the candidate list's composed part),
    each solved by Newton's method from its tracked point ``u`` (a's home frame; b's for
    ``mode`` 2): returns (point (P, 3), normal (P, 3) from b to a, gap (P,), R* (P,), the
    principal radii of relative curvature (P, 2), the new tracked points (P, 3), status (P,)).
    A patch that does not touch has gap +inf; a status other than PATCH_OK marks a touching
    contact the law cannot represent. ``first`` (P,): each row's pair's first row."""
    n = len(a)
    point = np.empty((n, 3))
    normal = np.empty((n, 3))
    gap = np.empty(n)
    rstar = np.empty(n)
    radii2 = np.empty((n, 2))
    unew = np.empty((n, 3))
    status = np.empty(n, np.int64)
    ct, cc = elliptic_table()
    run = _patches_parallel if n >= PATCH_PARALLEL_MIN else _patches_serial
    run(a, b, shift, mode, u, pos, rot, shape_of, geo.shape_kind, geo.shape_rad, geo.shape_op,
        geo.wall_op, geo.wall_sign, geo.wall_pos, geo.wall_rot, geo.ops, geo.lk, geo.lr, ct, cc,
        point, normal, gap, rstar, radii2, unew, status)
    _patch_dedupe(first, a, b, shape_of, geo.shape_rad, point, gap, status)
    return point, normal, gap, rstar, radii2, unew, status


@njit(cache=True)
def _seed_pair(ia, ib, shift, det_pt, det_gap, margin, pos, rot, shape_of, shape_kind,
               shape_rad, shape_op, shape_p0, shape_np, probes, wall_op, wall_sign, wall_pos,
               wall_rot, ops, lk, lr, ctab_t, ctab_c, o_mode, o_u, o_probe):
    """The patches of one composed pair at a rebuild: seeds are the detection's points
    (``det_pt``, gaps ``det_gap``) and every probe of a (of b, when b is a composed body)
    within ``margin`` of the other side, taken deepest first; a seed outside the footprint
    of every patch found so far starts a patch solve, and a solve that ends on a known patch
    adds nothing. Writes per patch its mode (0 a patch, tracked in a's home frame; 1 / 2 the
    deepest seed whose solve failed, a probe of a / of b, tracked in that body's frame), ``o_u``
    and ``o_probe`` (the seed's probe index within its shape, -1 for a detection point).
    Returns the number of rows (MAX_PATCHES + 1: too many)."""
    st = np.empty((MAX_STACK, STACK_COLS))
    Ha = np.empty((3, 3))
    Hb = np.empty((3, 3))
    out = np.empty(10)
    xa = np.empty(3)
    xb = np.empty(3)
    ka, rada, Ra, oa0, oa1, kb, radb, Rb, ob0, ob1, sb = _sides(
        ia, ib, shift, pos, rot, shape_of, shape_kind, shape_rad, shape_op, wall_op, wall_sign,
        wall_pos, wall_rot, xa, xb)
    scale = min(rada, radb)
    na_p = shape_np[shape_of[ia]] if ka == 1 else 0
    nb_p = shape_np[shape_of[ib]] if (ib >= 0 and kb == 1) else 0
    nd = det_pt.shape[0]
    ns = nd + na_p + nb_p
    spt = np.empty((ns, 3))
    sdep = np.empty(ns)
    sside = np.empty(ns, np.int64)          # 0 detection point, 1 a's probe, 2 b's probe
    sprobe = np.empty(ns, np.int64)
    k = 0
    for j in range(nd):
        for e in range(3):
            spt[k, e] = det_pt[j, e]
        sdep[k] = det_gap[j]
        sside[k] = 0
        sprobe[k] = -1
        k += 1
    for side in range(1, 3):
        if side == 1:
            m, xo, Ro, p0 = na_p, xa, Ra, shape_p0[shape_of[ia]] if ka == 1 else 0
        else:
            m, xo, Ro, p0 = nb_p, xb, Rb, shape_p0[shape_of[ib]] if nb_p > 0 else 0
        for p in range(m):
            q = probes[p0 + p]
            px = xo[0] + Ro[0, 0] * q[0] + Ro[0, 1] * q[1] + Ro[0, 2] * q[2]
            py = xo[1] + Ro[1, 0] * q[0] + Ro[1, 1] * q[1] + Ro[1, 2] * q[2]
            pz = xo[2] + Ro[2, 0] * q[0] + Ro[2, 1] * q[1] + Ro[2, 2] * q[2]
            if side == 1:
                kt, rt, xt, Rt, t0, t1, sg = kb, radb, xb, Rb, ob0, ob1, sb
            else:
                kt, rt, xt, Rt, t0, t1, sg = ka, rada, xa, Ra, oa0, oa1, 1.0
            if rt < np.inf:
                d2 = (px - xt[0]) ** 2 + (py - xt[1]) ** 2 + (pz - xt[2]) ** 2
                if d2 > (rt + margin) ** 2:
                    continue
            ph, gx, gy, gz = _field(kt, rt, xt, Rt, t0, t1, sg, ops, lk, lr, px, py, pz, st)
            gn = math.sqrt(gx * gx + gy * gy + gz * gz)
            if not (gn > 0.0):
                continue
            d = ph / gn
            if not (d < margin):
                continue
            spt[k, 0] = px
            spt[k, 1] = py
            spt[k, 2] = pz
            sdep[k] = d
            sside[k] = side
            sprobe[k] = p
            k += 1
    order = np.argsort(sdep[:k], kind="mergesort")
    px_ = np.empty((MAX_PATCHES, 3))
    foot = np.empty(MAX_PATCHES)
    npatch = 0
    fail = -1
    tol2 = (SAME_PATCH * scale) ** 2
    for oi in range(k):
        s = order[oi]
        covered = False
        for j in range(npatch):
            d2 = 0.0
            for e in range(3):
                d2 += (spt[s, e] - px_[j, e]) ** 2
            if d2 <= foot[j] * foot[j]:
                covered = True
                break
        if covered:
            continue
        res = _solve_patch(ka, rada, xa, Ra, oa0, oa1, kb, radb, xb, Rb, ob0, ob1, sb, ops,
                           lk, lr, scale, spt[s, 0], spt[s, 1], spt[s, 2], ctab_t, ctab_c, st,
                           Ha, Hb, out)
        if res != PATCH_OK:
            if fail < 0 and sside[s] != 0:
                fail = s
            continue
        same = False
        for j in range(npatch):
            d2 = 0.0
            for e in range(3):
                d2 += (out[e] - px_[j, e]) ** 2
            if d2 <= tol2:
                same = True
                break
        if same:
            continue
        if npatch == MAX_PATCHES:
            return MAX_PATCHES + 1
        for e in range(3):
            px_[npatch, e] = out[e]
        # the seeds within margin of a paraboloid patch of smaller radius R'
        foot[npatch] = math.sqrt(2.0 * out[8] * max(margin - out[6], 0.0))
        dx = out[0] - xa[0]
        dy = out[1] - xa[1]
        dz = out[2] - xa[2]
        o_mode[npatch] = 0
        for e in range(3):
            o_u[npatch, e] = Ra[0, e] * dx + Ra[1, e] * dy + Ra[2, e] * dz
        o_probe[npatch] = sprobe[s]
        npatch += 1
    if fail >= 0:
        covered = False
        for j in range(npatch):
            d2 = 0.0
            for e in range(3):
                d2 += (spt[fail, e] - px_[j, e]) ** 2
            if d2 <= foot[j] * foot[j]:
                covered = True
        if not covered:
            if npatch == MAX_PATCHES:
                return MAX_PATCHES + 1
            side = sside[fail]
            o_mode[npatch] = side
            s0 = shape_of[ia] if side == 1 else shape_of[ib]
            for e in range(3):
                o_u[npatch, e] = probes[shape_p0[s0] + sprobe[fail], e]
            o_probe[npatch] = sprobe[fail]
            npatch += 1
    return npatch


@njit(cache=True)
def seed_patches(qa, qb, qshift, det_off, det_pt, det_gap, margin, pos, rot, shape_of,
                 shape_kind, shape_rad, shape_op, shape_p0, shape_np, probes, wall_op,
                 wall_sign, wall_pos, wall_rot, ops, lk, lr, ctab_t, ctab_c):
    """:func:`_seed_pair` for each composed pair (a ``qa[k]``, b ``qb[k]``, image ``qshift``;
    its detection points ``det_pt[det_off[k]:det_off[k + 1]]``): (count (Q,), mode (Q, MP),
    u (Q, MP, 3), probe (Q, MP)) with MP = MAX_PATCHES. Serial, in pair order."""
    nq = qa.shape[0]
    cnt = np.empty(nq, np.int64)
    mode = np.zeros((nq, MAX_PATCHES), np.int64)
    u = np.zeros((nq, MAX_PATCHES, 3))
    probe = np.full((nq, MAX_PATCHES), -1, np.int64)
    for k in range(nq):
        cnt[k] = _seed_pair(qa[k], qb[k], qshift[k], det_pt[det_off[k]:det_off[k + 1]],
                            det_gap[det_off[k]:det_off[k + 1]], margin, pos, rot, shape_of,
                            shape_kind, shape_rad, shape_op, shape_p0, shape_np, probes,
                            wall_op, wall_sign, wall_pos, wall_rot, ops, lk, lr, ctab_t,
                            ctab_c, mode[k], u[k], probe[k])
    return cnt, mode, u, probe


# --------------------------------------------------------------------------------------------
# composed particles: distributed contacts (flat, line, edge and corner contacts)
# --------------------------------------------------------------------------------------------

#: Nodes per axis of a distributed contact's sampling grid (the grid is zoomed onto the
#: overlap region, so this is the resolution across the region in each direction).
DIST_GRID = np.int64(24)
#: At most this many zooms of the sampling grid onto the overlap region.
DIST_ZOOMS = np.int64(8)
#: Bisection steps that place the region's boundary between an inside and an outside node.
DIST_BISECT = np.int64(8)
#: A distributed contact is refused when its largest overlap exceeds this fraction of the
#: smaller bounding radius of its bodies (the law assumes a shallow overlap).
DIST_DEEP_LIMIT = 0.1
#: The feature id of a pair's distributed contact (one per pair; its history key).
DIST_FEATURE = (1 << 26) - 1
#: Status of a distributed contact whose overlap is too deep (refused).
PATCH_DIST_DEEP = 7
#: Candidate mode of a pair that had too many patches at its rebuild: always distributed.
MODE_DISTRIBUTED = 3

_PATCH_REASONS[PATCH_DIST_DEEP] = (
    f"the distributed contact's overlap exceeds {DIST_DEEP_LIMIT} x the smaller bounding "
    "radius (far too soft, or dt far too large)")


@njit(cache=True)
def _midway(ka, rada, xa, Ra, oa0, oa1, kb, radb, xb, Rb, ob0, ob1, sb, ops, lk, lr, px, py,
            pz, nx, ny, nz, s0, scale, st):
    """Along the line p + s n (n from b to a): (m, s) with m = max(phi_a, phi_b) at the s where
    the two are equal (Newton from s0): m < 0 means the line passes through both bodies, and
    m bounds the distance from p + s n to their intersection (1-Lipschitz fields)."""
    s = s0
    tol = PATCH_TOL * scale
    cap = 0.25 * scale
    m = np.inf
    for _ in range(12):
        x = px + s * nx
        y = py + s * ny
        z = pz + s * nz
        pa, gax, gay, gaz = _field(ka, rada, xa, Ra, oa0, oa1, 1.0, ops, lk, lr, x, y, z, st)
        pb, gbx, gby, gbz = _field(kb, radb, xb, Rb, ob0, ob1, sb, ops, lk, lr, x, y, z, st)
        m = max(pa, pb)
        fp = (gax - gbx) * nx + (gay - gby) * ny + (gaz - gbz) * nz
        if not (fp < -0.25):
            fp = -1.0
        step = -(pa - pb) / fp
        if step > cap:
            step = cap
        elif step < -cap:
            step = -cap
        if abs(step) <= tol:
            break
        s += step
    return m, s


@njit(cache=True)
def _exit(kind, rad, xt, Rt, o0, o1, sgn, ops, lk, lr, px, py, pz, nx, ny, nz, s0, direction,
          scale, st):
    """From p + s0 n inside the side, the s where its surface is crossed moving along
    ``direction`` * n (Newton on phi along the line, steps at least the sphere-tracing bound)."""
    s = s0
    tol = PATCH_TOL * scale
    for _ in range(30):
        ph, gx, gy, gz = _field(kind, rad, xt, Rt, o0, o1, sgn, ops, lk, lr, px + s * nx,
                                py + s * ny, pz + s * nz, st)
        d = direction * (gx * nx + gy * ny + gz * nz)       # d phi / d(distance moved)
        step = -ph / d if d > 0.2 else -ph      # Newton; at grazing incidence a safe |phi|
        if abs(step) <= tol:
            break
        s += direction * step
    return s


@njit(cache=True)
def _agm_ellipk(m):
    """Complete elliptic integral of the first kind K(m), m = e^2 in [0, 1)."""
    a = 1.0
    b = math.sqrt(1.0 - m)
    for _ in range(40):
        if abs(a - b) <= 1e-15 * a:
            break
        a, b = 0.5 * (a + b), math.sqrt(a * b)
    return 0.5 * math.pi / a


@njit(cache=True)
def _grid_eval(ka, rada, xa, Ra, oa0, oa1, kb, radb, xb, Rb, ob0, ob1, sb, ops, lk, lr, c,
               u1, u2, w1, w2, n, N, scale, st, gm, gs, gx):
    """m and s of :func:`_midway` at the N x N cell centres of the box c +- w1 u1 +- w2 u2;
    node positions into gx (N, N, 3)."""
    for i in range(N):
        a1 = ((2.0 * i + 1.0) / N - 1.0) * w1
        for j in range(N):
            a2 = ((2.0 * j + 1.0) / N - 1.0) * w2
            for e in range(3):
                gx[i, j, e] = c[e] + a1 * u1[e] + a2 * u2[e]
            m, s = _midway(ka, rada, xa, Ra, oa0, oa1, kb, radb, xb, Rb, ob0, ob1, sb, ops,
                           lk, lr, gx[i, j, 0], gx[i, j, 1], gx[i, j, 2], n[0], n[1], n[2],
                           0.0, scale, st)
            gm[i, j] = m
            gs[i, j] = s


#: A distributed contact's second normal candidate differs from the first by more than this
#: angle (rad).
DIST_DISTINCT = math.radians(30.0)
#: The fallback search's grid is this many times finer.
DIST_FALLBACK = 4
#: _dist_region's status when its search ended without an overlap it could rule out.
_DIST_UNRESOLVED = -1


@njit(cache=True)
def _nearest_probe(ka, rada, xa, Ra, oa0, oa1, kb, radb, xb, Rb, ob0, ob1, sb, ops, lk, lr,
                   pa0, pa1, pb0, pb1, probes, scale, st, excl, cmax, n, y0):
    """The deepest probe (of a in b, or of b in a; the smallest phi / |grad phi| in the other
    body, +inf when no probe is in reach, returned) with the other body's outward unit
    normal there (from b to a) into ``n`` and the probe into ``y0``; with ``excl`` only
    among the probes whose normal has a cosine below ``cmax`` with ``n``'s incoming value."""
    best = np.inf
    e0, e1, e2 = n[0], n[1], n[2]
    for side in range(2):
        p0, p1 = (pa0, pa1) if side == 0 else (pb0, pb1)
        xo, Ro = (xa, Ra) if side == 0 else (xb, Rb)
        for p in range(p0, p1):
            q = probes[p]
            px = xo[0] + Ro[0, 0] * q[0] + Ro[0, 1] * q[1] + Ro[0, 2] * q[2]
            py = xo[1] + Ro[1, 0] * q[0] + Ro[1, 1] * q[1] + Ro[1, 2] * q[2]
            pz = xo[2] + Ro[2, 0] * q[0] + Ro[2, 1] * q[1] + Ro[2, 2] * q[2]
            if side == 0:
                if radb < np.inf and ((px - xb[0]) ** 2 + (py - xb[1]) ** 2
                                      + (pz - xb[2]) ** 2) > (radb + scale) ** 2:
                    continue
                ph, gx, gy, gz = _field(kb, radb, xb, Rb, ob0, ob1, sb, ops, lk, lr, px, py,
                                        pz, st)
                sg = 1.0
            else:
                if ((px - xa[0]) ** 2 + (py - xa[1]) ** 2 + (pz - xa[2]) ** 2) \
                        > (rada + scale) ** 2:
                    continue
                ph, gx, gy, gz = _field(ka, rada, xa, Ra, oa0, oa1, 1.0, ops, lk, lr, px, py,
                                        pz, st)
                sg = -1.0
            gn = math.sqrt(gx * gx + gy * gy + gz * gz)
            if not (gn > 0.0):
                continue
            d = ph / gn
            if d < best:
                if excl and sg * (gx * e0 + gy * e1 + gz * e2) / gn >= cmax:
                    continue
                best = d
                n[0], n[1], n[2] = sg * gx / gn, sg * gy / gn, sg * gz / gn
                y0[0], y0[1], y0[2] = px, py, pz
    return best


@njit(cache=True)
def _dist_pair(ka, rada, xa, Ra, oa0, oa1, kb, radb, xb, Rb, ob0, ob1, sb, ops, lk, lr,
               pa0, pa1, pb0, pb1, probes, N, zooms, nbis, estar, touched, out):
    """The distributed contact of one pair (module docstring, "Distributed"): writes ``out``
    = (point (3), normal from b to a (3), largest overlap, elastic force, stiffness S = k A,
    area A, overlap volume V, equivalent ellipse semi-axes a, b) and returns PATCH_OK (force 0
    when nothing overlaps) or PATCH_DIST_DEEP. Probes [pa0, pa1) are a's (home frame),
    [pb0, pb1) b's; they only fix the normal (the deepest one's, the other body's outward
    normal there). ``touched``: the pair's distributed contact touched in the last substep
    (it then gets the fallback search of the module docstring when nothing is found)."""
    st = np.empty((MAX_STACK, STACK_COLS))
    for e in range(out.shape[0]):
        out[e] = 0.0
    scale = min(rada, radb)
    n = np.zeros(3)
    y0 = np.zeros(3)
    best = _nearest_probe(ka, rada, xa, Ra, oa0, oa1, kb, radb, xb, Rb, ob0, ob1, sb, ops, lk,
                          lr, pa0, pa1, pb0, pb1, probes, scale, st, False, 1.0, n, y0)
    if best == np.inf:
        return PATCH_OK
    res = _dist_region(ka, rada, xa, Ra, oa0, oa1, kb, radb, xb, Rb, ob0, ob1, sb, ops, lk, lr,
                       N, zooms, nbis, estar, scale, st, n, y0, out)
    if res != _DIST_UNRESOLVED:
        return res
    # Neither found nor ruled out. Where two bodies' rims or edges cross, the overlap (0.2-0.5
    # mm in a ring bed, against the grid's 1.2 mm cells) lies between the probes, the nearest
    # probe outside it sets the normal, and the region can fall between the nodes at every
    # zoom: a pair carrying 8 N lost it for 17 substeps and was found again deeper. Tried in
    # turn: the nearest probe with a normal more than DIST_DISTINCT from the first's, and, for
    # a contact that touched a substep ago, both normals on a grid DIST_FALLBACK times finer;
    # of the first two that find the overlap the shorter one is kept (the direction of least
    # penetration: along the other normal an overlap read 0.5 mm against 0.27 mm).
    n2 = n.copy()
    y2 = np.zeros(3)
    best2 = _nearest_probe(ka, rada, xa, Ra, oa0, oa1, kb, radb, xb, Rb, ob0, ob1, sb, ops, lk,
                           lr, pa0, pa1, pb0, pb1, probes, scale, st, True,
                           math.cos(DIST_DISTINCT), n2, y2)
    alt = np.empty(out.shape[0])
    found = 0
    res = PATCH_OK
    for k in range(3):
        # k = 0: the second normal; 1, 2: the first and the second on the finer grid
        if (k != 1 and best2 == np.inf) or (k > 0 and not touched):
            continue
        nk, yk = (n, y0) if k == 1 else (n2, y2)
        r = _dist_region(ka, rada, xa, Ra, oa0, oa1, kb, radb, xb, Rb, ob0, ob1, sb, ops, lk,
                         lr, N if k == 0 else DIST_FALLBACK * N, zooms, nbis, estar, scale, st,
                         nk, yk, alt)
        if r == _DIST_UNRESOLVED:
            continue
        if found == 0 or alt[6] < out[6]:
            for e in range(out.shape[0]):
                out[e] = alt[e]
            res = r
        found += 1
        if found == 2:
            break
    return res


@njit(cache=True)
def _dist_region(ka, rada, xa, Ra, oa0, oa1, kb, radb, xb, Rb, ob0, ob1, sb, ops, lk, lr, N,
                 zooms, nbis, estar, scale, st, n, y0, out):
    """The region, overlap and law of :func:`_dist_pair` along the unit normal ``n`` (from b
    to a) through the probe ``y0``: writes ``out`` and returns PATCH_OK (force 0: nothing
    overlaps anywhere, a rigorous bound on the first, whole box), _DIST_UNRESOLVED (force 0:
    no overlap found, none ruled out) or PATCH_DIST_DEEP."""
    for e in range(out.shape[0]):
        out[e] = 0.0
    out[3], out[4], out[5] = n[0], n[1], n[2]
    # ---- grid box: the smaller side's bounding disc, in the plane through y0
    xs = xa if rada <= radb else xb
    c = np.empty(3)
    dn = (xs[0] - y0[0]) * n[0] + (xs[1] - y0[1]) * n[1] + (xs[2] - y0[2]) * n[2]
    for e in range(3):
        c[e] = xs[e] - dn * n[e]
    t1x, t1y, t1z, t2x, t2y, t2z = _tangents(n[0], n[1], n[2])
    u1 = np.array([t1x, t1y, t1z])
    u2 = np.array([t2x, t2y, t2z])
    w1 = scale
    w2 = scale
    gm = np.empty((N, N))
    gs = np.empty((N, N))
    gx_ = np.empty((N, N, 3))
    ok = False
    NF = N
    for it in range(zooms):
        # a coarse first look (its rigorous bound settles most pairs that do not overlap)
        N = min(np.int64(8), NF) if it == 0 else NF
        _grid_eval(ka, rada, xa, Ra, oa0, oa1, kb, radb, xb, Rb, ob0, ob1, sb, ops, lk, lr, c,
                   u1, u2, w1, w2, n, N, scale, st, gm, gs, gx_)
        h1 = 2.0 * w1 / N
        h2 = 2.0 * w2 / N
        hd = 0.5 * math.sqrt(h1 * h1 + h2 * h2)
        # inside nodes: their in-plane coordinates, moments
        cnt = 0
        s1 = 0.0
        s2 = 0.0
        border = False
        border1 = False
        border2 = False
        imin = 0
        jmin = 0
        for i in range(N):
            for j in range(N):
                if gm[i, j] < gm[imin, jmin]:
                    imin, jmin = i, j
                if gm[i, j] < 0.0:
                    cnt += 1
                    s1 += ((2.0 * i + 1.0) / N - 1.0) * w1
                    s2 += ((2.0 * j + 1.0) / N - 1.0) * w2
                    if i == 0 or i == N - 1:
                        border1 = True
                    if j == 0 or j == N - 1:
                        border2 = True
                    border = border1 or border2
        if cnt == 0:
            if gm[imin, jmin] > hd:
                # nothing within reach: no overlap, a rigorous bound on the first (whole) box
                # only; after a zoom it is the zoomed box's
                return PATCH_OK if it == 0 else _DIST_UNRESOLVED
            # quadratic model of m on the 3 x 3 nodes around the smallest: jump to its minimum
            i0 = min(max(imin, 1), N - 2)
            j0 = min(max(jmin, 1), N - 2)
            f0 = gm[i0, j0]
            g1 = 0.5 * (gm[i0 + 1, j0] - gm[i0 - 1, j0])
            g2 = 0.5 * (gm[i0, j0 + 1] - gm[i0, j0 - 1])
            h11 = gm[i0 + 1, j0] - 2.0 * f0 + gm[i0 - 1, j0]
            h22 = gm[i0, j0 + 1] - 2.0 * f0 + gm[i0, j0 - 1]
            h12 = 0.25 * (gm[i0 + 1, j0 + 1] - gm[i0 + 1, j0 - 1] - gm[i0 - 1, j0 + 1]
                          + gm[i0 - 1, j0 - 1])
            # eigen-directions of the 2 x 2 model Hessian (in grid units)
            half = 0.5 * (h11 + h22)
            rad_ = math.sqrt(0.25 * (h11 - h22) ** 2 + h12 * h12)
            lam1 = half + rad_
            lam2 = half - rad_
            if abs(h12) > 1e-300:
                e1x, e1y = lam1 - h22, h12
            elif h11 >= h22:
                e1x, e1y = 1.0, 0.0
            else:
                e1x, e1y = 0.0, 1.0
            en = math.sqrt(e1x * e1x + e1y * e1y)
            e1x /= en
            e1y /= en
            e2x, e2y = -e1y, e1x
            d1 = 0.0
            d2 = 0.0
            ga = g1 * e1x + g2 * e1y
            gb = g1 * e2x + g2 * e2y
            if lam1 > 0.0:
                d1 = min(max(-ga / lam1, -1.5), 1.5)
            if lam2 > 0.0:
                d2 = min(max(-gb / lam2, -1.5), 1.5)
            di = d1 * e1x + d2 * e2x
            dj = d1 * e1y + d2 * e2y
            a1 = ((2.0 * i0 + 1.0) / N - 1.0) * w1 + di * h1
            a2 = ((2.0 * j0 + 1.0) / N - 1.0) * w2 + dj * h2
            if lam1 > 0.0 and lam2 <= 0.05 * lam1:
                # line-like (flat along e2): the next grid's axes along and across the line,
                # a row of nodes through the model's minimum, the extent along it kept
                v1 = np.empty(3)
                v2 = np.empty(3)
                for e in range(3):
                    v1[e] = e2x * h1 * u1[e] + e2y * h2 * u2[e]     # along
                    v2[e] = e1x * h1 * u1[e] + e1y * h2 * u2[e]     # across
                l1 = math.sqrt(v1[0] ** 2 + v1[1] ** 2 + v1[2] ** 2)
                for e in range(3):
                    v1[e] /= l1
                dd = v1[0] * v2[0] + v1[1] * v2[1] + v1[2] * v2[2]
                for e in range(3):
                    v2[e] -= dd * v1[e]
                l2 = math.sqrt(v2[0] ** 2 + v2[1] ** 2 + v2[2] ** 2)
                for e in range(3):
                    v2[e] /= l2
                off = 0.0
                for e in range(3):
                    off += (a1 * u1[e] + a2 * u2[e]) * v2[e]
                wmax = max(w1, w2)
                for e in range(3):
                    c[e] += (off + wmax / NF) * v2[e]
                    u1[e] = v1[e]
                    u2[e] = v2[e]
                w1 = wmax
                w2 = wmax
                continue
            # shift the next (full) grid so that a node lies on the model's minimum: a small
            # region between the nodes is then seen
            k1 = min(max(int(round((a1 / w1 + 1.0) * 0.5 * NF - 0.5)), 0), NF - 1)
            k2 = min(max(int(round((a2 / w2 + 1.0) * 0.5 * NF - 0.5)), 0), NF - 1)
            b1 = a1 - ((2.0 * k1 + 1.0) / NF - 1.0) * w1
            b2 = a2 - ((2.0 * k2 + 1.0) / NF - 1.0) * w2
            for e in range(3):
                c[e] += b1 * u1[e] + b2 * u2[e]
            continue
        # inside nodes exist: principal axes of their positions, the box around them
        m1 = s1 / cnt
        m2 = s2 / cnt
        j11 = 0.0
        j12 = 0.0
        j22 = 0.0
        for i in range(N):
            for j in range(N):
                if gm[i, j] < 0.0:
                    q1 = ((2.0 * i + 1.0) / N - 1.0) * w1 - m1
                    q2 = ((2.0 * j + 1.0) / N - 1.0) * w2 - m2
                    j11 += q1 * q1
                    j12 += q1 * q2
                    j22 += q2 * q2
        j11 += cnt * h1 * h1 / 12.0
        j22 += cnt * h2 * h2 / 12.0
        half = 0.5 * (j11 + j22)
        rad_ = math.sqrt(0.25 * (j11 - j22) ** 2 + j12 * j12)
        lam1 = half + rad_
        lam2 = half - rad_
        if lam1 > 1.5 * lam2 and abs(j12) > 1e-12 * lam1:
            e1x, e1y = lam1 - j22, j12
            en = math.sqrt(e1x * e1x + e1y * e1y)
            e1x /= en
            e1y /= en
        else:
            e1x, e1y = 1.0, 0.0                    # keep the current axes
        e2x, e2y = -e1y, e1x
        lo1 = np.inf
        hi1 = -np.inf
        lo2 = np.inf
        hi2 = -np.inf
        for i in range(N):
            for j in range(N):
                if gm[i, j] < 0.0:
                    q1 = ((2.0 * i + 1.0) / N - 1.0) * w1
                    q2 = ((2.0 * j + 1.0) / N - 1.0) * w2
                    r1 = q1 * e1x + q2 * e1y
                    r2 = q1 * e2x + q2 * e2y
                    lo1 = min(lo1, r1)
                    hi1 = max(hi1, r1)
                    lo2 = min(lo2, r2)
                    hi2 = max(hi2, r2)
        mg1 = abs(e1x) * h1 + abs(e1y) * h2
        mg2 = abs(e2x) * h1 + abs(e2y) * h2
        nw1 = 0.5 * (hi1 - lo1) + mg1
        nw2 = 0.5 * (hi2 - lo2) + mg2
        same_axes = e1x == 1.0 and e1y == 0.0
        if same_axes:
            # the overlap reaches the grid's edge: widen that way
            if border1:
                nw1 = max(nw1, 1.5 * w1)
            if border2:
                nw2 = max(nw2, 1.5 * w2)
        if not border and same_axes and nw1 >= 0.7 * w1 and nw2 >= 0.7 * w2 and N == NF:
            ok = True
            break
        if it == zooms - 1:
            ok = not border
            break
        if N != NF and not border and same_axes and nw1 >= 0.7 * w1 and nw2 >= 0.7 * w2:
            continue                               # the same box, now at full resolution
        cc1 = 0.5 * (lo1 + hi1)
        cc2 = 0.5 * (lo2 + hi2)
        v1 = np.empty(3)
        v2 = np.empty(3)
        for e in range(3):
            c[e] = c[e] + (cc1 * e1x + cc2 * e2x) * u1[e] + (cc1 * e1y + cc2 * e2y) * u2[e]
            v1[e] = e1x * u1[e] + e1y * u2[e]
            v2[e] = e2x * u1[e] + e2y * u2[e]
        for e in range(3):
            u1[e] = v1[e]
            u2[e] = v2[e]
        w1 = nw1
        w2 = nw2
    if not ok:
        # the zooms ran out with the overlap on the grid's border or never resolved: sample
        # what the last grid holds (a coarse estimate, documented)
        pass
    # ---- integrate over the last grid: inside cells, their extents to the boundary
    h1 = 2.0 * w1 / N
    h2 = 2.0 * w2 / N
    A = 0.0
    V = 0.0
    cA1 = 0.0
    cA2 = 0.0
    cV1 = 0.0
    cV2 = 0.0
    cVs = 0.0
    J11 = 0.0
    J12 = 0.0
    J22 = 0.0
    dmax = 0.0
    ext = np.empty(4)
    for i in range(N):
        for j in range(N):
            if not (gm[i, j] < 0.0):
                continue
            # the chord of the intersection along n through the node
            px, py, pz = gx_[i, j, 0], gx_[i, j, 1], gx_[i, j, 2]
            s_a = _exit(ka, rada, xa, Ra, oa0, oa1, 1.0, ops, lk, lr, px, py, pz, n[0], n[1],
                        n[2], gs[i, j], -1.0, scale, st)
            s_b = _exit(kb, radb, xb, Rb, ob0, ob1, sb, ops, lk, lr, px, py, pz, n[0], n[1],
                        n[2], gs[i, j], 1.0, scale, st)
            d = s_b - s_a
            if not (d > 0.0):
                continue
            for k in range(4):
                di = (1, -1, 0, 0)[k]
                dj = (0, 0, 1, -1)[k]
                hh = h1 if k < 2 else h2
                ii = i + di
                jj = j + dj
                if ii < 0 or jj < 0 or ii >= N or jj >= N:
                    ext[k] = 0.5 * hh
                    continue
                if gm[ii, jj] < 0.0:
                    ext[k] = 0.5 * hh
                    continue
                # bisect the boundary on the segment to the outside neighbour
                lo_ = 0.0
                hi_ = 1.0
                sg = gs[i, j]
                for _ in range(nbis):
                    t = 0.5 * (lo_ + hi_)
                    qx = px + t * (gx_[ii, jj, 0] - px)
                    qy = py + t * (gx_[ii, jj, 1] - py)
                    qz = pz + t * (gx_[ii, jj, 2] - pz)
                    mq, sq = _midway(ka, rada, xa, Ra, oa0, oa1, kb, radb, xb, Rb, ob0, ob1,
                                     sb, ops, lk, lr, qx, qy, qz, n[0], n[1], n[2], sg, scale,
                                     st)
                    if mq < 0.0:
                        lo_ = t
                        sg = sq
                    else:
                        hi_ = t
                ext[k] = 0.5 * (lo_ + hi_) * hh
            l1 = ext[0] + ext[1]
            l2 = ext[2] + ext[3]
            w = l1 * l2
            q1 = ((2.0 * i + 1.0) / N - 1.0) * w1 + 0.5 * (ext[0] - ext[1])
            q2 = ((2.0 * j + 1.0) / N - 1.0) * w2 + 0.5 * (ext[2] - ext[3])
            A += w
            V += w * d
            cA1 += w * q1
            cA2 += w * q2
            cV1 += w * d * q1
            cV2 += w * d * q2
            cVs += w * d * 0.5 * (s_a + s_b)
            J11 += w * (q1 * q1 + l1 * l1 / 12.0)
            J12 += w * q1 * q2
            J22 += w * (q2 * q2 + l2 * l2 / 12.0)
            dmax = max(dmax, d)
    if not (V > 0.0):
        return _DIST_UNRESOLVED
    a1 = cA1 / A
    a2 = cA2 / A
    J11 -= A * a1 * a1
    J12 -= A * a1 * a2
    J22 -= A * a2 * a2
    half = 0.5 * (J11 + J22)
    rad_ = math.sqrt(0.25 * (J11 - J22) ** 2 + J12 * J12)
    lam1 = half + rad_
    lam2 = max(half - rad_, 1e-300)
    r = math.sqrt(lam1 / lam2)
    ea = math.sqrt(A * r / math.pi)            # the equal-area ellipse of the region's shape
    eb = A / (math.pi * ea)
    kk = _agm_ellipk(1.0 - 1.0 / (r * r))
    k = math.pi * ea * estar / (kk * A)        # pressure per unit overlap
    q1 = cV1 / V
    q2 = cV2 / V
    qs = cVs / V
    for e in range(3):
        out[e] = c[e] + q1 * u1[e] + q2 * u2[e] + qs * n[e]
    out[6] = dmax
    out[7] = k * V
    out[8] = k * A
    out[9] = A
    out[10] = V
    out[11] = ea
    out[12] = eb
    if dmax > DIST_DEEP_LIMIT * scale:
        return PATCH_DIST_DEEP
    return PATCH_OK


@njit(cache=True)
def _dist_one(i, a, b, shift, pos, rot, shape_of, shape_kind, shape_rad, shape_op, shape_p0,
              shape_np, probes, wall_op, wall_sign, wall_pos, wall_rot, ops, lk, lr, estar,
              touched, N, zooms, nbis, out, status):
    """Distributed contact i of :func:`distributed_geometry` (writes only row i)."""
    xa = np.empty(3)
    xb = np.empty(3)
    ia = a[i]
    ib = b[i]
    ka, rada, Ra, oa0, oa1, kb, radb, Rb, ob0, ob1, sb = _sides(
        ia, ib, shift[i], pos, rot, shape_of, shape_kind, shape_rad, shape_op, wall_op, wall_sign,
        wall_pos, wall_rot, xa, xb)
    pa0 = pa1 = pb0 = pb1 = 0
    if ka == 1:
        pa0 = shape_p0[shape_of[ia]]
        pa1 = pa0 + shape_np[shape_of[ia]]
    if ib >= 0 and kb == 1:
        pb0 = shape_p0[shape_of[ib]]
        pb1 = pb0 + shape_np[shape_of[ib]]
    status[i] = _dist_pair(ka, rada, xa, Ra, oa0, oa1, kb, radb, xb, Rb, ob0, ob1, sb, ops, lk,
                           lr, pa0, pa1, pb0, pb1, probes, N, zooms, nbis, estar[i],
                           touched[i] != 0, out[i])


@njit(cache=True)
def _dist_serial(a, b, shift, pos, rot, shape_of, shape_kind, shape_rad, shape_op, shape_p0,
                 shape_np, probes, wall_op, wall_sign, wall_pos, wall_rot, ops, lk, lr, estar,
                 touched, N, zooms, nbis, out, status):
    for i in range(a.shape[0]):
        _dist_one(i, a, b, shift, pos, rot, shape_of, shape_kind, shape_rad, shape_op,
                  shape_p0, shape_np, probes, wall_op, wall_sign, wall_pos, wall_rot, ops, lk,
                  lr, estar, touched, N, zooms, nbis, out, status)


@njit(cache=True, parallel=True)
def _dist_parallel(a, b, shift, pos, rot, shape_of, shape_kind, shape_rad, shape_op, shape_p0,
                   shape_np, probes, wall_op, wall_sign, wall_pos, wall_rot, ops, lk, lr,
                   estar, touched, N, zooms, nbis, out, status):
    for i in prange(a.shape[0]):
        _dist_one(i, a, b, shift, pos, rot, shape_of, shape_kind, shape_rad, shape_op,
                  shape_p0, shape_np, probes, wall_op, wall_sign, wall_pos, wall_rot, ops, lk,
                  lr, estar, touched, N, zooms, nbis, out, status)


#: Below this many distributed contacts they are computed serially (same bits either way).
DIST_PARALLEL_MIN = 4


def distributed_geometry(a, b, shift, pos, rot, shape_of, geo, estar, touched=None):
    """The distributed contact of each pair (a[i], b[i] at image shift[i]; E* per pair):
    (out (P, 13): point (3), normal (3), largest overlap, elastic force, stiffness S, area,
    overlap volume, ellipse semi-axes; status (P,)). A pair with nothing overlapping has
    force 0. ``touched`` (P,) bool: the pair's distributed contact touched in the last
    substep (the fallback search; None: none did)."""
    n = len(a)
    touched = np.zeros(n, np.int64) if touched is None else np.asarray(touched, np.int64)
    out = np.zeros((n, 13))
    status = np.zeros(n, np.int64)
    nps = np.diff(np.append(geo.shape_p0, len(geo.probes))).astype(np.int64)
    run = _dist_parallel if n >= DIST_PARALLEL_MIN else _dist_serial
    run(np.asarray(a, np.int64), np.asarray(b, np.int64), np.ascontiguousarray(shift), pos, rot,
        shape_of, geo.shape_kind, geo.shape_rad, geo.shape_op, geo.shape_p0, nps, geo.probes,
        geo.wall_op, geo.wall_sign, geo.wall_pos, geo.wall_rot, geo.ops, geo.lk, geo.lr,
        np.ascontiguousarray(estar, dtype=np.float64), touched, np.int64(DIST_GRID),
        np.int64(DIST_ZOOMS), np.int64(DIST_BISECT), out, status)
    return out, status


@lru_cache(maxsize=4096)
def damping_gamma_linear(e):
    """:func:`damping_gamma` for a distributed contact: the ``gamma`` with which the clamped
    linear law ``F = S delta + gamma sqrt(S m*) delta'`` (S constant) rebounds at ``e``."""
    e = check_float("e_n", e, E_MIN, 1.0)
    if e == 1.0:
        return 0.0
    from scipy.optimize import brentq

    def rest(g):
        return float(rebound_speed(g, _CAL_STEP, True))
    hi = 1.0
    while rest(hi) > e:
        hi *= 2.0
    return float(brentq(lambda g: rest(g) - e, 0.0, hi, xtol=1e-14, rtol=1e-12))


# --------------------------------------------------------------------------------------------
# per-simulation state
# --------------------------------------------------------------------------------------------

class HertzState:
    """The Hertz engine's state in a Simulation: moduli per material id, rolling friction per
    pair of material ids, and the contact histories (``keys`` (K,) sorted int64, ``xi`` (K, 3)
    the tangential displacement and ``mr`` (K, 3) the rolling spring torque, world frame, for
    ``n_bodies`` bodies)."""

    def __init__(self):
        self.moduli = {}                       # material id -> (E, nu)
        self.rolling = {}                      # (i, j), i <= j, or None (every pair) -> mu_r
        self.keys = np.zeros(0, np.int64)
        self.xi = np.zeros((0, 3))
        self.mr = np.zeros((0, 3))
        self.n_bodies = -1
        self.last = None                       # the last substep's contacts and forces
        self.cand = None                       # the candidate list (see substep)
        self.spacing = None                    # (geometry, probe spacing per shape)
        self.dist_last = None                  # the last distributed contacts' details

    def set_material(self, material_id, youngs, poisson):
        """Young's modulus ``youngs`` (> 0, finite; pressure units) and Poisson ratio
        ``poisson`` in (-1, 0.5) of material id ``material_id`` in [0, 1023]."""
        mid = check_int("material_id", material_id, 0, MAX_MATERIAL_ID)
        e = check_float("youngs", youngs, 0.0, lo_open=True)
        nu = check_float("poisson", poisson, -1.0, 0.5, lo_open=True, hi_open=True)
        self.moduli[mid] = (e, nu)

    def set_rolling(self, mu_r, material_a=None, material_b=None):
        """Rolling friction ``mu_r`` in [0, MU_R_MAX] for the pair of material ids
        (``material_a``, ``material_b``), or for every pair not declared when both are None."""
        mu_r = check_float("mu_r", mu_r, 0.0, MU_R_MAX)
        if (material_a is None) != (material_b is None):
            raise PecletArgumentError("material_b" if material_b is None else "material_a",
                                      "given together with the other material id (a pair), "
                                      "or both None (every pair)", None)
        if material_a is None:
            self.rolling[None] = mu_r
            return
        ia = check_int("material_a", material_a, 0, MAX_MATERIAL_ID)
        ib = check_int("material_b", material_b, 0, MAX_MATERIAL_ID)
        self.rolling[(min(ia, ib), max(ia, ib))] = mu_r

    def rolling_active(self):
        return any(v > 0.0 for v in self.rolling.values())

    def snapshot(self):
        """What a refused substep puts back (:meth:`restore`): histories and candidates."""
        return (self.keys, self.xi, self.mr, self.cand)

    def restore(self, kept):
        self.keys, self.xi, self.mr, self.cand = kept

    def clear_history(self):
        self.keys = np.zeros(0, np.int64)
        self.xi = np.zeros((0, 3))
        self.mr = np.zeros((0, 3))

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

    def lookup_rolling(self, keys):
        """The stored rolling spring torque (nc, 3) of each key, zero for a new contact."""
        out = np.zeros((len(keys), 3))
        if len(keys) and len(self.keys):
            j = np.minimum(np.searchsorted(self.keys, keys), len(self.keys) - 1)
            hit = self.keys[j] == keys
            out[hit] = self.mr[j[hit]]
        return out

    def store(self, keys, xi, touching, n_bodies, mr=None):
        o = np.argsort(keys[touching], kind="stable")
        self.keys = keys[touching][o]
        self.xi = xi[touching][o]
        self.mr = mr[touching][o] if mr is not None else np.zeros((len(self.keys), 3))
        self.n_bodies = n_bodies

    def arrays(self):
        """(moduli (M, 3) rows id, E, nu; keys; xi; n_bodies) for a save."""
        rows = [[k, e, nu] for k, (e, nu) in sorted(self.moduli.items())]
        return (np.array(rows, np.float64).reshape(-1, 3), self.keys.copy(), self.xi.copy(),
                np.int64(self.n_bodies))

    def rolling_arrays(self):
        """(settings (P, 3) rows material_a, material_b, mu_r with -1, -1 for every pair;
        mr (K, 3) aligned with ``keys``) for a save."""
        rows = [[-1, -1, v] if k is None else [k[0], k[1], v]
                for k, v in sorted(self.rolling.items(), key=lambda kv: (-1, -1)
                                   if kv[0] is None else kv[0])]
        return np.array(rows, np.float64).reshape(-1, 3), np.ascontiguousarray(self.mr)


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


def _pair_rolling(sim, c, state):
    """mu_r per contact (nc,) from :meth:`HertzState.set_rolling` (a pair of material ids, else
    the setting for every pair, else 0; a wall without a material id takes the setting for
    every pair), or None when no contact has rolling resistance (the step then does not run
    the rolling kernel at all: the arithmetic of a run without it)."""
    if not state.rolling_active():
        return None
    mats = sim._materials
    nc = len(c.a)
    ida = mats.body_ids[c.a] if mats.body_ids is not None else np.zeros(nc, np.int64)
    isw = c.b < 0
    bb = np.where(isw, 0, c.b)
    idb = mats.body_ids[bb] if mats.body_ids is not None else np.zeros(nc, np.int64)
    if len(mats.wall_ids):
        idb = np.where(isw, mats.wall_ids[np.where(isw, -1 - c.b, 0)], idb)
    else:
        idb = np.where(isw, -1, idb)
    default = state.rolling.get(None, 0.0)
    out = np.full(nc, default)
    pairs = [(k, v) for k, v in state.rolling.items() if k is not None]
    if pairs:
        lo = np.minimum(ida, idb)
        hi = np.maximum(ida, idb)
        own_wall = idb < 0
        for (i, j), v in pairs:
            out[(lo == i) & (hi == j) & ~own_wall] = v
    if not np.any(out > 0.0):
        return None
    return out


def _pair_restitution(sim, c):
    """e_n per contact (the pair material's, as :func:`_pair_parameters` uses)."""
    from peclet.dem.materials import per_contact
    mats = sim._materials
    if mats.active():
        e_c, _, _ = mats.per_contact(c.a, c.b, sim._material, sim._geometry())
    else:
        e_c, _, _ = per_contact(c.b, sim._material, sim._geometry())
    return np.asarray(e_c, np.float64)


def _distributed_rows(sim, state, cand, x, rotm, pa, pb, pp, pn, pg, status, kept):
    """Replace, in the composed rows' geometry (``pp``, ``pn``, ``pg``, ``status``, changed
    in place), every pair with a contact the patch law cannot hold (a status other than
    PATCH_OK on a touching patch, or a pair seeded MODE_DISTRIBUTED) by one distributed
    contact on the pair's first row (the others get gap +inf). Returns (rows (D,) in the
    composed arrays, overlap-law arrays: kernel gap (D,), kernel R* (D,), gamma (D,)) or None
    when no pair is distributed. Raises HertzPatchError (state restored from ``kept``) for a
    distributed contact it refuses."""
    from peclet.dem.contacts import WarmStart
    dist = (status != PATCH_OK) | (cand.mode == MODE_DISTRIBUTED)
    # a pair with a failed seed (a watched probe) and no touching Hertz patch is sampled too:
    # a line or edge contact can lie between the probes
    watched = (cand.mode == 1) | (cand.mode == 2)
    if np.any(watched):
        hertz_touch = np.unique(cand.first[(cand.mode == 0) & (pg < 0.0)])
        dist |= watched & ~np.isin(cand.first, hertz_touch)
    if not np.any(dist):
        return None
    rep = np.unique(cand.first[dist])
    in_d = np.isin(cand.first, rep)
    k = cand.comp
    estar = cand.params[0][k][rep]
    dkeys = WarmStart.keys_of(_Pairs(pa[rep], pb[rep], np.full(len(rep), DIST_FEATURE,
                                                                np.int64)), len(sim._walls))
    out, dst = distributed_geometry(pa[rep], pb[rep], cand.shift[k][rep], x, rotm,
                                    sim._shape_table()[1], sim._geometry(), estar,
                                    np.isin(dkeys, state.keys))
    if np.any(dst != PATCH_OK):
        state.restore(kept)
        _raise_patch_error(pa[rep], pb[rep], dst)
    pg[in_d] = np.inf
    status[in_d] = PATCH_OK
    force, stiff = out[:, 7], out[:, 8]
    touch = force > 0.0
    pg[rep] = np.where(touch, -out[:, 6], np.inf)
    pp[rep] = out[:, :3]
    pn[rep] = out[:, 3:6]
    # the overlap law through the Hertz kernel: a delta_h and R*_h with the same force F and
    # stiffness S (F = 4/3 E* sqrt(R*_h) delta_h^1.5, S = 2 E* sqrt(R*_h delta_h))
    dh = np.where(touch, 1.5 * force / np.where(touch, stiff, 1.0), 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        rh = np.where(touch, (0.75 * force / (estar * np.where(touch, dh, 1.0) ** 1.5)) ** 2,
                      0.0)
    e = cand.e_n[k][rep]
    gam = np.array([damping_gamma_linear(float(v)) for v in e])
    state.dist_last = out
    return rep, np.where(touch, -dh, np.inf), rh, gam


def check(sim, state, dt):
    """Refuse what the engine cannot run: undeclared moduli, a dt above ``RAYLEIGH_FRACTION``
    of the smallest Rayleigh time (a composed body: its bounding radius, its mass spread over
    the bounding sphere), restitution below ``E_MIN``. A composed particle's unsupported
    contacts are refused when they touch (:class:`HertzPatchError`)."""
    b = sim._bodies
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
    and ``keys`` (task order: the detection's rows, a composed pair's rows replaced by its
    patches), ``x_ref`` / ``q_ref`` the positions and quaternions they were found at, ``skin``
    the detection margin, ``radii`` (N,), and ``params`` the pair parameters (E*, G*, R*, m*,
    gamma, mu) per candidate. With composed particles: ``comp`` the rows that are patches and
    ``sph`` the others, and per patch ``mode`` (0 a patch tracked by ``u`` in a's home frame; 1
    / 2 a watched probe of a / of b, ``u`` in that body's frame) and ``first`` (its pair's
    first patch); ``comp`` None otherwise. ``mu_r`` the rolling friction per candidate, None
    when no candidate has any."""
    a: np.ndarray
    b: np.ndarray
    shift: np.ndarray
    feat: np.ndarray
    keys: np.ndarray
    x_ref: np.ndarray
    skin: float
    radii: np.ndarray
    params: tuple
    comp: np.ndarray = None
    sph: np.ndarray = None
    mode: np.ndarray = None
    u: np.ndarray = None
    first: np.ndarray = None
    q_ref: np.ndarray = None
    e_n: np.ndarray = None
    mu_r: np.ndarray = None


class _Pairs(NamedTuple):
    a: np.ndarray
    b: np.ndarray
    feat: np.ndarray


def _raise_patch_error(a, b, status):
    """Raise :class:`HertzPatchError` for the first row whose status is not PATCH_OK."""
    bad = np.flatnonzero(status != PATCH_OK)
    if len(bad):
        i = int(bad[0])
        raise HertzPatchError(a[i], b[i], _PATCH_REASONS[int(status[i])])


def _probe_spacing(state, geo):
    """Per shape: the largest distance from a probe to its nearest other probe (0 for a
    sphere), cached per geometry."""
    kept = state.spacing
    if kept is not None and kept[0] is geo:
        return kept[1]
    from scipy.spatial import cKDTree
    nps = np.diff(np.append(geo.shape_p0, len(geo.probes)))
    out = np.zeros(len(geo.shape_kind))
    for s in range(len(out)):
        if nps[s] >= 2:
            p = geo.probes[geo.shape_p0[s]:geo.shape_p0[s] + nps[s]]
            d, _ = cKDTree(p).query(p, k=2)
            out[s] = float(d[:, 1].max())
    state.spacing = (geo, out)
    return out


def _home(x, R, p):
    """World points p (n, 3) in the frame of the body at x with rotation R (home -> world)."""
    return (p - x) @ R


def _composed_candidates(sim, state, c, x, rot, geo, shape_of, skin, n_walls):
    """The candidate rows with every composed pair (a composed body on either side) replaced
    by its patches (:func:`seed_patches`), their feature ids (the probe nearest the patch
    point: of a, or of b offset by FEATURE_DIR when a is a sphere; FAILED_FEATURE added for a
    watched probe) and keys; the stored tangential histories of the composed pairs are carried
    over to the new keys, each old patch to the nearest new patch of its pair within twice the
    probe spacing plus the skin (both in the same body frame). Returns None when no pair is
    composed, else (a, b, shift, feat, keys, comp, sph, mode, u, first)."""
    from peclet.dem.contacts import _FEATURE_BITS, WarmStart
    from peclet.dem.narrowphase import FEATURE_DIR
    from peclet.dem.shapes import SCENE
    kind = geo.shape_kind[shape_of]
    bb = np.where(c.b >= 0, c.b, 0)
    comp_row = (kind[c.a] == SCENE) | ((c.b >= 0) & (kind[bb] == SCENE))
    if not comp_row.any():
        return None
    n = len(c.a)
    new = np.ones(n, bool)
    new[1:] = ((c.a[1:] != c.a[:-1]) | (c.b[1:] != c.b[:-1])
               | np.any(c.shift[1:] != c.shift[:-1], axis=1))
    g0 = np.flatnonzero(new)
    g1 = np.append(g0[1:], n)
    gcomp = comp_row[g0]
    cg = np.flatnonzero(gcomp)
    rows = np.concatenate([np.arange(g0[k], g1[k]) for k in cg])
    det_off = np.concatenate([[0], np.cumsum(g1[cg] - g0[cg])]).astype(np.int64)
    nps = np.diff(np.append(geo.shape_p0, len(geo.probes))).astype(np.int64)
    ct, cc = elliptic_table()
    cnt, mode, u, probe = seed_patches(
        c.a[g0[cg]], c.b[g0[cg]], np.ascontiguousarray(c.shift[g0[cg]]), det_off,
        np.ascontiguousarray(c.point[rows]), np.ascontiguousarray(c.gap[rows]), float(skin),
        x, rot, shape_of, geo.shape_kind, geo.shape_rad, geo.shape_op, geo.shape_p0, nps,
        geo.probes, geo.wall_op, geo.wall_sign, geo.wall_pos, geo.wall_rot, geo.ops, geo.lk,
        geo.lr, ct, cc)
    too_many = np.flatnonzero(cnt > MAX_PATCHES)
    if len(too_many):
        # more patches than one pair may hold: the pair's contact is distributed
        cnt[too_many] = 1
        mode[too_many, 0] = MODE_DISTRIBUTED
        u[too_many, 0] = 0.0
        probe[too_many, 0] = -1
    spacing = _probe_spacing(state, geo)
    # the Mindlin and rolling histories travel together (columns 0-2 and 3-5)
    old_keys, old_xi = state.keys, np.hstack([state.xi, state.mr])
    mask = (1 << _FEATURE_BITS) - 1
    out_a, out_b, out_s, out_f, out_c = [], [], [], [], []
    p_mode, p_u, p_first = [], [], []
    carried_keys, carried_xi, dropped_pairs = [], [], []
    npatch = 0
    ci = 0
    for k in range(len(g0)):
        if not gcomp[k]:
            sl = slice(g0[k], g1[k])
            out_a.append(c.a[sl])
            out_b.append(c.b[sl])
            out_s.append(c.shift[sl])
            out_f.append(c.feat[sl])
            out_c.append(np.zeros(g1[k] - g0[k], bool))
            continue
        m = int(cnt[ci])
        ia, ib, sh = int(c.a[g0[k]]), int(c.b[g0[k]]), c.shift[g0[k]]
        md, uu, pr = mode[ci, :m], u[ci, :m], probe[ci, :m]
        ci += 1
        # the frame features live in: a's when a is composed, else b's (offset FEATURE_DIR)
        on_a = kind[ia] == SCENE
        fb = ia if on_a else ib
        fs = shape_of[fb]
        fx = x[fb] + (0.0 if on_a else sh)
        pts = geo.probes[geo.shape_p0[fs]:geo.shape_p0[fs] + nps[fs]]
        off = 0 if on_a else FEATURE_DIR
        # patch points in the feature frame
        world = x[ia] + uu @ rot[ia].T
        loc = _home(fx, rot[fb], world)
        feat = np.empty(m, np.int64)
        taken = set()
        for j in range(m):
            if md[j] == MODE_DISTRIBUTED:
                feat[j] = DIST_FEATURE
                continue
            if md[j] != 0:
                feat[j] = FAILED_FEATURE + (FEATURE_DIR if md[j] == 2 else 0) + int(pr[j])
                continue
            order = np.argsort(((pts - loc[j]) ** 2).sum(axis=1), kind="stable")
            f = next(int(o) for o in order if int(o) not in taken)
            taken.add(f)
            feat[j] = off + f
        pair_key = WarmStart.keys_of(_Pairs(np.array([ia]), np.array([ib]),
                                            np.zeros(1, np.int64)), n_walls)[0]
        dropped_pairs.append(pair_key >> _FEATURE_BITS)
        new_keys = WarmStart.keys_of(_Pairs(np.full(m, ia), np.full(m, ib), feat), n_walls)
        # carry the histories: old patch keys of this pair, by distance in the feature frame
        sel = np.flatnonzero(((old_keys >> _FEATURE_BITS) == (pair_key >> _FEATURE_BITS))
                             & ((old_keys & mask) < FAILED_FEATURE))
        live = np.flatnonzero(md == 0)
        # a distributed contact's history keeps its key (the pair and DIST_FEATURE)
        dk = WarmStart.keys_of(_Pairs(np.array([ia]), np.array([ib]),
                                      np.array([DIST_FEATURE])), n_walls)[0]
        hit = np.flatnonzero(old_keys == dk)
        if len(hit):
            carried_keys.append(dk)
            carried_xi.append(old_xi[hit[0]])
        if len(sel) and len(live):
            of = (old_keys[sel] & mask) - off
            ok = (of >= 0) & (of < len(pts))
            sel, of = sel[ok], of[ok]
            d = np.sqrt(((loc[live][:, None, :] - pts[of][None, :, :]) ** 2).sum(axis=2))
            lim = 2.0 * spacing[fs] + skin
            cand_pairs = [(d[i, j], i, j) for i in range(len(live)) for j in range(len(sel))
                          if d[i, j] <= lim]
            used_new, used_old = set(), set()
            for _, i, j in sorted(cand_pairs):
                if i in used_new or j in used_old:
                    continue
                used_new.add(i)
                used_old.add(j)
                carried_keys.append(new_keys[live[i]])
                carried_xi.append(old_xi[sel[j]])
        out_a.append(np.full(m, ia, np.int64))
        out_b.append(np.full(m, ib, np.int64))
        out_s.append(np.tile(sh, (m, 1)))
        out_f.append(feat)
        out_c.append(np.ones(m, bool))
        p_mode.append(md)
        p_u.append(uu)
        p_first.append(np.full(m, npatch, np.int64))
        npatch += m
    a = np.concatenate(out_a).astype(np.int64)
    b = np.concatenate(out_b).astype(np.int64)
    shift = np.ascontiguousarray(np.concatenate(out_s).reshape(-1, 3), dtype=np.float64)
    feat = np.concatenate(out_f).astype(np.int64)
    isc = np.concatenate(out_c)
    keys = WarmStart.keys_of(_Pairs(a, b, feat), n_walls)
    # the stored histories: the composed pairs' entries replaced by the carried ones
    keep = ~np.isin(old_keys >> _FEATURE_BITS, np.array(dropped_pairs, np.int64))
    nk = np.concatenate([old_keys[keep], np.array(carried_keys, np.int64)])
    nx = np.concatenate([old_xi[keep], np.array(carried_xi, np.float64).reshape(-1, 6)])
    o = np.argsort(nk, kind="stable")
    nx = nx[o]
    state.keys = nk[o]
    state.xi = np.ascontiguousarray(nx[:, :3])
    state.mr = np.ascontiguousarray(nx[:, 3:])
    return (a, b, shift, feat, keys, np.flatnonzero(isc), np.flatnonzero(~isc),
            np.concatenate(p_mode).astype(np.int64),
            np.ascontiguousarray(np.concatenate(p_u).reshape(-1, 3)),
            np.concatenate(p_first).astype(np.int64))


def _turn_angles(q, q_ref):
    """Per body: the angle (rad) of the rotation from quaternion q_ref to q."""
    chord = np.minimum(np.sqrt(((q - q_ref) ** 2).sum(axis=1)),
                       np.sqrt(((q + q_ref) ** 2).sum(axis=1)))
    return 4.0 * np.arcsin(np.minimum(0.5 * chord, 1.0))


def _candidates(sim, state, x, q, skin_frac, inv_mass):
    """The candidate list for positions ``x``: kept from the last substep while no pair can
    have closed the skin (twice the largest displacement since it was built below the skin,
    every wall static and 1-Lipschitz, no periodic axis; with composed particles, four times
    the largest surface displacement |dx| + R_bound x turn angle, the other half of the skin
    covering the probes' spacing), else rebuilt by the engine's detection with margin =
    ``skin_frac`` x the smallest radius. Every contact that touches is in the list either way,
    and its geometry is recomputed exactly at every substep (:func:`contact_geometry`,
    :func:`patch_geometry`); for spheres the schedule of rebuilds never changes a bit."""
    from peclet.core.geom.transforms import quats_to_matrices
    from peclet.dem.contacts import WarmStart
    from peclet.dem.shapes import SCENE
    cand = state.cand
    geo = sim._geometry()
    shape_of = sim._shape_table()[1]
    scene = geo.shape_kind[shape_of] == SCENE
    if cand is not None and len(cand.x_ref) == len(x) and not sim._domain.periodic.any() \
            and not sim._wallmo.moving() and bool(np.all(geo.wall_lip)):
        d = np.sqrt(((x - cand.x_ref) ** 2).sum(axis=1))
        if cand.q_ref is None:
            if 2.0 * float(d.max(initial=0.0)) < cand.skin:
                return cand
        else:
            d = d + np.where(scene, cand.radii * _turn_angles(q, cand.q_ref), 0.0)
            if 4.0 * float(d.max(initial=0.0)) < cand.skin:
                return cand
    radii = sim._radii()
    skin = skin_frac * float(radii.min())
    rot = np.ascontiguousarray(quats_to_matrices(q))
    c = sim._detect(x, rot, skin)
    n_walls = len(sim._walls)
    comp = _composed_candidates(sim, state, c, x, rot, geo, shape_of, skin, n_walls) \
        if scene.any() else None
    if comp is None:
        cand = Candidates(c.a, c.b, np.ascontiguousarray(c.shift), c.feat,
                          WarmStart.keys_of(c, n_walls), x.copy(), skin, radii,
                          _pair_parameters(sim, c, state, inv_mass),
                          q_ref=q.copy() if scene.any() else None,
                          mu_r=_pair_rolling(sim, c, state))
    else:
        a, b, shift, feat, keys, crow, srow, mode, u, first = comp
        cand = Candidates(a, b, shift, feat, keys, x.copy(), skin, radii,
                          _pair_parameters(sim, _Pairs(a, b, feat), state, inv_mass),
                          crow, srow, mode, u, first, q.copy(),
                          _pair_restitution(sim, _Pairs(a, b, feat)),
                          _pair_rolling(sim, _Pairs(a, b, feat), state))
    state.cand = cand
    return cand


def substep(sim, state, dt, skin_frac):
    """One explicit substep of ``dt`` (the facade has checked the arguments and the state and
    cleared ``state.cand`` at the start of the call). Commits the new state; raises StepError
    (state of the substep's start kept) on a non-finite or runaway state."""
    import time

    from peclet.dem import solver
    from peclet.dem.contacts import Contacts, WarmStart, lever_arms
    from peclet.dem.rigid import advance_all

    t0 = time.perf_counter()
    b = sim._bodies
    if state.n_bodies != b.n:
        state.clear_history()
    inv_mass, inv_inertia, x, q, v, w = sim._working_state()
    limits = sim._guard_limits()        # fixed within the substep
    sim._guard(x, q, v, w, limits)
    kept = state.snapshot()
    try:
        cand = _candidates(sim, state, x, q, skin_frac, inv_mass)
    except HertzPatchError:
        state.restore(kept)     # a rebuild re-keys the histories
        raise
    t1 = time.perf_counter()
    nc = len(cand.a)
    point = np.empty((nc, 3))
    normal = np.empty((nc, 3))
    gap = np.empty(nc)
    geo = sim._geometry()
    estar, gstar, rstar, mstar, gam, mu = cand.params
    unew = None
    dist = None
    if cand.comp is None:
        contact_geometry(cand.a, cand.b, cand.shift, x, cand.radii, geo.wall_op, geo.wall_sign,
                         geo.wall_pos, geo.wall_rot, geo.ops, geo.lk, geo.lr, point, normal,
                         gap)
    else:
        from peclet.core.geom.transforms import quats_to_matrices
        s = cand.sph
        if len(s):
            ps, ns, gs = np.empty((len(s), 3)), np.empty((len(s), 3)), np.empty(len(s))
            contact_geometry(cand.a[s], cand.b[s], np.ascontiguousarray(cand.shift[s]), x,
                             cand.radii, geo.wall_op, geo.wall_sign, geo.wall_pos,
                             geo.wall_rot, geo.ops, geo.lk, geo.lr, ps, ns, gs)
            point[s], normal[s], gap[s] = ps, ns, gs
        k = cand.comp
        pa, pb = cand.a[k], cand.b[k]
        rotm = np.ascontiguousarray(quats_to_matrices(q))
        pp, pn, pg, pr, _, unew, status = patch_geometry(
            pa, pb, np.ascontiguousarray(cand.shift[k]), cand.mode, cand.u, cand.first, x,
            rotm, sim._shape_table()[1], geo)
        dist = _distributed_rows(sim, state, cand, x, rotm, pa, pb, pp, pn, pg, status, kept)
        if np.any(status != PATCH_OK):
            state.restore(kept)
            _raise_patch_error(pa, pb, status)
        point[k], normal[k], gap[k] = pp, pn, pg
        rstar = rstar.copy()
        rstar[k] = pr
    feat, keys = cand.feat, cand.keys
    gap_k = gap
    # the rolling lever: the normal law's R* (a patch's), but a distributed contact takes its
    # bounding spheres' R* (its kernel R*_h is no radius, see the module notes)
    rroll = rstar
    if dist is not None:
        # the distributed contacts: their own key and the overlap law through the kernel
        rows = cand.comp[dist[0]]
        rroll = rstar.copy()
        rroll[rows] = cand.params[2][rows]
        feat = feat.copy()
        feat[rows] = DIST_FEATURE
        keys = keys.copy()
        keys[rows] = WarmStart.keys_of(_Pairs(cand.a[rows], cand.b[rows], feat[rows]),
                                       len(sim._walls))
        gap_k = gap.copy()
        gap_k[rows] = dist[1]
        rstar[rows] = dist[2]
        gam = gam.copy()
        gam[rows] = dist[3]
    c = Contacts(cand.a, cand.b, cand.shift, point, normal, gap, feat)
    xi = state.lookup(keys)
    ra, rb = lever_arms(c, x)
    nc = len(c.a)
    vw = np.zeros((nc, 3))
    if sim._wallmo.moving():
        isw = c.b < 0
        vw[isw] = sim._wallmo.surface_velocity(-1 - c.b[isw], c.point[isw])
    force = np.empty((nc, 3))
    fn = np.empty(nc)
    contact_forces(c.a, c.b, np.ascontiguousarray(c.normal), np.ascontiguousarray(gap_k), ra,
                   rb, v, w, vw, estar, gstar, rstar, mstar, gam, mu, xi, dt, force, fn)
    fb = np.zeros((b.n, 3)) if sim._ext_force is None else sim._ext_force.copy()
    tb = np.zeros((b.n, 3)) if sim._ext_torque is None else sim._ext_torque.copy()
    accumulate(c.a, c.b, ra, rb, force, b.n, fb, tb)
    mr = None
    if cand.mu_r is not None:
        mr = state.lookup_rolling(keys)
        wom = np.zeros((nc, 3))
        if sim._wallmo.moving():
            isw = c.b < 0
            wom[isw] = sim._wallmo.omega[-1 - c.b[isw]]
        troll = np.empty((nc, 3))
        rolling_torques(c.a, c.b, np.ascontiguousarray(c.normal), np.ascontiguousarray(gap_k),
                        ra, rb, w, wom, estar, rstar, np.ascontiguousarray(rroll), cand.mu_r,
                        fn, inv_mass, np.ascontiguousarray(inv_inertia.mean(axis=1)), dt, mr,
                        troll)
        accumulate_torques(c.a, c.b, troll, tb)
    wii = solver.world_inv_inertias(q, inv_inertia)
    with np.errstate(over="ignore", invalid="ignore"):   # the guard reports it
        kick_drift(x, v, w, fb, tb, inv_mass, np.ascontiguousarray(wii), sim._gravity, dt)
    sim._guard(x, q, v, w, limits)
    advance_all(q, w, inv_inertia, dt)
    sim._domain.wrap(x)
    sim._guard(x, q, v, w, limits)
    # commit
    b.pos, b.quat, b.vel, b.omega = x, q, v, w
    touching = c.gap < 0.0
    state.store(keys, xi, touching, b.n, mr)
    if unew is not None:
        state.cand = cand._replace(u=unew)
    state.last = (c, force, fn, xi, troll if mr is not None else None)
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
    ``normal_force`` (n,) >= 0, ``tangential_displacement`` (n, 3) the Mindlin history,
    ``rolling_torque`` (n, 3) the rolling resistance torque on body a (b gets the opposite, a
    wall nothing; zero without rolling friction)."""
    if state.last is None:
        z = np.zeros(0)
        return {"body_a": np.zeros(0, np.int64), "body_b": np.zeros(0, np.int64),
                "point": np.zeros((0, 3)), "normal": np.zeros((0, 3)), "depth": z,
                "force": np.zeros((0, 3)), "normal_force": z,
                "tangential_displacement": np.zeros((0, 3)), "rolling_torque": np.zeros((0, 3))}
    c, force, fn, xi, troll = state.last
    m = c.gap < 0.0
    o = np.lexsort((c.feat[m], c.b[m], c.a[m]))
    if troll is None:
        troll = np.zeros((len(c.a), 3))
    return {"body_a": c.a[m][o], "body_b": c.b[m][o], "point": c.point[m][o],
            "normal": c.normal[m][o], "depth": -c.gap[m][o], "force": force[m][o],
            "normal_force": fn[m][o], "tangential_displacement": xi[m][o],
            "rolling_torque": troll[m][o]}
