"""Composed (CSG) particles: one Hertz patch per touching region, solved exactly every substep.

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
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from peclet.core.validation import PecletArgumentError

from . import dispatch
from .calibration import RATIO_LIMIT
from .fields import field, hessian, pair_of, shapes_of, surface_curvature, tangents, tt

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
#: than RATIO_LIMIT (:mod:`peclet.dem.hertz.calibration`: a line-like contact, a cylinder on its
#: side, an edge).
#: At most this many patches per body pair.
MAX_PATCHES = 16
#: Two patch solves of a pair that end closer than this fraction of the length scale found
#: the same patch.
SAME_PATCH = 1e-7
#: Feature ids of the seeds whose patch solve failed (kept to watch their probe) carry this bit.
FAILED_FEATURE = 1 << 25

#: Patch status codes (the kernels' ``status`` arrays; anything but OK on a touching patch is
#: refused by :func:`raise_patch_error`).
PATCH_OK = 0
PATCH_NO_CONVERGENCE = 1
PATCH_NOT_CONVEX = 2
PATCH_DEEP = 3
PATCH_LINE = 4
PATCH_PROBE_INSIDE = 5
PATCH_TOO_MANY = 6

PATCH_REASONS = {
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



def raise_patch_error(a, b, status):
    """Raise :class:`HertzPatchError` for the first row whose status is not PATCH_OK."""
    bad = np.flatnonzero(status != PATCH_OK)
    if len(bad):
        i = int(bad[0])
        raise HertzPatchError(a[i], b[i], PATCH_REASONS[int(status[i])])


@njit(cache=True)
def solve_patch(p, x0, y0, z0, Ha, Hb, out):
    """The contact of one patch of the :class:`~peclet.dem.hertz.fields.Pair` ``p`` between
    side a (a body: sphere or tree, sign +1) and side b (a body, or a wall with its sign), by Newton's method from (x0, y0, z0): the point where
    the two unit gradients are opposite and the two distance estimates phi/|grad phi| are
    equal (midway between the surfaces; for exact distance fields the stationary point of
    d_a + d_b on that mid-surface). Writes ``out`` = (point (3), normal from b to a (3), gap
    d_a + d_b, R* (the elliptical-Hertz radius), R' <= R'' the principal radii of relative
    curvature at the surfaces) and returns a status: PATCH_OK, PATCH_NO_CONVERGENCE,
    PATCH_NOT_CONVEX (the relative curvature is not positive definite) or PATCH_LINE (R''/R'
    beyond RATIO_LIMIT); ``out[6]`` always holds the gap at the last point evaluated."""
    A, B, sh, scale, st = p
    ctab_t, ctab_c = sh.ctab_t, sh.ctab_c
    h = FD_STEP * scale
    tol = PATCH_TOL * scale
    cap = 0.25 * scale
    x, y, z = x0, y0, z0
    t = np.empty(6)
    for it in range(PATCH_MAX_ITER):
        pa, gax, gay, gaz = field(A, sh, x, y, z, st)
        pb, gbx, gby, gbz = field(B, sh, x, y, z, st)
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
        t[0], t[1], t[2], t[3], t[4], t[5] = tangents(nx, ny, nz)
        hessian(A, sh, x, y, z, h, st, Ha)
        hessian(B, sh, x, y, z, h, st, Hb)
        m11 = (tt(Ha, t[0], t[1], t[2], t[0], t[1], t[2]) / na
               + tt(Hb, t[0], t[1], t[2], t[0], t[1], t[2]) / nb)
        m12 = (tt(Ha, t[0], t[1], t[2], t[3], t[4], t[5]) / na
               + tt(Hb, t[0], t[1], t[2], t[3], t[4], t[5]) / nb)
        m22 = (tt(Ha, t[3], t[4], t[5], t[3], t[4], t[5]) / na
               + tt(Hb, t[3], t[4], t[5], t[3], t[4], t[5]) / nb)
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
            c11, c12, c22 = surface_curvature(Ha, na, da, t)
            e11, e12, e22 = surface_curvature(Hb, nb, db, t)
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


class PatchRows(NamedTuple):
    """Per patch: bodies ``a``, ``b``, b's image ``shift`` (P, 3), the ``mode`` (0 a patch, 1 /
    2 a watched probe of a / of b) and the tracked point ``u`` (P, 3) in a's home frame (b's
    for mode 2)."""
    a: np.ndarray
    b: np.ndarray
    shift: np.ndarray
    mode: np.ndarray
    u: np.ndarray


class PatchOut(NamedTuple):
    """Per patch: point (P, 3), normal (P, 3) from b to a, gap (P,), R* (P,), the principal
    radii of relative curvature (P, 2), the new tracked point (P, 3), the status (P,)."""
    point: np.ndarray
    normal: np.ndarray
    gap: np.ndarray
    rstar: np.ndarray
    radii2: np.ndarray
    unew: np.ndarray
    status: np.ndarray


@njit(cache=True)
def _patch_one(i, rows, sh, res_):
    """Patch i of :func:`patch_geometry` (writes only row i)."""
    a, b, shift, mode, u = rows
    point, normal, gap, rstar, radii2, unew, status = res_
    Ha = np.empty((3, 3))
    Hb = np.empty((3, 3))
    out = np.empty(10)
    p = pair_of(a[i], b[i], shift[i], sh)
    A, B, _, scale, st = p
    xa, Ra, xb, Rb = A.x, A.R, B.x, B.R
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
            ph, gx, gy, gz = field(B, sh, px, py, pz, st)
        else:
            ph, gx, gy, gz = field(A, sh, px, py, pz, st)
        if ph < 0.0:
            status[i] = PATCH_PROBE_INSIDE
        return
    res = solve_patch(p, px, py, pz, Ha, Hb, out)
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


patches_loops = dispatch.row_loops(_patch_one)


def patch_geometry(a, b, shift, mode, u, first, pos, rot, shape_of, geo):
    """The exact contact of every composed patch (rows of the candidate list's composed part),
    each solved by Newton's method from its tracked point ``u`` (a's home frame; b's for
    ``mode`` 2): returns (point (P, 3), normal (P, 3) from b to a, gap (P,), R* (P,), the
    principal radii of relative curvature (P, 2), the new tracked points (P, 3), status (P,)).
    A patch that does not touch has gap +inf; a status other than PATCH_OK marks a touching
    contact the law cannot represent. ``first`` (P,): each row's pair's first row. Serial
    below the package setting ``PATCH_PARALLEL_MIN`` patches."""
    n = len(a)
    point = np.empty((n, 3))
    normal = np.empty((n, 3))
    gap = np.empty(n)
    rstar = np.empty(n)
    radii2 = np.empty((n, 2))
    unew = np.empty((n, 3))
    status = np.empty(n, np.int64)
    dispatch.run(patches_loops, n, "PATCH_PARALLEL_MIN",
                 PatchRows(a, b, shift, mode, u), shapes_of(pos, rot, shape_of, geo),
                 PatchOut(point, normal, gap, rstar, radii2, unew, status))
    _patch_dedupe(first, a, b, shape_of, geo.shape_rad, point, gap, status)
    return point, normal, gap, rstar, radii2, unew, status
