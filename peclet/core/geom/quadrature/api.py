"""The quadrature's public API: BodyProperties, body_properties, principal_frame, the checks.

Mass properties of a CSG solid by implicit quadrature (sign of phi only). Method: an adaptive
octree of cells (:mod:`.refine`) with a Saye-style height-function rule in each cut cell
(Saye, SIAM J. Sci. Comput. 37(2) A993, 2015; :mod:`.cell_rule`), extended with exact
breakpoints at CSG creases (:mod:`.breaks`), the height integral done exactly by a certified
line search (:mod:`.line_search`). The package docstring summarises the algorithm.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ...validation import PecletArgumentError, check_float, check_int
from ..transforms import matrix_to_quat
from .constants import CERTIFY_TOL, LINE_EXTRA, LINE_EXTRA_LOOSE, MAX_BREAKS, V_PROBES
from .refine import arrays_key, integrate_body


@dataclass(frozen=True)
class BodyProperties:
    """Mass properties of a solid (all in the root's parent frame, user units).

    volume, mass (= density * volume), com (3,), inertia (3, 3) about the com (mass-weighted,
    density x volume integrals of (r^2 I - r r^T)), principal (3,) ascending moments, axes
    (3, 3) whose COLUMNS are the principal axes (a proper rotation, det +1), quat (x, y, z, w)
    of ``axes`` (the rotation taking principal-frame coordinates to the root's frame),
    volume_error and moment_error (absolute error estimates of volume and of any inertia
    entry/principal moment), diagnostics (dict).
    """

    volume: float
    mass: float
    density: float
    com: np.ndarray
    inertia: np.ndarray
    principal: np.ndarray
    axes: np.ndarray
    quat: np.ndarray
    volume_error: float
    moment_error: float
    diagnostics: dict = field(default_factory=dict)


def check_box(lo, hi):
    """(lo, hi) as float64 arrays (3,) of a box with hi > lo on every axis, or raise
    :class:`PecletArgumentError` naming the bad argument."""
    lo_a = np.asarray(lo, dtype=np.float64).reshape(-1)
    hi_a = np.asarray(hi, dtype=np.float64).reshape(-1)
    if lo_a.size != 3 or not np.all(np.isfinite(lo_a)):
        raise PecletArgumentError("lo", "3 finite numbers", lo)
    if hi_a.size != 3 or not np.all(np.isfinite(hi_a)):
        raise PecletArgumentError("hi", "3 finite numbers", hi)
    if not np.all(hi_a > lo_a):
        raise PecletArgumentError("hi", "greater than lo on every axis", hi_a.tolist(),
                                  f"lo={lo_a.tolist()}")
    return lo_a, hi_a


def _check_faces(builder, root, lo, hi, m):
    """Raise unless phi >= 0 on an (m+1)^2 sample of every face of the box."""
    u = np.linspace(0.0, 1.0, m + 1)
    a, b = np.meshgrid(u, u, indexing="ij")
    a = a.ravel()
    b = b.ravel()
    pts = []
    for ax in range(3):
        o1, o2 = [k for k in range(3) if k != ax]
        for side in (lo[ax], hi[ax]):
            p = np.empty((a.size, 3))
            p[:, ax] = side
            p[:, o1] = lo[o1] + a * (hi[o1] - lo[o1])
            p[:, o2] = lo[o2] + b * (hi[o2] - lo[o2])
            pts.append(p)
    phi = builder.eval_root(root, np.concatenate(pts))
    if np.any(phi < 0.0):
        raise PecletArgumentError("lo, hi", "a box containing the solid (phi >= 0 on its "
                                  "boundary)", (lo.tolist(), hi.tolist()),
                                  f"box does not contain the solid: min phi {phi.min():.3g} "
                                  "on its faces; enlarge lo/hi")


def principal_axes(inertia, tol):
    """Ascending principal moments and a proper rotation whose columns are the axes.

    Deterministic axis choice: eigenvalues closer than ``tol`` form a cluster; within a
    cluster the basis is rotated onto the input axes (orthogonal Procrustes onto the
    coordinate axes that the cluster's subspace captures best), so a sphere or a cube gives
    the identity and a ring about y keeps x and z. A non-degenerate axis is signed so that its
    largest component is positive; the last non-degenerate axis then absorbs det = +1.
    """
    w, V = np.linalg.eigh(inertia)
    order = np.argsort(w, kind="stable")
    w = w[order]
    V = V[:, order]
    clusters = [[0]]
    for i in range(1, 3):
        if w[i] - w[clusters[-1][-1]] <= tol:
            clusters[-1].append(i)
        else:
            clusters.append([i])
    A = V.copy()
    free = []
    for cl in clusters:
        if len(cl) == 1:
            i = cl[0]
            col = A[:, i]
            if col[np.argmax(np.abs(col))] < 0.0:
                A[:, i] = -col
            free.append(i)
            continue
        Vc = V[:, cl]
        # coordinate axes best captured by the cluster's subspace, in index order
        capture = np.sum(Vc * Vc, axis=1)
        tgt = np.sort(np.argsort(-capture, kind="stable")[:len(cl)])
        T = np.eye(3)[:, tgt]
        U, _, Wt = np.linalg.svd(Vc.T @ T)
        A[:, cl] = Vc @ (U @ Wt)
    if np.linalg.det(A) < 0.0:
        i = free[-1] if free else 2
        A[:, i] = -A[:, i]
    return w, A


def body_properties(builder, root, lo, hi, density=1.0, n=32, tol=1e-8, cache=None):
    """Mass properties of the solid ``phi < 0`` of ``root`` inside the box [lo, hi].

    Parameters
    ----------
    lo, hi : 3 finite numbers each, hi > lo; the box must contain the solid (phi >= 0 on its
        boundary, checked on a sample of the faces).
    density : > 0, mass per unit volume.
    n : int in [2, 4096], the sampling resolution: structure (where the solid's pieces start
        and end across the lines) is probed on ``n`` intervals per axis of the box, i.e. on
        ``ceil(n / 4)`` top-level cells of ``V_PROBES = 4`` probe intervals each. Cut cells
        refine adaptively below that; along a line nothing is sampled at all (roots are
        found by a certified search on 1-Lipschitz trees, steps of 1/64 of the cell
        otherwise). A piece of solid narrower than ``box / n`` across both transverse axes
        can be found late or missed; a finer ``n`` costs time roughly as ``n^2``.
    tol : in (0, 1e-3], the relative accuracy asked of the moments: cells are refined, the
        worst first, until their estimates add up to at most ``tol`` of the solid's volume
        (and of its first and second moments), so ``volume_error <= tol * volume`` unless a
        cell hit MAX_DEPTH (``diagnostics["unconverged_cells"]``).
    cache : optional dict shared between calls on the same tree and box (e.g. the tolerances
        of a convergence study): the box check and every cell integrated are done once and
        taken from it afterwards. The results are bitwise the same with or without it.

    Only the SIGN of phi enters the integrand (gradients choose the height direction), so
    bound-only leaves (ellipsoid, superquadric, hollow_cylinder_shell) carry no bias; for them
    no cell can be skipped, so they cost more.
    """
    lo_a, hi_a = check_box(lo, hi)
    n = check_int("n", n, 2, 4096)
    density = check_float("density", density, 0.0, lo_open=True)
    tol = check_float("tol", tol, 0.0, 1e-3, lo_open=True)
    prog = builder.program(root)
    m = max(2 * int(n), 16)
    if cache is not None and not isinstance(cache, dict):
        raise PecletArgumentError("cache", "None or a dict (shared between calls)", cache)
    faces = None if cache is None else ("faces", m) + arrays_key(
        (lo_a, hi_a, prog.ops, prog.leaf_kind, prog.leaf_reals, prog.op_begin, prog.op_end))
    if faces is None or faces not in cache:
        _check_faces(builder, root, lo_a, hi_a, m)
        if faces is not None:
            cache[faces] = True
    # a tree with a finite Lipschitz constant L (a grid leaf's is measured) is searched as
    # phi / L, which is 1-Lipschitz with the same solid; L = 1 for exact leaves (no change)
    lconst = float(builder.lipschitz_constant(root))
    lip = math.isfinite(lconst)
    budget = 0 if not lip else (LINE_EXTRA if tol < CERTIFY_TOL else LINE_EXTRA_LOOSE)
    top = max(1, -(-int(n) // V_PROBES))
    mom, err, diag = integrate_body(prog, lo_a, hi_a, top, budget, tol, cache,
                                    kinv=1.0 / lconst if lip else 1.0)
    cen = 0.5 * (lo_a + hi_a)
    if diag[3] != 0.0:
        raise ValueError(f"a line crossed the surface more than {MAX_BREAKS} times, or a cell "
                         f"had more than {MAX_BREAKS} breakpoints: the tree is pathological "
                         "for this box (or n is far too small)")
    vol = float(mom[0])
    if not vol > 0.0:
        raise ValueError("empty solid: no point of the box has phi < 0")
    d = mom[1:4] / vol                       # com relative to the box centre
    com = cen + d
    S = np.array([[mom[4], mom[7], mom[8]],
                  [mom[7], mom[5], mom[9]],
                  [mom[8], mom[9], mom[6]]])
    S_com = S - vol * np.outer(d, d)         # second moments about the com
    inertia = density * (np.trace(S_com) * np.eye(3) - S_com)
    # error propagation (first order, absolute)
    e_v = float(err[0])
    e_d = (np.abs(err[1:4]) + np.abs(d) * e_v) / vol
    e_S = max(err[4:10].max(), 0.0) + 2.0 * vol * np.max(np.abs(d)) * e_d.max() \
        + float(np.max(d * d)) * e_v
    e_I = density * 3.0 * e_S
    principal, axes = principal_axes(inertia, tol=max(1e-9 * abs(np.trace(inertia)), 10 * e_I))
    quat = matrix_to_quat(axes)
    return BodyProperties(volume=vol, mass=density * vol, density=density, com=com,
                          inertia=inertia, principal=principal, axes=axes, quat=quat,
                          volume_error=e_v, moment_error=float(e_I),
                          diagnostics={"cells": int(diag[0]), "max_depth": int(diag[1]),
                                       "unconverged_cells": int(diag[2]), "n": int(n),
                                       "top_cells": top,
                                       "tol": tol, "lipschitz": lip})


def principal_frame(builder, root, lo, hi, **kw):
    """(new_root, props): an exact copy of ``root`` whose frame is the principal frame.

    ``new_root = builder.add_reframed(root, translation=-A^T com, rotation=quat(A^T))`` with A
    = props.axes, so in the new root's parent frame the com is at the origin and the principal
    axes lie on x, y, z (ascending moments). A transform on a copied root, never a resample.
    ``kw`` goes to :func:`body_properties`.
    """
    props = body_properties(builder, root, lo, hi, **kw)
    # a C-ordered copy: matrix_to_quat is compiled once, for C arrays (a transposed view is
    # F-ordered, and a second compilation cost a cold first run about a second)
    At = np.ascontiguousarray(props.axes.T)
    new_root = builder.add_reframed(root, translation=-(At @ props.com),
                                    rotation=matrix_to_quat(At))
    return new_root, props


