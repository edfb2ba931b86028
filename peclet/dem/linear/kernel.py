"""The linear spring-dashpot force per contact (Numba), for :mod:`peclet.dem.linear`.

Reads the explicit engine's bundles (:class:`~peclet.dem.hertz.law.ContactRows`,
:class:`~peclet.dem.hertz.law.Motion`, :class:`~peclet.dem.hertz.law.ForceOut`) and its own
per-contact constants :class:`LinearRows`; each row writes only its own slots, so the serial and
the parallel loop give the same bits."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

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
    kn, kt, cn, mu = law
    d = -rows.gap[i]
    if d <= 0.0:
        clear_row(i, out)
        return
    nx, ny, nz, vn, tx, ty, tz = contact_velocity(i, rows, motion)
    # no clamp: the dashpot may pull at the end of a contact, which is what makes the
    # restitution exactly e (the module notes of peclet.dem.linear); no tangential dashpot
    fn = kn[i] * d - cn[i] * vn
    fx, fy, fz = tangential_spring(i, out.xi, nx, ny, nz, tx, ty, tz, dt, kt[i], 0.0,
                                   mu[i] * max(fn, 0.0))
    store_row(i, out, fn, nx, ny, nz, fx, fy, fz)


forces_loops = dispatch.row_loops(_one_contact)


def linear_forces(rows, law, motion, dt, out):
    """Per contact i: the linear spring-dashpot force on body ``rows.a[i]`` (``out.force``,
    world; b gets its opposite), the normal force ``out.fn`` and the tangential spring's
    stretch ``out.xi`` (in: last step's, zero for a new contact; out: this step's, zero where
    the bodies do not overlap). Serial below ``peclet.dem.hertz.PARALLEL_MIN`` contacts."""
    dispatch.run(forces_loops, len(rows.a), "PARALLEL_MIN", rows, law,
                 motion, dt, out)
