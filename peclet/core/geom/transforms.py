"""Rotations and conformal transforms: the one home of every quaternion formula in peclet.

Conventions: quaternions are ``(x, y, z, w)``, unit, and act as an *active* rotation:
``v_out = R(q) v_in`` (for a body: home/principal frame -> world frame). A transform
``(t, q, s)`` maps a point of a node's own frame to its parent's frame as
``p_parent = s R(q) p_local + t``; the node's value in the parent frame is
``s * f(R(q)^T (p_parent - t) / s)`` (docs/architecture.md §2).

The quaternion kernels are ``@njit(cache=True)``: the same compiled function serves Python
callers (pass float64 arrays) and Numba kernels (the DEM engine, the rotor step), so there is
exactly one definition of each formula and the two worlds cannot drift apart by a bit.

Normalisation (:func:`quat_normalize`) first scales q by the power of two nearest its largest
component, so ``[1e200] * 4`` and ``[1e-200] * 4`` both give ``[0.5] * 4``. Scaling by a power
of two is exact, so wherever ``|q|^2`` neither overflows nor underflows the result has the
same bits as the plain ``q / sqrt(x x + y y + z z + w w)`` (summed in that order).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from peclet.core.validation import PecletArgumentError

IDENTITY_QUAT = np.array([0.0, 0.0, 0.0, 1.0])

#: A quaternion whose norm differs from 1 by more than this is normalised. Below it the value is
#: kept bit for bit, so that encode -> decode -> encode is the identity.
QUAT_NORM_TOL = 1e-14

_QUAT_ACCEPTED = "a finite, non-zero quaternion (x, y, z, w)"


# --------------------------------------------------------------------------------------------
# Quaternion kernels (Python and Numba)
# --------------------------------------------------------------------------------------------

@njit(cache=True)
def _scaled_norm(x, y, z, w):
    # (|q| / 2**e, e) with 2**(e-1) <= max|q_k| < 2**e; (0, 0) for a zero q and (nan, 0) for a
    # non-finite one. ldexp is exact, so the squares of the scaled components never over- or
    # underflow, and the rounding is that of the unscaled sum whenever that one is finite.
    if not (abs(x) < np.inf and abs(y) < np.inf and abs(z) < np.inf and abs(w) < np.inf):
        return np.nan, 0
    m = max(abs(x), abs(y), abs(z), abs(w))
    if m == 0.0:
        return 0.0, 0
    e = math.frexp(m)[1]
    x = math.ldexp(x, -e)
    y = math.ldexp(y, -e)
    z = math.ldexp(z, -e)
    w = math.ldexp(w, -e)
    return math.sqrt(x * x + y * y + z * z + w * w), e


@njit(cache=True)
def quat_norm(q):
    """``|q|`` of a quaternion, without overflow or underflow of the squares (inf only when
    |q| itself exceeds the float range; NaN for a non-finite q)."""
    n, e = _scaled_norm(q[0], q[1], q[2], q[3])
    return math.ldexp(n, e)


@njit(cache=True)
def normalize_xyzw(x, y, z, w):
    """``(x, y, z, w) / |q|`` on scalars and True, or ``(0, 0, 0, 0, False)`` for a zero or
    non-finite q. The allocation-free, raising-free core of every normalisation."""
    n, e = _scaled_norm(x, y, z, w)
    if not (n > 0.0):
        return 0.0, 0.0, 0.0, 0.0, False
    return (math.ldexp(x, -e) / n, math.ldexp(y, -e) / n, math.ldexp(z, -e) / n,
            math.ldexp(w, -e) / n, True)


@njit(cache=True)
def normalize_into(q, out):
    """Write ``q / |q|`` into ``out`` (4,) and return True, or return False (``out`` untouched)
    for a zero or non-finite q (the caller names its argument)."""
    x, y, z, w, ok = normalize_xyzw(q[0], q[1], q[2], q[3])
    if ok:
        out[0], out[1], out[2], out[3] = x, y, z, w
    return ok


@njit(cache=True)
def quat_normalize(q):
    """Unit quaternion ``q / |q|`` (x, y, z, w), robust to any finite magnitude.

    Raises :class:`PecletArgumentError` naming ``q`` for a zero or non-finite quaternion.
    """
    out = np.empty(4)
    if not normalize_into(q, out):
        raise PecletArgumentError("q", _QUAT_ACCEPTED, (q[0], q[1], q[2], q[3]))
    return out


@njit(cache=True)
def normalize_rows(quats):
    """Row-wise :func:`quat_normalize` of ``quats`` (N, 4). Returns ``(unit (N, 4), bad)``
    where ``bad`` is the first zero or non-finite row, or -1 (the caller names its argument)."""
    n = quats.shape[0]
    out = np.empty((n, 4))
    for i in range(n):
        if not normalize_into(quats[i], out[i]):
            return out, i
    return out, -1


@njit(cache=True)
def multiply_xyzw(ax, ay, az, aw, bx, by, bz, bw):
    """Hamilton product ``a b`` on scalars (x, y, z, w): rotation ``b`` first, then ``a``."""
    return (aw * bx + bw * ax + ay * bz - az * by,
            aw * by + bw * ay + az * bx - ax * bz,
            aw * bz + bw * az + ax * by - ay * bx,
            aw * bw - ax * bx - ay * by - az * bz)


@njit(cache=True)
def quat_multiply(a, b):
    """Hamilton product ``a b`` of quaternions (x, y, z, w): rotation ``b`` first, then ``a``."""
    out = np.empty(4)
    out[0], out[1], out[2], out[3] = multiply_xyzw(a[0], a[1], a[2], a[3],
                                                   b[0], b[1], b[2], b[3])
    return out


@njit(cache=True)
def quat_to_matrix(q):
    """Rotation matrix R (3, 3) of a unit quaternion (x, y, z, w): ``v_out = R v_in``."""
    x, y, z, w = q[0], q[1], q[2], q[3]
    R = np.empty((3, 3))
    R[0, 0] = 1.0 - 2.0 * (y * y + z * z)
    R[0, 1] = 2.0 * (x * y - z * w)
    R[0, 2] = 2.0 * (x * z + y * w)
    R[1, 0] = 2.0 * (x * y + z * w)
    R[1, 1] = 1.0 - 2.0 * (x * x + z * z)
    R[1, 2] = 2.0 * (y * z - x * w)
    R[2, 0] = 2.0 * (x * z - y * w)
    R[2, 1] = 2.0 * (y * z + x * w)
    R[2, 2] = 1.0 - 2.0 * (x * x + y * y)
    return R


@njit(cache=True)
def quats_to_matrices(quats):
    """R (N, 3, 3) of unit quaternions (N, 4), row by row :func:`quat_to_matrix`."""
    n = quats.shape[0]
    out = np.empty((n, 3, 3))
    for i in range(n):
        R = quat_to_matrix(quats[i])
        for a in range(3):          # element copies: a slice assignment compiles a
            for b in range(3):      # shape-mismatch message (seconds of a cold start)
                out[i, a, b] = R[a, b]
    return out


@njit(cache=True)
def matrix_to_quat(R):
    """Unit quaternion (x, y, z, w) with w >= 0 of a proper rotation matrix R (3, 3), by
    Shepperd's method (the largest of the four diagonal combinations under the root)."""
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    q = np.empty(4)
    if tr > 0.0:
        s = 2.0 * np.sqrt(1.0 + tr)
        q[0] = (R[2, 1] - R[1, 2]) / s
        q[1] = (R[0, 2] - R[2, 0]) / s
        q[2] = (R[1, 0] - R[0, 1]) / s
        q[3] = 0.25 * s
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q[0] = 0.25 * s
        q[1] = (R[0, 1] + R[1, 0]) / s
        q[2] = (R[0, 2] + R[2, 0]) / s
        q[3] = (R[2, 1] - R[1, 2]) / s
    elif R[1, 1] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q[0] = (R[0, 1] + R[1, 0]) / s
        q[1] = 0.25 * s
        q[2] = (R[1, 2] + R[2, 1]) / s
        q[3] = (R[0, 2] - R[2, 0]) / s
    else:
        s = 2.0 * np.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q[0] = (R[0, 2] + R[2, 0]) / s
        q[1] = (R[1, 2] + R[2, 1]) / s
        q[2] = 0.25 * s
        q[3] = (R[1, 0] - R[0, 1]) / s
    if q[3] < 0.0:
        for k in range(4):
            q[k] = -q[k]
    return quat_normalize(q)


@njit(cache=True)
def rotate_xyz(ux, uy, uz, w, vx, vy, vz):
    """``R(q) v`` for the unit quaternion q = (ux, uy, uz, w) on scalars (no allocation, for
    per-body inner loops): ``v' = v + w t + u x t`` with ``t = 2 u x v``, the sandwich
    ``q v q*`` without forming the matrix. The inverse rotation is u -> -u."""
    tx = 2.0 * (uy * vz - uz * vy)
    ty = 2.0 * (uz * vx - ux * vz)
    tz = 2.0 * (ux * vy - uy * vx)
    return (vx + w * tx + (uy * tz - uz * ty),
            vy + w * ty + (uz * tx - ux * tz),
            vz + w * tz + (ux * ty - uy * tx))


@njit(cache=True)
def _rotate(ux, uy, uz, w, v):
    x, y, z = rotate_xyz(ux, uy, uz, w, v[0], v[1], v[2])
    out = np.empty(3)
    out[0] = x
    out[1] = y
    out[2] = z
    return out


@njit(cache=True)
def quat_rotate(q, v):
    """``R(q) v`` (3,) for a unit quaternion q (x, y, z, w): e.g. body -> world."""
    return _rotate(q[0], q[1], q[2], q[3], v)


@njit(cache=True)
def quat_rotate_inv(q, v):
    """``R(q)^T v`` (3,) for a unit quaternion q (x, y, z, w): e.g. world -> body."""
    return _rotate(-q[0], -q[1], -q[2], q[3], v)


# --------------------------------------------------------------------------------------------
# Argument coercion and transforms (Python side)
# --------------------------------------------------------------------------------------------

def as_translation(value, name="translation") -> np.ndarray:
    if value is None:
        return np.zeros(3)
    t = np.asarray(value, dtype=np.float64).reshape(-1)
    if t.size != 3 or not np.all(np.isfinite(t)):
        raise PecletArgumentError(name, "3 finite numbers", value)
    return t.copy()


def as_quaternion(value, name="rotation") -> np.ndarray:
    """A unit quaternion (x, y, z, w); ``None`` is the identity. Input off unit norm by more
    than :data:`QUAT_NORM_TOL` is normalised (any finite magnitude, however large or small);
    zero or non-finite input raises :class:`PecletArgumentError` naming ``name``."""
    if value is None:
        return IDENTITY_QUAT.copy()
    try:
        q = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise PecletArgumentError(name, "a quaternion of 4 finite numbers (x, y, z, w)",
                                  value) from None
    if q.size != 4 or not np.all(np.isfinite(q)):
        raise PecletArgumentError(name, "a quaternion of 4 finite numbers (x, y, z, w)", value)
    q = np.ascontiguousarray(q)
    n = quat_norm(q)
    if n == 0.0:
        raise PecletArgumentError(name, "a non-zero quaternion (x, y, z, w)", value)
    if abs(n - 1.0) > QUAT_NORM_TOL:
        q = quat_normalize(q)
    return q.copy()


def as_scale(value, name="scale") -> float:
    if value is None:
        return 1.0
    s = float(value)
    if not (np.isfinite(s) and s > 0.0):
        raise PecletArgumentError(name, "a finite number > 0 (isotropic)", value)
    return s


def compose(outer, inner):
    """Compose transforms ``outer ∘ inner``; each is (t, q, s). Returns (t, q, s)."""
    t_o, q_o, s_o = outer
    t_i, q_i, s_i = inner
    q_o = np.ascontiguousarray(q_o, dtype=np.float64)
    q_i = np.ascontiguousarray(q_i, dtype=np.float64)
    t = t_o + s_o * (quat_to_matrix(q_o) @ t_i)
    q = quat_normalize(quat_multiply(q_o, q_i))
    return t, q, s_o * s_i


def transform_ball(centre, radius, t, q, s):
    """The ball (c, r) of a node's frame, expressed in its parent frame."""
    if not np.isfinite(radius):
        return np.asarray(t, float).copy(), float("inf")
    q = np.ascontiguousarray(q, dtype=np.float64)
    return t + s * (quat_to_matrix(q) @ centre), s * radius
