"""The linear spring-dashpot force per contact (Numba), for :mod:`peclet.dem.linear`.

Reads the explicit engine's bundles (:class:`~peclet.dem.hertz.law.ContactRows`,
:class:`~peclet.dem.hertz.law.Motion`, :class:`~peclet.dem.hertz.law.ForceOut`) and its own
per-contact constants :class:`LinearRows`; each row writes only its own slots, so the serial and
the parallel loop give the same bits."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit, prange

from peclet.dem.hertz import dispatch
from peclet.dem.hertz.law import clear_row, contact_velocity, store_row, tangential_spring


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
    normal, gap = rows.normal, rows.gap
    kn, kt, cn, mu = law
    d = -gap[i]
    if d <= 0.0:
        clear_row(i, out)
        return
    nx, ny, nz = normal[i, 0], normal[i, 1], normal[i, 2]
    vn, tx, ty, tz = contact_velocity(i, rows, motion)
    # no clamp: the dashpot may pull at the end of a contact, which is what makes the
    # restitution exactly e (the module notes of peclet.dem.linear); no tangential dashpot
    fn = kn[i] * d - cn[i] * vn
    fx, fy, fz = tangential_spring(i, out.xi, nx, ny, nz, tx, ty, tz, dt, kt[i], 0.0,
                                   mu[i] * max(fn, 0.0))
    store_row(i, out, fn, nx, ny, nz, fx, fy, fz)


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
