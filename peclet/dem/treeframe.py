"""A placed tree's two frames: a world offset carried into the tree's home frame, and the
tree's gradient (times a wall's sign) carried back into the world.

A tree (a shape's or a wall's) is placed at ``x`` with rotation ``R`` (home -> world: p = R q +
x). The narrow phase (:mod:`peclet.dem.probing`) and the Hertz law's exact contacts
(:func:`peclet.dem.hertz.law.contact_geometry`, :func:`peclet.dem.hertz.fields.field`) evaluate
trees through these, so that all of them do the same floating-point operations."""
from __future__ import annotations

import math

from numba import njit


@njit(cache=True, inline="always")
def to_home(R, dx, dy, dz):
    """R^T d: the world offset d (from the tree's origin) in the tree's home frame."""
    return (R[0, 0] * dx + R[1, 0] * dy + R[2, 0] * dz,
            R[0, 1] * dx + R[1, 1] * dy + R[2, 1] * dz,
            R[0, 2] * dx + R[1, 2] * dy + R[2, 2] * dz)


@njit(cache=True, inline="always")
def to_world(R, sgn, gx, gy, gz):
    """sgn R g: the home-frame gradient g in the world frame, times ``sgn`` (-1 for an
    inverted wall, +1 otherwise)."""
    return (sgn * (R[0, 0] * gx + R[0, 1] * gy + R[0, 2] * gz),
            sgn * (R[1, 0] * gx + R[1, 1] * gy + R[1, 2] * gz),
            sgn * (R[2, 0] * gx + R[2, 1] * gy + R[2, 2] * gz))


@njit(cache=True, inline="always")
def world_normal(R, sgn, gx, gy, gz):
    """(nx, ny, nz, norm): :func:`to_world` of the gradient and its length, not normalised
    (the caller decides what a zero or NaN length means)."""
    nx, ny, nz = to_world(R, sgn, gx, gy, gz)
    return nx, ny, nz, math.sqrt(nx * nx + ny * ny + nz * nz)
