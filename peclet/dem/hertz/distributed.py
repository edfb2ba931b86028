"""Composed particles: distributed contacts (flat, line, edge and corner contacts).

Distributed contacts (flat, line, edge, corner). Where the patch law fails on a touching
patch (no positive relative curvature: a face on a face or a wall, a cylinder on its side,
an edge or a corner; R''/R' > RATIO_LIMIT; delta > DELTA_LIMIT x R'; a probe inside the other
body where no patch solves; more than MAX_PATCHES patches), or a pair with such a failed seed
has no touching Hertz patch, the whole pair gets ONE distributed contact instead
(:func:`distributed_geometry`, every substep). Pairs that the patch law holds are untouched
(bit for bit). The law::

    normal n: the other body's outward unit normal at the deepest probe (of a in b or b in a)
    region:   the overlap of the two bodies seen along n, sampled on a DIST_GRID^2 grid in the
              plane normal to n, zoomed onto the region (a coarse look, then boxes around the
              inside nodes along their principal axes; a region thinner than the spacing, a
              line, is found from a quadratic model of m and a row of nodes put through it),
              each inside node's cell cut at the region's boundary by bisection; inside means
              m = min_s max(phi_a, phi_b) < 0 along the node's normal line (1-Lipschitz, so a
              node with m > half the cell diagonal rules its cell out)
    fallback: when the search neither finds an overlap nor rules one out on its first, whole
              box: along a second normal (the deepest probe whose normal is more than
              DIST_DISTINCT from the first's), and, for a contact that touched in the last
              substep, along both on a grid DIST_FALLBACK times finer; of the first two that
              find the overlap, the one with the shorter largest chord (the direction of
              least penetration). A search that finds its overlap at once is unchanged.
    overlap:  d(x) = the chord of the intersection along n at x (Newton to both surfaces);
              V = sum d w, A = sum w over the cells (w their areas), J their second moments
    law:      p(x) = k d(x),  k = pi a E* / (K(e) A),  F = k V,  S = k A
              a, b the ellipse of area A with J's principal ratio (a / b = sqrt(J1 / J2)),
              e^2 = 1 - b^2 / a^2, K the complete elliptic integral of the first kind

k makes the region's rigid flat punch exact for an ellipse: F = pi a E* delta / K(e) (the flat
elliptical punch; a circle, K = pi / 2, gives F = 2 a E* delta, Johnson 1985 §3.8). Accuracy
against closed forms (E* the pair's, the bodies taken as half-spaces): a square punch 0.6 %
softer than Gazetas' rigid-footing fit (the equal-area disc has the least stiffness of all
plane shapes of its area, Polya-Szego); a cylinder of length L on its side: F = k V gives
F ~ 1.18 E* L delta / ln(2 L / b_g) (b_g = sqrt(2 R delta)), 4-6 % softer than Lundberg's
finite line contact delta = 2 F / (pi L E*) (1.8864 + ln(L / 2 b)) (chosen over Johnson §4.3's
two-dimensional approach, which needs a datum, and over the "simple" F = pi/4 E* L delta of
two-dimensional DEM, ~3.5x stiffer than either at these loads); a cone / corner 4.7 % stiffer
than Sneddon's F = (2 / pi) E* cot(theta) delta^2; a sphere 6 % stiffer than Hertz (such
patches take the exact Hertz path anyway). It acts at the pressure centroid of the region,
along n (exact torque for one plane region). Through the same force kernel: delta_h = 3 F /
(2 S) and R*_h with 4/3 E* sqrt(R*_h) delta_h^1.5 = F, so that the kernel's S_n = S, the
Mindlin spring is S_t = 4 (G* / E*) S (Mindlin's ratio), truncated at Coulomb as before, and
the Tsuji dashpot gamma sqrt(S m*) uses gamma from :func:`damping_gamma_linear` (the same
calibration for the linear law x'' = -max(0, x + gamma x'): exact e for a flat punch; for a
line contact F is linear up to the log; for a corner, F ~ delta^2, the rebound differs from e).
Key: the pair and DIST_FEATURE (one per pair, stable across rebuilds; the history carries
over). ``hertz_contacts`` lists the contact with depth = the largest chord. Limits: one
region and one normal per pair (two separate regions of a pair are lumped into one ellipse,
their couple about n lost); the normal is a probe's, so it can jump between neighbouring
probes on a curved surface, and where two rims or edges cross the overlap lies between the
probes (none inside), the nearest probe outside it sets n, and n can turn by tens of degrees
in a substep (the largest chord then reads up to ~2x longer: the fallback's choice of the
shorter chord covers only the fallback); a new region found at no grid node within
DIST_ZOOMS zooms exerts no force until it grows (a touching one gets the fallback); a switch between the patch law and the distributed law is a jump of a
few % in force and restarts the Mindlin history. Refused with :class:`HertzPatchError` (a
PecletArgumentError naming both bodies; the state of the failing substep's start kept): a
distributed contact whose largest chord exceeds DIST_DEEP_LIMIT x the smaller bounding radius.
Rolling resistance acts on it with the bounding spheres' R* (see "Rolling resistance").
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from . import dispatch
from .fields import field, pair_of, shapes_of
from .overlap import DIST_BISECT, DIST_GRID, DIST_UNRESOLVED, DIST_ZOOMS, dist_region
from .patch import PATCH_OK

#: A distributed contact's second normal candidate differs from the first by more than this
#: angle (rad).
DIST_DISTINCT = math.radians(30.0)
#: The fallback search's grid is this many times finer.
DIST_FALLBACK = 4


class DistRows(NamedTuple):
    """Per pair: bodies ``a``, ``b``, b's image ``shift`` (P, 3), E* and ``touched`` (int64:
    its distributed contact touched in the last substep)."""
    a: np.ndarray
    b: np.ndarray
    shift: np.ndarray
    estar: np.ndarray
    touched: np.ndarray


class DistOut(NamedTuple):
    """Per pair: ``out`` (P, 13) (see :func:`distributed_geometry`) and the ``status`` (P,)."""
    out: np.ndarray
    status: np.ndarray


@njit(cache=True)
def _nearest_probe(p, pa0, pa1, pb0, pb1, excl, cmax, n, y0):
    """The deepest probe (of a in b, or of b in a; the smallest phi / |grad phi| in the other
    body, +inf when no probe is in reach, returned) with the other body's outward unit
    normal there (from b to a) into ``n`` and the probe into ``y0``; with ``excl`` only
    among the probes whose normal has a cosine below ``cmax`` with ``n``'s incoming value."""
    A, B, sh, scale, st = p
    xa, Ra, rada, xb, Rb, radb = A.x, A.R, A.rad, B.x, B.R, B.rad
    probes = sh.probes
    best = np.inf
    e0, e1, e2 = n[0], n[1], n[2]
    for side in range(2):
        q0, q1 = (pa0, pa1) if side == 0 else (pb0, pb1)
        xo, Ro = (xa, Ra) if side == 0 else (xb, Rb)
        for j in range(q0, q1):
            q = probes[j]
            px = xo[0] + Ro[0, 0] * q[0] + Ro[0, 1] * q[1] + Ro[0, 2] * q[2]
            py = xo[1] + Ro[1, 0] * q[0] + Ro[1, 1] * q[1] + Ro[1, 2] * q[2]
            pz = xo[2] + Ro[2, 0] * q[0] + Ro[2, 1] * q[1] + Ro[2, 2] * q[2]
            if side == 0:
                if radb < np.inf and ((px - xb[0]) ** 2 + (py - xb[1]) ** 2
                                      + (pz - xb[2]) ** 2) > (radb + scale) ** 2:
                    continue
                ph, gx, gy, gz = field(B, sh, px, py,
                                        pz, st)
                sg = 1.0
            else:
                if ((px - xa[0]) ** 2 + (py - xa[1]) ** 2 + (pz - xa[2]) ** 2) \
                        > (rada + scale) ** 2:
                    continue
                ph, gx, gy, gz = field(A, sh, px, py,
                                        pz, st)
                sg = -1.0
            gn = math.sqrt(gx * gx + gy * gy + gz * gz)
            if not (gn > 0.0):
                continue
            d = ph / gn
            if d < best:
                if excl and sg * (gx * e0 + gy * e1 + gz * e2) / gn >= cmax:
                    continue
                best = d
                n[0], n[1], n[2] = sg * gx / gn, sg * gy / gn, sg * gz / gn
                y0[0], y0[1], y0[2] = px, py, pz
    return best



@njit(cache=True)
def dist_pair(p, pa0, pa1, pb0, pb1, N, zooms, nbis, estar, touched, out):
    """The distributed contact of the :class:`~peclet.dem.hertz.fields.Pair` ``p`` (module
    docstring): writes ``out`` = (point (3), normal from b to a (3), largest overlap, elastic force, stiffness S = k A,
    area A, overlap volume V, equivalent ellipse semi-axes a, b) and returns PATCH_OK (force 0
    when nothing overlaps) or PATCH_DIST_DEEP. Probes [pa0, pa1) are a's (home frame),
    [pb0, pb1) b's; they only fix the normal (the deepest one's, the other body's outward
    normal there). ``touched``: the pair's distributed contact touched in the last substep
    (it then gets the fallback search of the module docstring when nothing is found)."""
    for e in range(out.shape[0]):
        out[e] = 0.0
    n = np.zeros(3)
    y0 = np.zeros(3)
    best = _nearest_probe(p, pa0, pa1, pb0, pb1, False, 1.0, n, y0)
    if best == np.inf:
        return PATCH_OK
    res = dist_region(p, N, zooms, nbis, estar, n, y0, out)
    if res != DIST_UNRESOLVED:
        return res
    # Neither found nor ruled out. Where two bodies' rims or edges cross, the overlap (0.2-0.5
    # mm in a ring bed, against the grid's 1.2 mm cells) lies between the probes, the nearest
    # probe outside it sets the normal, and the region can fall between the nodes at every
    # zoom: a pair carrying 8 N lost it for 17 substeps and was found again deeper. Tried in
    # turn: the nearest probe with a normal more than DIST_DISTINCT from the first's, and, for
    # a contact that touched a substep ago, both normals on a grid DIST_FALLBACK times finer;
    # of the first two that find the overlap the shorter one is kept (the direction of least
    # penetration: along the other normal an overlap read 0.5 mm against 0.27 mm).
    n2 = n.copy()
    y2 = np.zeros(3)
    best2 = _nearest_probe(p, pa0, pa1, pb0, pb1, True, math.cos(DIST_DISTINCT), n2, y2)
    alt = np.empty(out.shape[0])
    found = 0
    res = PATCH_OK
    for k in range(3):
        # k = 0: the second normal; 1, 2: the first and the second on the finer grid
        if (k != 1 and best2 == np.inf) or (k > 0 and not touched):
            continue
        nk, yk = (n, y0) if k == 1 else (n2, y2)
        r = dist_region(p, N if k == 0 else DIST_FALLBACK * N, zooms, nbis, estar, nk, yk,
                        alt)
        if r == DIST_UNRESOLVED:
            continue
        if found == 0 or alt[6] < out[6]:
            for e in range(out.shape[0]):
                out[e] = alt[e]
            res = r
        found += 1
        if found == 2:
            break
    return res


@njit(cache=True)
def _dist_one(i, rows, sh, N, zooms, nbis, res):
    """Distributed contact i of :func:`distributed_geometry` (writes only row i)."""
    a, b, shift, estar, touched = rows
    out, status = res
    ia = a[i]
    ib = b[i]
    p = pair_of(ia, ib, shift[i], sh)
    shape_of, shape_p0, shape_np = sh.shape_of, sh.shape_p0, sh.shape_np
    pa0 = pa1 = pb0 = pb1 = 0
    if p.a.kind == 1:
        pa0 = shape_p0[shape_of[ia]]
        pa1 = pa0 + shape_np[shape_of[ia]]
    if ib >= 0 and p.b.kind == 1:
        pb0 = shape_p0[shape_of[ib]]
        pb1 = pb0 + shape_np[shape_of[ib]]
    status[i] = dist_pair(p, pa0, pa1, pb0, pb1, N, zooms, nbis, estar[i], touched[i] != 0,
                          out[i])


dist_loops = dispatch.row_loops(_dist_one)


def distributed_geometry(a, b, shift, pos, rot, shape_of, geo, estar, touched=None):
    """The distributed contact of each pair (a[i], b[i] at image shift[i]; E* per pair):
    (out (P, 13): point (3), normal (3), largest overlap, elastic force, stiffness S, area,
    overlap volume, ellipse semi-axes; status (P,)). A pair with nothing overlapping has
    force 0. ``touched`` (P,) bool: the pair's distributed contact touched in the last
    substep (the fallback search; None: none did). Serial below the package setting
    ``DIST_PARALLEL_MIN`` pairs."""
    n = len(a)
    touched = np.zeros(n, np.int64) if touched is None else np.asarray(touched, np.int64)
    out = np.zeros((n, 13))
    status = np.zeros(n, np.int64)
    rows = DistRows(np.asarray(a, np.int64), np.asarray(b, np.int64),
                    np.ascontiguousarray(shift), np.ascontiguousarray(estar, dtype=np.float64),
                    touched)
    dispatch.run(dist_loops, n, "DIST_PARALLEL_MIN", rows,
                 shapes_of(pos, rot, shape_of, geo), np.int64(DIST_GRID), np.int64(DIST_ZOOMS),
                 np.int64(DIST_BISECT), DistOut(out, status))
    return out, status
