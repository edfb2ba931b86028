"""The linear spring-dashpot force per contact (Numba), for :mod:`peclet.dem.linear`.

Reads the explicit engine's bundles (:class:`~peclet.dem.hertz.law.ContactRows`,
:class:`~peclet.dem.hertz.law.Motion`, :class:`~peclet.dem.hertz.law.ForceOut`) and its own
per-contact constants :class:`LinearRows`; each row writes only its own slots, so the serial and
the parallel loop give the same bits."""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from peclet.dem.hertz import dispatch
from peclet.dem.hertz.law import cross, into_plane


class LinearRows(NamedTuple):
    """Per contact: normal stiffness ``kn`` (force/length), tangential stiffness ``kt``,
    normal dashpot ``cn`` (force time/length) and friction ``mu``."""
    kn: np.ndarray
    kt: np.ndarray
    cn: np.ndarray
    mu: np.ndarray


@njit(cache=True)
def _one_contact(i, rows, law, motion, dt, out):
    # contact i of linear_forces; writes only row i
    a, b, normal, gap, ra, rb = rows
    kn, kt, cn, mu = law
    vel, omega, vwall = motion
    xi, force, fn_out = out
    d = -gap[i]
    if d <= 0.0:
        for e in range(3):
            force[i, e] = 0.0
            xi[i, e] = 0.0
        fn_out[i] = 0.0
        return
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
    tx = vx - vn * nx
    ty = vy - vn * ny
    tz = vz - vn * nz
    # no clamp: the dashpot may pull at the end of a contact, which is what makes the
    # restitution exactly e (the module notes of peclet.dem.linear)
    fn = kn[i] * d - cn[i] * vn
    hx, hy, hz = into_plane(xi[i, 0], xi[i, 1], xi[i, 2], nx, ny, nz)
    hx += tx * dt
    hy += ty * dt
    hz += tz * dt
    fx = -kt[i] * hx
    fy = -kt[i] * hy
    fz = -kt[i] * hz
    ft = math.sqrt(fx * fx + fy * fy + fz * fz)
    lim = mu[i] * max(fn, 0.0)
    if ft > lim:
        # Coulomb: the force onto the cone, the spring stretched to hold exactly it
        s = lim / ft
        fx *= s
        fy *= s
        fz *= s
        if kt[i] > 0.0:
            hx = -fx / kt[i]
            hy = -fy / kt[i]
            hz = -fz / kt[i]
    xi[i, 0], xi[i, 1], xi[i, 2] = hx, hy, hz
    force[i, 0] = fn * nx + fx
    force[i, 1] = fn * ny + fy
    force[i, 2] = fn * nz + fz
    fn_out[i] = fn


@njit(cache=True)
def forces_serial(rows, law, motion, dt, out):
    for i in range(rows.a.shape[0]):
        _one_contact(i, rows, law, motion, dt, out)


@njit(cache=True, parallel=True)
def forces_parallel(rows, law, motion, dt, out):
    for i in prange(rows.a.shape[0]):
        _one_contact(np.int64(i), rows, law, motion, dt, out)


def linear_forces(rows, law, motion, dt, out):
    """Per contact i: the linear spring-dashpot force on body ``rows.a[i]`` (``out.force``,
    world; b gets its opposite), the normal force ``out.fn`` and the tangential spring's
    stretch ``out.xi`` (in: last step's, zero for a new contact; out: this step's, zero where
    the bodies do not overlap). Serial below ``peclet.dem.hertz.PARALLEL_MIN`` contacts."""
    dispatch.run(forces_serial, forces_parallel, len(rows.a), "PARALLEL_MIN", rows, law,
                 motion, dt, out)
