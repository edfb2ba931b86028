"""Rolling resistance of the Hertz engine: the elastic-plastic spring-dashpot of Ai et al. (2011,
type C), optional and off by default.

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
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from . import dispatch
from .law import add_opposite, into_plane, truncate


class RollLaw(NamedTuple):
    """Per contact: E* and the kernel's R* (with the gap: the normal stiffness), the rolling
    radius ``rroll``, ``mu_r`` and this step's normal force ``fn``."""
    estar: np.ndarray
    rstar: np.ndarray
    rroll: np.ndarray
    mu_r: np.ndarray
    fn: np.ndarray


class Spin(NamedTuple):
    """The bodies' ``omega`` (N, 3), each contact's wall angular velocity ``wom`` (nc, 3), the
    bodies' inverse mass and mean principal inverse moment ``inv_rot`` (N,)."""
    omega: np.ndarray
    wom: np.ndarray
    inv_mass: np.ndarray
    inv_rot: np.ndarray


class RollOut(NamedTuple):
    """Per contact: the rolling spring torque ``mr`` (nc, 3) (in: last step's, out: this
    step's) and the ``torque`` (nc, 3) on body a."""
    mr: np.ndarray
    torque: np.ndarray


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
def _one_rolling(i, rows, law, spin, dt, out):
    # contact i of rolling_torques; writes only row i
    a, b, normal, gap, ra, rb = rows
    estar, rstar, rroll, mu_r, fn = law
    omega, wom, inv_mass, inv_rot = spin
    mr, torque = out
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
    hx, hy, hz = into_plane(mr[i, 0], mr[i, 1], mr[i, 2], nx, ny, nz)
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
            tx, ty, tz, _ = truncate(tx, ty, tz, lim)
    mr[i, 0], mr[i, 1], mr[i, 2] = hx, hy, hz
    torque[i, 0], torque[i, 1], torque[i, 2] = tx, ty, tz


rolling_loops = dispatch.row_loops(_one_rolling)


def rolling_torques(rows, law, spin, dt, out):
    """Per contact i (each writes only row i): the rolling resistance torque on body
    ``rows.a[i]`` (``out.torque`` (nc, 3), world; b gets its opposite, a wall nothing).
    ``out.mr`` (nc, 3) comes in as last step's spring torque (zero for a new contact) and leaves
    as this step's (zero where the bodies do not touch or do not press). ``law``
    (:class:`RollLaw`): the kernel's R* (with the gap and E*: the normal stiffness), the
    rolling radius, the normal force of :func:`~peclet.dem.hertz.law.contact_forces` this
    step; ``spin`` (:class:`Spin`): a wall's angular velocity ``wom``, the bodies' mean
    principal inverse moment ``inv_rot`` (the dashpot's inertia)."""
    dispatch.run(rolling_loops, len(rows.a), "PARALLEL_MIN", rows, law,
                 spin, dt, out)


@njit(cache=True)
def accumulate_torques(a, b, torque, t_body):
    """Add each contact's rolling torque to its bodies, serially in contact order: a gets +T,
    b (a body) -T, a wall nothing."""
    for i in range(a.shape[0]):
        tx, ty, tz = torque[i, 0], torque[i, 1], torque[i, 2]
        if tx == 0.0 and ty == 0.0 and tz == 0.0:
            continue
        add_opposite(t_body, a[i], b[i], tx, ty, tz)
