"""The Hertz–Mindlin force law per contact, the sums into the bodies, the kick-drift integrator
and the sphere contacts' exact geometry (docstring of :mod:`peclet.dem.hertz`: normal and
tangential force, integrator, lever arms, determinism).

The kernels take their arrays bundled: :class:`ContactRows` (which bodies, along which normal,
how far apart, with which lever arms), :class:`PairLaw` (the per-contact constants of the law),
:class:`Motion` (the velocities the law reads) and :class:`ForceOut` (what it writes)."""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from peclet.core.geom.kernels import MAX_STACK, STACK_COLS, eval_point
from peclet.dem.treeframe import to_home, world_normal
from . import dispatch


class ContactRows(NamedTuple):
    """Per contact: body ``a``, body (or wall -1 - w) ``b``, ``normal`` (nc, 3) from b to a,
    ``gap`` (nc,) (< 0: an overlap), lever arms ``ra`` / ``rb`` (nc, 3)."""
    a: np.ndarray
    b: np.ndarray
    normal: np.ndarray
    gap: np.ndarray
    ra: np.ndarray
    rb: np.ndarray


class PairLaw(NamedTuple):
    """Per contact: E*, G*, R*, m*, the dashpot's gamma and the friction mu."""
    estar: np.ndarray
    gstar: np.ndarray
    rstar: np.ndarray
    mstar: np.ndarray
    gamma: np.ndarray
    mu: np.ndarray


class Motion(NamedTuple):
    """The bodies' velocities ``vel`` and ``omega`` (N, 3) and each contact's wall velocity
    ``vwall`` (nc, 3) (zero where b is a body)."""
    vel: np.ndarray
    omega: np.ndarray
    vwall: np.ndarray


class ForceOut(NamedTuple):
    """Per contact: the tangential history ``xi`` (nc, 3) (in: last step's, out: this step's),
    the ``force`` (nc, 3) on body a and the normal force ``fn`` (nc,)."""
    xi: np.ndarray
    force: np.ndarray
    fn: np.ndarray


class Walls(NamedTuple):
    """What a sphere's wall contact reads: the walls' program rows ``wall_op`` (W, 2), signs,
    poses (``wall_pos`` (W, 3), ``wall_rot`` (W, 3, 3)) and the program tables. Its fields
    are also the walls part of :class:`peclet.dem.hertz.fields.Shapes`."""
    wall_op: np.ndarray
    wall_sign: np.ndarray
    wall_pos: np.ndarray
    wall_rot: np.ndarray
    ops: np.ndarray
    lk: np.ndarray
    lr: np.ndarray


def walls_of(geo):
    """The :class:`Walls` of a :class:`peclet.dem.shapes.Geometry`."""
    return Walls(geo.wall_op, geo.wall_sign, geo.wall_pos, geo.wall_rot, geo.ops, geo.lk, geo.lr)


@njit(cache=True)
def cross(a0, a1, a2, b0, b1, b2):
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True)
def into_plane(hx, hy, hz, nx, ny, nz):
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
def truncate(x, y, z, limit):
    """(x, y, z, cut): the vector shortened to length ``limit`` (direction kept) where it is
    longer, and whether it was; the Coulomb cone of a force, the plastic limit of a torque."""
    n = math.sqrt(x * x + y * y + z * z)
    if n > limit:
        s = limit / n
        return x * s, y * s, z * s, True
    return x, y, z, False


@njit(cache=True)
def contact_velocity(i, rows, motion):
    """(n_x, n_y, n_z, v_n, t_x, t_y, t_z) of contact i: its unit normal (from b to a), the
    normal component of the velocity of a's surface point relative to b's (or to the wall's
    surface, ``motion.vwall[i]``; positive when separating) and its tangential part, world
    frame. Shared by every force law."""
    a, b, normal, _, ra, rb = rows
    vel, omega, vwall = motion
    ia = a[i]
    nx, ny, nz = normal[i, 0], normal[i, 1], normal[i, 2]
    cx, cy, cz = cross(omega[ia, 0], omega[ia, 1], omega[ia, 2], ra[i, 0], ra[i, 1],
                       ra[i, 2])
    vx = vel[ia, 0] + cx
    vy = vel[ia, 1] + cy
    vz = vel[ia, 2] + cz
    ib = b[i]
    if ib >= 0:
        cx, cy, cz = cross(omega[ib, 0], omega[ib, 1], omega[ib, 2], rb[i, 0], rb[i, 1],
                           rb[i, 2])
        vx -= vel[ib, 0] + cx
        vy -= vel[ib, 1] + cy
        vz -= vel[ib, 2] + cz
    else:
        vx -= vwall[i, 0]
        vy -= vwall[i, 1]
        vz -= vwall[i, 2]
    vn = vx * nx + vy * ny + vz * nz
    return nx, ny, nz, vn, vx - vn * nx, vy - vn * ny, vz - vn * nz


@njit(cache=True)
def tangential_spring(i, xi, nx, ny, nz, tx, ty, tz, dt, stiffness, damping, limit):
    """The tangential force (fx, fy, fz) of contact i from its history ``xi[i]`` (turned into
    the current tangent plane, length kept, then advanced by the tangential velocity (tx, ty,
    tz) over dt): ``-stiffness xi - damping v_t``, truncated at ``limit`` (Coulomb: the force
    onto the cone and the spring stretched to hold exactly it). Writes ``xi[i]``."""
    hx, hy, hz = into_plane(xi[i, 0], xi[i, 1], xi[i, 2], nx, ny, nz)
    hx += tx * dt
    hy += ty * dt
    hz += tz * dt
    fx = -stiffness * hx - damping * tx
    fy = -stiffness * hy - damping * ty
    fz = -stiffness * hz - damping * tz
    fx, fy, fz, cut = truncate(fx, fy, fz, limit)
    if cut:
        if stiffness > 0.0:
            hx = -fx / stiffness
            hy = -fy / stiffness
            hz = -fz / stiffness
    xi[i, 0], xi[i, 1], xi[i, 2] = hx, hy, hz
    return fx, fy, fz


@njit(cache=True)
def clear_row(i, out):
    """Contact i does not touch: no force, and its history forgotten."""
    for e in range(3):
        out.force[i, e] = 0.0
        out.xi[i, e] = 0.0
    out.fn[i] = 0.0


@njit(cache=True)
def store_row(i, out, fn, nx, ny, nz, fx, fy, fz):
    """Contact i's force on a: ``fn`` along the unit normal (nx, ny, nz) plus the
    tangential (fx, fy, fz); its normal force ``fn``."""
    out.force[i, 0] = fn * nx + fx
    out.force[i, 1] = fn * ny + fy
    out.force[i, 2] = fn * nz + fz
    out.fn[i] = fn


@njit(cache=True)
def _one_contact(i, rows, law, motion, dt, out):
    # contact i of contact_forces; writes only row i
    estar, gstar, rstar, mstar, gamma, mu = law
    d = -rows.gap[i]
    if d <= 0.0:
        clear_row(i, out)
        return
    nx, ny, nz, vn, tx, ty, tz = contact_velocity(i, rows, motion)
    sq = math.sqrt(rstar[i] * d)
    sn = 2.0 * estar[i] * sq
    st = 8.0 * gstar[i] * sq
    fn = 4.0 / 3.0 * estar[i] * sq * d - gamma[i] * math.sqrt(sn * mstar[i]) * vn
    if fn < 0.0:
        fn = 0.0
    fx, fy, fz = tangential_spring(i, out.xi, nx, ny, nz, tx, ty, tz, dt, st,
                                   gamma[i] * math.sqrt(st * mstar[i]), mu[i] * fn)
    store_row(i, out, fn, nx, ny, nz, fx, fy, fz)


forces_loops = dispatch.row_loops(_one_contact)


def contact_forces(rows, law, motion, dt, out):
    """Per contact i (each writes only row i): the Hertz–Mindlin force on body ``rows.a[i]``
    (``out.force`` (nc, 3), world; b gets its opposite) and the normal force ``out.fn`` (nc,);
    ``out.xi`` (nc, 3) comes in as last step's world-frame tangential displacement (zero for a
    new contact) and leaves as this step's (zero where the bodies do not overlap). The normal
    points from b to a; a gap < 0 is an overlap; a wall (b < 0) moves with ``motion.vwall[i]``;
    per-contact E*, G*, R*, m*, gamma, mu in ``law`` (:class:`PairLaw`). Serial below the
    package setting ``PARALLEL_MIN`` contacts (:mod:`peclet.dem.hertz.dispatch`)."""
    dispatch.run(forces_loops, len(rows.a), "PARALLEL_MIN", rows, law,
                 motion, dt, out)


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
        ib = b[i]
        add_opposite(f_body, ia, ib, fx, fy, fz)
        cx, cy, cz = cross(ra[i, 0], ra[i, 1], ra[i, 2], fx, fy, fz)
        t_body[ia, 0] += cx
        t_body[ia, 1] += cy
        t_body[ia, 2] += cz
        if ib >= 0:
            cx, cy, cz = cross(rb[i, 0], rb[i, 1], rb[i, 2], fx, fy, fz)
            t_body[ib, 0] -= cx
            t_body[ib, 1] -= cy
            t_body[ib, 2] -= cz


@njit(cache=True)
def add_opposite(out, ia, ib, x, y, z):
    """(x, y, z) added to row ``ia`` of ``out`` and, when ``ib`` is a body (>= 0), taken
    from row ``ib``: a contact's force or torque on its two bodies."""
    out[ia, 0] += x
    out[ia, 1] += y
    out[ia, 2] += z
    if ib >= 0:
        out[ib, 0] -= x
        out[ib, 1] -= y
        out[ib, 2] -= z


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


kick_loops = dispatch.row_loops(_kick_one)


def kick_drift(x, v, w, f_body, t_body, inv_mass, wii, g, dt):
    """v += dt (inv_mass F + g) (g only where inv_mass > 0), omega += dt I_w^-1 T with the
    world inverse inertia ``wii`` (N, 3, 3), x += dt v. Per body (own rows only; serial below
    the package setting ``PARALLEL_MIN`` bodies)."""
    dispatch.run(kick_loops, len(x), "PARALLEL_MIN", x, v, w, f_body, t_body,
                 inv_mass, wii, g, dt)


@njit(cache=True)
def contact_geometry(a, b, shift, pos, radii, walls, point, normal, gap):
    """The exact contact of each candidate (sphere ``a[i]`` against sphere ``b[i]`` at image
    ``shift[i]``, or against wall ``-1 - b[i]`` at its pose), with the narrow phase's
    formulas: the centre line for two spheres, the wall's tree at the sphere's centre
    (``phi - r``, normal along the tree's gradient) for a wall; ``point`` midway between the
    surfaces, ``normal`` from b to a, ``gap`` signed (+inf where a wall's gradient vanishes).
    Serial, in candidate order. ``walls``: :class:`Walls`."""
    wall_op, wall_sign, wall_pos, wall_rot, ops, lk, lr = walls
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
            qx, qy, qz = to_home(Rt, px - wall_pos[w, 0], py - wall_pos[w, 1],
                                 pz - wall_pos[w, 2])
            phi, gx, gy, gz = eval_point(ops, lk, lr, wall_op[w, 0], wall_op[w, 1], qx, qy, qz,
                                         st)
            sgn = wall_sign[w]
            g = sgn * phi - r
            nx, ny, nz, nn = world_normal(Rt, sgn, gx, gy, gz)
            if not (nn > 0.0 and g == g):
                g = np.inf
                nn = 1.0
            nx, ny, nz = nx / nn, ny / nn, nz / nn
            h = r + 0.5 * g
        point[i, 0] = px - h * nx
        point[i, 1] = py - h * ny
        point[i, 2] = pz - h * nz
        normal[i, 0] = nx
        normal[i, 1] = ny
        normal[i, 2] = nz
        gap[i] = g

