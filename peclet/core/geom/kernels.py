"""Numba kernels: the ONLY place a distance formula is written.

A tree is evaluated from a *program*: flat arrays produced once per root by
:mod:`peclet.core.geom.program`. Each program is a post-order list of operations

    ops[k] = (code, arg)      code 0 = push leaf row ``arg``; 32/33/34 = union/inter/diff

over a table of leaves whose transform to the world (root parent) frame is pre-composed:

    leaf_reals[j] = params[0:8], T[3], R[9] (row-major), S, pad

A world point p is mapped to the leaf frame as ``R^T (p - T) / S``; the leaf's value in the
world frame is ``S * f(.)`` and its gradient ``R grad f``. Because min/max commute with
positive scaling, this equals the node-by-node definition of docs/architecture.md §2.

Programs of many roots can share one pair of arrays; a root is then addressed by its
``[op_begin, op_end)`` range. Nothing here is compiled per tree: every tree goes through the same
machine code.

Conventions: phi < 0 inside, gradients point outward; ties in a CSG operator go to the LEFT
child; at a point where a leaf's gradient is undefined (a centre, an axis) a fixed unit vector
is returned (the +x direction, or the documented face normal).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .grid_kernel import grid_eval

#: Column layout of a leaf row.
LEAF_T = 8
LEAF_R = 11
LEAF_S = 20
LEAF_COLS = 24

OP_LEAF = 0
OP_UNION = 32
OP_INTERSECTION = 33
OP_DIFFERENCE = 34

#: Stack slots per point; the builder refuses trees that would need more.
MAX_STACK = 64
#: Columns of the scratch stack: phi, gradient (3), and the leaf row that produced phi.
STACK_COLS = 5

#: Points per parallel chunk. Fixed, so results never depend on the thread count.
CHUNK = 256


@njit(cache=True, inline="always")
def _sgn(v):
    return 1.0 if v >= 0.0 else -1.0


@njit(cache=True)
def _box2(u, w):
    """Signed distance in a 2-D frame where the box is {u <= 0, w <= 0}.

    Returns (d, du, dw, feature) with feature 0 where the u side dominates, 1 otherwise."""
    mu = u if u > 0.0 else 0.0
    mw = w if w > 0.0 else 0.0
    outside = math.sqrt(mu * mu + mw * mw)
    feat = 0 if u >= w else 1
    if outside > 0.0:
        return outside, mu / outside, mw / outside, feat
    if u >= w:
        return u, 1.0, 0.0, feat
    return w, 0.0, 1.0, feat


@njit(cache=True)
def _radial(x, z):
    """rho = |(x, z)| and the unit radial direction (ex, ez); +x on the axis."""
    rho = math.sqrt(x * x + z * z)
    if rho > 0.0:
        return rho, x / rho, z / rho
    return 0.0, 1.0, 0.0


@njit(cache=True)
def _segment2(px, py, ax, ay, bx, by):
    """Squared distance from (px, py) to segment a-b, and the vector from the closest point."""
    ex = bx - ax
    ey = by - ay
    ee = ex * ex + ey * ey
    t = 0.0
    if ee > 0.0:
        t = ((px - ax) * ex + (py - ay) * ey) / ee
        t = min(max(t, 0.0), 1.0)
    dx = px - (ax + t * ex)
    dy = py - (ay + t * ey)
    return dx * dx + dy * dy, dx, dy


@njit(cache=True)
def _box(L, j, x, y, z):
    """box: half extents hx, hy, hz (features 0..5: the faces +x, -x, +y, -y, +z, -z).
    Returns (phi, gx, gy, gz, feature), as :func:`leaf_eval`."""
    hx = L[j, 0]
    hy = L[j, 1]
    hz = L[j, 2]
    qx = abs(x) - hx
    qy = abs(y) - hy
    qz = abs(z) - hz
    if qx >= qy and qx >= qz:
        feat = 0 if x >= 0.0 else 1
    elif qy >= qz:
        feat = 2 if y >= 0.0 else 3
    else:
        feat = 4 if z >= 0.0 else 5
    mx = qx if qx > 0.0 else 0.0
    my = qy if qy > 0.0 else 0.0
    mz = qz if qz > 0.0 else 0.0
    outside = math.sqrt(mx * mx + my * my + mz * mz)
    if outside > 0.0:
        return (outside, _sgn(x) * mx / outside, _sgn(y) * my / outside,
                _sgn(z) * mz / outside, feat)
    if feat < 2:
        return qx, _sgn(x), 0.0, 0.0, feat
    if feat < 4:
        return qy, 0.0, _sgn(y), 0.0, feat
    return qz, 0.0, 0.0, _sgn(z), feat


@njit(cache=True)
def _capped_cone(L, j, x, y, z):
    """capped_cone about y: rBottom at y=-h, rTop at y=+h, h."""
    r1 = L[j, 0]
    r2 = L[j, 1]
    h = L[j, 2]
    rho, ex, ez = _radial(x, z)
    # distance to the three profile segments in the (rho, y) half-plane
    d2, vx, vy = _segment2(rho, y, 0.0, -h, r1, -h)
    nx, ny = 0.0, -1.0
    feat = 0
    e2, wx, wy = _segment2(rho, y, r1, -h, r2, h)
    if e2 < d2:
        d2, vx, vy = e2, wx, wy
        sl = math.sqrt(4.0 * h * h + (r2 - r1) * (r2 - r1))
        nx, ny = 2.0 * h / sl, -(r2 - r1) / sl
        feat = 1
    e2, wx, wy = _segment2(rho, y, r2, h, 0.0, h)
    if e2 < d2:
        d2, vx, vy = e2, wx, wy
        nx, ny = 0.0, 1.0
        feat = 2
    inside = abs(y) <= h and 2.0 * h * (rho - r1) <= (r2 - r1) * (y + h)
    d = math.sqrt(d2)
    if d > 0.0:
        s = -1.0 if inside else 1.0
        gr = s * vx / d
        gy = s * vy / d
    else:
        gr = nx
        gy = ny
    if inside:
        d = -d
    return d, gr * ex, gy, gr * ez, feat


@njit(cache=True)
def _ellipsoid(L, j, x, y, z):
    """ellipsoid: rx, ry, rz (a bound, not the distance)."""
    rx = L[j, 0]
    ry = L[j, 1]
    rz = L[j, 2]
    ax = x / rx
    ay = y / ry
    az = z / rz
    bx = ax / rx
    by = ay / ry
    bz = az / rz
    k0 = math.sqrt(ax * ax + ay * ay + az * az)
    k1 = math.sqrt(bx * bx + by * by + bz * bz)
    if k0 < 1e-100 or k1 < 1e-100:
        # at (or within 1e-100 of) the centre; k1^3 below would underflow to 0
        return -min(rx, min(ry, rz)), 1.0, 0.0, 0.0, 0
    v = k0 * (k0 - 1.0) / k1
    # grad k0 = (x/r^2)/k0 = b/k0; grad k1 = (x/r^4)/k1 = (b/r^2)/k1
    c0 = (2.0 * k0 - 1.0) / (k0 * k1)
    c1 = k0 * (k0 - 1.0) / (k1 * k1 * k1)
    return (v, c0 * bx - c1 * bx / (rx * rx), c0 * by - c1 * by / (ry * ry),
            c0 * bz - c1 * bz / (rz * rz), 0)


@njit(cache=True)
def _superquadric(L, j, x, y, z):
    """superquadric: rx, ry, rz, e (a bound, not the distance)."""
    rx = L[j, 0]
    ry = L[j, 1]
    rz = L[j, 2]
    m = 2.0 / L[j, 3]
    rmin = min(rx, min(ry, rz))
    ax = abs(x) / rx
    ay = abs(y) / ry
    az = abs(z) / rz
    amax = max(ax, max(ay, az))
    if amax == 0.0:
        return -rmin, 1.0, 0.0, 0.0, 0
    g = (ax / amax) ** m + (ay / amax) ** m + (az / amax) ** m
    f = amax * g ** (1.0 / m)
    # n = grad F, homogeneous of degree 0 so never zero away from the origin
    tx = ax / f
    ty = ay / f
    tz = az / f
    nx = tx ** (m - 1.0) * _sgn(x) / rx
    ny = ty ** (m - 1.0) * _sgn(y) / ry
    nz = tz ** (m - 1.0) * _sgn(z) / rz
    nn2 = nx * nx + ny * ny + nz * nz
    nn = math.sqrt(nn2)
    d = (f - 1.0) / nn
    if d < -rmin:
        return -rmin, 0.0, 0.0, 0.0, 1
    # grad d = n/|n| - (F - 1) H n / |n|^3, H the Hessian of F (see the leaf table docs)
    k = (m - 1.0) / f
    hx = k * tx ** (m - 2.0) / rx * (nx / rx - _sgn(x) * ax * nn2 / f)
    hy = k * ty ** (m - 2.0) / ry * (ny / ry - _sgn(y) * ay * nn2 / f)
    hz = k * tz ** (m - 2.0) / rz * (nz / rz - _sgn(z) * az * nn2 / f)
    c = (f - 1.0) / (nn2 * nn)
    return d, nx / nn - c * hx, ny / nn - c * hy, nz / nn - c * hz, 0


@njit(cache=True)
def leaf_eval(kind, L, j, x, y, z):
    """Value, gradient and feature of leaf row ``j`` of ``L`` at canonical point (x, y, z).

    Returns (phi, gx, gy, gz, feature). ``feature`` numbers the smooth piece of the leaf's
    surface that is active (a box face, a profile segment of a cone, a cap or a wall of a
    tube; 0 for smooth leaves): it changes exactly across the leaf's own creases, which the
    quadrature uses as breakpoints. An unknown kind returns NaN: the builder refuses unknown
    kinds, so a NaN here means a corrupted table, and the caller's finite check reports it.
    The longer formulas are functions of their own (:func:`_box`, :func:`_capped_cone` and
    the bounds :func:`_ellipsoid`, :func:`_superquadric`).
    """
    if kind == 1:  # sphere
        r = L[j, 0]
        n = math.sqrt(x * x + y * y + z * z)
        if n > 0.0:
            return n - r, x / n, y / n, z / n, 0
        return -r, 1.0, 0.0, 0.0, 0

    if kind == 2:  # hollow_cylinder about y: rOuter, height, thickness
        ro = L[j, 0]
        hh = 0.5 * L[j, 1]
        ht = 0.5 * L[j, 2]
        rho, ex, ez = _radial(x, z)
        du = rho - (ro - ht)
        d, gu, gw, f = _box2(abs(du) - ht, abs(y) - hh)
        gr = gu * _sgn(du)
        # features: 0 outer wall, 1 inner wall, 2 top cap, 3 bottom cap
        feat = (0 if du >= 0.0 else 1) if f == 0 else (2 if y >= 0.0 else 3)
        return d, gr * ex, gw * _sgn(y), gr * ez, feat

    if kind == 3:  # box
        return _box(L, j, x, y, z)

    if kind == 4:  # hollow_cylinder_shell about z: rOuter, rInner, height
        rho, ex, ey = _radial(x, y)
        a = rho - L[j, 0]
        b = L[j, 1] - rho
        c = abs(z) - 0.5 * L[j, 2]
        if a >= b and a >= c:
            return a, ex, ey, 0.0, 0
        if b >= c:
            return b, -ex, -ey, 0.0, 1
        return c, 0.0, 0.0, _sgn(z), (2 if z >= 0.0 else 3)

    if kind == 5:  # capsule about y: radius, halfLength
        hl = L[j, 1]
        cy = min(max(y, -hl), hl)
        dy = y - cy
        feat = 0 if dy == 0.0 else (1 if dy > 0.0 else 2)
        n = math.sqrt(x * x + dy * dy + z * z)
        if n > 0.0:
            return n - L[j, 0], x / n, dy / n, z / n, feat
        return -L[j, 0], 1.0, 0.0, 0.0, feat

    if kind == 6:  # torus about y: R, r
        rho, ex, ez = _radial(x, z)
        a = rho - L[j, 0]
        n = math.sqrt(a * a + y * y)
        if n > 0.0:
            ga = a / n
            return n - L[j, 1], ga * ex, y / n, ga * ez, 0
        return -L[j, 1], ex, 0.0, ez, 0

    if kind == 7:  # capped_cone
        return _capped_cone(L, j, x, y, z)

    if kind == 8:  # ellipsoid (a bound)
        return _ellipsoid(L, j, x, y, z)

    if kind == 9:  # superquadric (a bound)
        return _superquadric(L, j, x, y, z)

    if kind == 10:  # half_space: unit normal n, offset
        nx = L[j, 0]
        ny = L[j, 1]
        nz = L[j, 2]
        return nx * x + ny * y + nz * z - L[j, 3], nx, ny, nz, 0

    if kind == 0:  # grid: a sampled field (grid_kernel.py)
        return grid_eval(L, j, x, y, z)

    return np.nan, np.nan, np.nan, np.nan, 0


#: Features per leaf in the active-feature id ``leaf_row * FEATURES + feature``.
FEATURES = 8


@njit(cache=True)
def eval_point(ops, leaf_kind, leaf_reals, op_begin, op_end, x, y, z, st):
    """Evaluate the program ``ops[op_begin:op_end]`` at world point (x, y, z).

    ``st`` is a scratch array (MAX_STACK, STACK_COLS). Returns (phi, gx, gy, gz); afterwards
    ``st[0, 4]`` holds the active feature ``leaf_row * FEATURES + feature`` (the leaf whose
    value phi is, ties going left, and its active surface piece), which the quadrature uses to
    locate creases.
    """
    sp = 0
    L = leaf_reals
    for k in range(op_begin, op_end):
        code = ops[k, 0]
        if code == OP_LEAF:
            j = ops[k, 1]
            dx = x - L[j, 8]
            dy = y - L[j, 9]
            dz = z - L[j, 10]
            s = L[j, 20]
            # R^T d / S with R row-major in columns 11..19
            lx = (L[j, 11] * dx + L[j, 14] * dy + L[j, 17] * dz) / s
            ly = (L[j, 12] * dx + L[j, 15] * dy + L[j, 18] * dz) / s
            lz = (L[j, 13] * dx + L[j, 16] * dy + L[j, 19] * dz) / s
            v, gx, gy, gz, feat = leaf_eval(leaf_kind[j], L, j, lx, ly, lz)
            st[sp, 0] = s * v
            st[sp, 1] = L[j, 11] * gx + L[j, 12] * gy + L[j, 13] * gz
            st[sp, 2] = L[j, 14] * gx + L[j, 15] * gy + L[j, 16] * gz
            st[sp, 3] = L[j, 17] * gx + L[j, 18] * gy + L[j, 19] * gz
            st[sp, 4] = j * FEATURES + feat
            sp += 1
        else:
            sp -= 1
            a = st[sp - 1, 0]
            b = st[sp, 0]
            if code == OP_UNION:
                if b < a:
                    st[sp - 1, 0] = b
                    st[sp - 1, 1] = st[sp, 1]
                    st[sp - 1, 2] = st[sp, 2]
                    st[sp - 1, 3] = st[sp, 3]
                    st[sp - 1, 4] = st[sp, 4]
            elif code == OP_INTERSECTION:
                if b > a:
                    st[sp - 1, 0] = b
                    st[sp - 1, 1] = st[sp, 1]
                    st[sp - 1, 2] = st[sp, 2]
                    st[sp - 1, 3] = st[sp, 3]
                    st[sp - 1, 4] = st[sp, 4]
            else:
                if -b > a:
                    st[sp - 1, 0] = -b
                    st[sp - 1, 1] = -st[sp, 1]
                    st[sp - 1, 2] = -st[sp, 2]
                    st[sp - 1, 3] = -st[sp, 3]
                    st[sp - 1, 4] = st[sp, 4]
    return st[0, 0], st[0, 1], st[0, 2], st[0, 3]


@njit(cache=True, parallel=True)
def eval_points(ops, leaf_kind, leaf_reals, op_begin, op_end, points, out_phi, out_grad,
                with_grad):
    """phi (and, if ``with_grad``, the gradient) of one program at every row of ``points``.

    Parallel over fixed-size chunks of points; each point is independent, so the result is
    bitwise the same at any thread count.
    """
    n = points.shape[0]
    nchunk = (n + CHUNK - 1) // CHUNK
    for c in prange(nchunk):
        st = np.empty((MAX_STACK, STACK_COLS))
        i1 = min(n, (c + 1) * CHUNK)
        for i in range(c * CHUNK, i1):
            v, gx, gy, gz = eval_point(ops, leaf_kind, leaf_reals, op_begin, op_end,
                                       points[i, 0], points[i, 1], points[i, 2], st)
            out_phi[i] = v
            if with_grad:
                out_grad[i, 0] = gx
                out_grad[i, 1] = gy
                out_grad[i, 2] = gz


@njit(cache=True, parallel=True)
def bake_lattice(ops, leaf_kind, leaf_reals, op_begin, op_end, origin, spacing, dims, band,
                 out):
    """phi on the lattice origin + (i, j, k) * spacing, flattened with x fastest.

    Coordinates are formed as ``origin[a] + idx * spacing[a]``, exactly as NumPy forms
    ``origin + np.arange(n) * spacing``, so a baked value equals eval at the same point
    bitwise. With ``band < 0`` every value is evaluated. With ``band >= 0`` (only for a
    1-Lipschitz program) each x-row is sphere-traced: after a value f, the points closer than
    ``|f| - band`` are not evaluated but given ``sign(f) (|f| - distance)``, a bound of the
    right sign with magnitude > band. So every value with |phi| <= band is exact; marching
    cubes with band >= the lattice cell's diagonal sees the same sign-changing cells with the
    same corner values, i.e. returns the same mesh, for a fraction of the evaluations.
    """
    nx = dims[0]
    ny = dims[1]
    nz = dims[2]
    nrow = ny * nz
    for r in prange(nrow):
        st = np.empty((MAX_STACK, STACK_COLS))
        jy = r % ny
        kz = r // ny
        y = origin[1] + jy * spacing[1]
        z = origin[2] + kz * spacing[2]
        base = r * nx
        i = 0
        while i < nx:
            x = origin[0] + i * spacing[0]
            v, gx, gy, gz = eval_point(ops, leaf_kind, leaf_reals, op_begin, op_end, x, y, z,
                                       st)
            out[base + i] = v
            i += 1
            if band >= 0.0:
                # reach shortened by a relative 1e-9 against round-off in the coordinates
                reach = (abs(v) - band) * (1.0 - 1e-9)
                s = 1.0 if v >= 0.0 else -1.0
                while i < nx:
                    d = (origin[0] + i * spacing[0]) - x
                    if d >= reach:
                        break
                    out[base + i] = s * (abs(v) - d)
                    i += 1
