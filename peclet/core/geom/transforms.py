"""Conformal transforms on the Python side: quaternions (x, y, z, w), active rotation.

A transform ``(t, q, s)`` maps a point of a node's own frame to its parent's frame as
``p_parent = s R(q) p_local + t``; the node's value in the parent frame is
``s * f(R(q)^T (p_parent - t) / s)`` (DESIGN.md §2).
"""
from __future__ import annotations

import numpy as np

IDENTITY_QUAT = np.array([0.0, 0.0, 0.0, 1.0])

#: A quaternion whose norm differs from 1 by more than this is normalised. Below it the value is
#: kept bit for bit, so that encode -> decode -> encode is the identity.
QUAT_NORM_TOL = 1e-14


def as_translation(value, name="translation") -> np.ndarray:
    if value is None:
        return np.zeros(3)
    t = np.asarray(value, dtype=np.float64).reshape(-1)
    if t.size != 3 or not np.all(np.isfinite(t)):
        raise ValueError(f"{name} must be 3 finite numbers, got {value!r}")
    return t.copy()


def as_quaternion(value, name="rotation") -> np.ndarray:
    """A unit quaternion (x, y, z, w). Non-unit input is normalised; zero is an error."""
    if value is None:
        return IDENTITY_QUAT.copy()
    q = np.asarray(value, dtype=np.float64).reshape(-1)
    if q.size != 4 or not np.all(np.isfinite(q)):
        raise ValueError(f"{name} must be a quaternion of 4 finite numbers (x, y, z, w), "
                         f"got {value!r}")
    n = float(np.sqrt(q @ q))
    if n == 0.0:
        raise ValueError(f"{name} must be a non-zero quaternion (x, y, z, w), got zero")
    if abs(n - 1.0) > QUAT_NORM_TOL:
        q = q / n
    return q.copy()


def as_scale(value, name="scale") -> float:
    if value is None:
        return 1.0
    s = float(value)
    if not (np.isfinite(s) and s > 0.0):
        raise ValueError(f"{name} must be a finite number > 0 (isotropic), got {value!r}")
    return s


def quat_to_matrix(q) -> np.ndarray:
    """Rotation matrix of a unit quaternion (x, y, z, w)."""
    x, y, z, w = (float(v) for v in q)
    return np.array([
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w)],
        [2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w)],
        [2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y)],
    ])


def matrix_to_quat(R) -> np.ndarray:
    """Unit quaternion (x, y, z, w) with w >= 0 of a proper rotation matrix (Shepperd's method)."""
    R = np.asarray(R, dtype=np.float64)
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    if tr > 0.0:
        s = 2.0 * np.sqrt(1.0 + tr)
        q = np.array([(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s,
                      (R[1, 0] - R[0, 1]) / s, 0.25 * s])
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = np.array([0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s,
                      (R[2, 1] - R[1, 2]) / s])
    elif R[1, 1] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = np.array([(R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s,
                      (R[0, 2] - R[2, 0]) / s])
    else:
        s = 2.0 * np.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = np.array([(R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s,
                      (R[1, 0] - R[0, 1]) / s])
    if q[3] < 0.0:
        q = -q
    return q / np.linalg.norm(q)


def quat_multiply(a, b) -> np.ndarray:
    """Hamilton product a * b of (x, y, z, w) quaternions: rotate by b, then by a."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ])


def compose(outer, inner):
    """Compose transforms ``outer ∘ inner``; each is (t, q, s). Returns (t, q, s)."""
    t_o, q_o, s_o = outer
    t_i, q_i, s_i = inner
    t = t_o + s_o * (quat_to_matrix(q_o) @ t_i)
    q = quat_multiply(q_o, q_i)
    q = q / np.sqrt(q @ q)
    return t, q, s_o * s_i


def transform_ball(centre, radius, t, q, s):
    """The ball (c, r) of a node's frame, expressed in its parent frame."""
    if not np.isfinite(radius):
        return np.asarray(t, float).copy(), float("inf")
    return t + s * (quat_to_matrix(q) @ centre), s * radius
