"""Permeability of a frozen pack: geometry from the exact trees, the flow, and what it means.

The domain (world frame of the pack: y up, periodic in x and z with sides ``pack.box``) is a
bulk window ``y in [y0, y1]`` cut out of the bed, by default the page's first window (1 D
above the floor, 0.8 D below the highest centre; :func:`peclet.packing.analysis.geometry.bulk_windows`).
The flow needs a periodic y as well; ``y_mode`` says how:

- ``"wrap"`` (default): the window wraps onto itself; elements cut at y0 and y1 meet at a
  seam where the structure's correlations are broken (the porosity is not changed on
  average); the field jumps there, so every link across the seam is searched for a wall
  (``build_geometry(seams=...)``);
- ``"mirror"``: the window and its mirror image about y1 make a period 2 (y1 - y0): the solid
  is continuous across both mirror planes, at twice the cost; but an element cut by a mirror
  plane joins its own image into a body stretched along y, and the pores likewise, so flow
  *along y* meets aligned bodies and straight channels at every plane and k along y comes
  out too high: measured on a 40-sphere rained pack at D/8 (window 2.25 D), the Kozeny
  constant along y is 3.64 mirrored, 4.70 wrapped, and 5.10 / 4.77 across (x / z, wrapped);
  on the page's ring pack k along y is 8% higher mirrored than wrapped. Flow across the
  planes (x, z) is barely affected (2%);
- ``"open"``: not periodic and no walls: refused (fluid would leave the box).

**Grown beds** (``peclet pack --protocol grow``, :mod:`peclet.flow.packs`) are triply
periodic (:class:`~peclet.flow.domain.PeriodicCell`): the lattice is one whole period, there is
no window and no seam, and the body force is the exact dP/L along x, y or z. The set-up shared
with the pressure-drop curve (pack, container, lattice, geometry, porosity, diameters; the
superficial velocity and dP/L of a solve) is :mod:`peclet.flow.setup`.

**Column sections** (a pack made in a ``column:N`` container, :func:`pack_container`): the
lattice covers the column's cross-section and is not periodic across it: the column's wall,
taken from the same :class:`~peclet.packing.bed.containers.Container` the pack used (its side wall
tree, whose signed distance inside the column is exactly ``R - r``), closes x and z, so no
fluid leaves the box there. The flow runs along the axis (y), periodic over an axial section
of the bed, by default its middle (the floor and the top each cut by
``min(2 D, bed height / 3)``, as the bed's own analysis crops it). The elements are not
periodic along the axis, so the section is wrapped (``y_mode="wrap"``): the bed at the
section's top meets the bed at its bottom at a *seam* where elements cut at both ends face each
other (not mirrored: a mirror plane joins each cut element to its image into a body
stretched along the axis and the pores into straight channels, and the flow is *along* the
axis here; see ``"mirror"`` above). The seam's structure is wrong: it may block or open the
flow locally, and the whole period's resistance includes it. So dP/L is measured *away from
the seam*: the fluid-averaged pressure p = rho c_s^2 of every lattice plane (all fluid nodes of
the plane) is fitted by a line over the planes more than ``seam_margin`` (1 D) from the seam;
its slope s enters the momentum balance of the bulk, where the driving gradient is
``dP/L = g - s`` (g the body force density). The seam's excess resistance is the pressure
jump it carries; ``seam_share = s / g`` is its share of the drive (0 for a seam that changes
nothing: an empty pipe). Its error: the fit's standard error (reported), and the seam's
disturbance reaching beyond the margin (a pore's length, decaying). The whole-period value
``k_D2_period = mu U / g`` (seam included) is reported beside it.

For a column, U is the flux over uncut links per unit *column* cross-section (pi R^2, exact),
the porosity ``eps`` is the lattice's fluid fraction of the nodes inside the wall (so it
includes the wall's loose first layer), and the pressure drop is compared with Eisfeld &
Schnitzlein's (2001) wall-corrected Ergun equation (Reichelt's form) with their constants for
spheres, K1 = 154, k1 = 1.15, k2 = 0.87::

    dP/L = K1 A_w^2 (1 - eps)^2 / eps^3 * mu U / d_p^2 + A_w / B_w (1 - eps) / eps^3 * rho U^2 / d_p
    A_w = 1 + 2 / (3 (D_t / d_p) (1 - eps)),   B_w = (k1 (d_p / D_t)^2 + k2)^2

with D_t the column diameter and d_p the volume-equivalent sphere diameter (6 V_p / pi)^(1/3)
(= D for spheres; other shapes get the sphere constants, an approximation):
``ergun_wall_ratio`` = measured dP/L over this. A_w > 1 is the wall's extra surface (more
drag); B_w < 1 its loose packing (the inertial term, negligible at the default Re = 0.01).
Also reported: D_t / d_p, the wall's share of the drag (links whose crossing is on the wall),
and the core porosity (nodes more than 1 D from the wall).

**Where dP/L comes from.** The flow is driven along ``axis`` by a uniform body force density
rho g on the fluid. Where the structure is periodic along the flow this is exact: write the
pressure as p = P - rho g . x with P periodic (it must be, in a periodic domain); the momentum
equation of p with the body force is that of P driven by a mean pressure gradient dP/L = rho g,
so k = mu U / (rho g) with no approximation beyond the lattice's. That holds for a box pack
along x or z (the pack's own periodic directions; the wrapped window's seam then lies along the
flow, a layer of the structure like any other), for the mirrored window, and for the
validation's sphere arrays. Its check is the force balance: at steady state the walls take the
whole body force, ``solid_drag_balance`` = wall force / body force (the solver's two-step mean
``balance``), 1 to the convergence tolerance (1e-4), reported for every pack, box or column.

Along y the wrapped window is not periodic in the pack: the seam carries a pressure jump of its
own, so mu U / (rho g) is the whole *period's* k, the seam's excess resistance included. A
column section takes dP/L from the pressure slope away from the seam (above). A box pack keeps
the body force (``k_D2`` = ``k_D2_period``, ``dpdl_source`` says so) and reports the seam-free
estimate beside it (``k_D2_seam_free``, ``seam_share`` and its standard error,
``seam_share_by_margin``: the share fitted beyond 0.5, 1 and 1.5 margins), because on box packs
the fit is not the better figure. Measured at D/8, with k along x and z (exact, no seam across
the flow; a poured bed may be anisotropic, so this brackets the seam's effect rather than
measuring it): the page's 48-ring pack, k_x = 0.005728, k_z = 0.005727 D^2, k_y = 0.005377
whole period (-6%) and 0.006763 seam-free (+18%; seam share 0.13-0.20 for margins 0.25-1.5 D,
the fit's standard error 0.011; the mirrored window, whose k along y is too high, was measured
8% above the whole-period figure, i.e. below the seam-free one); a rained 150-sphere box:4
pack, k_x = 0.000873, k_z = 0.000882, k_y = 0.000844 whole period (-4%) and 0.000916 seam-free
(+4%; share 0.063-0.088). Beyond the margins the window leaves 2-5 D of planes, over which the
plane pressure wanders from a line at the pore scale by more than the fit's standard error
says; so the seam-free figure is no closer to the lateral ones than the whole period's, which
sat 4-6% below them on these packs. A column section has no lateral direction to check against;
``seam_share_by_margin`` shows its fit's spread there too, and it is the largest uncertainty of
a column's k: on a column:5 section of 150 rained spheres (window 3.8 D) the share is 0.07,
0.11 and 0.17 beyond 0.5, 1 and 1.5 D at D/8, D/12 and D/16 alike, so k moves by -4% / +6% with
the margin, against 0.3% between D/12 and D/16 (validation/flow.py, ``column``).

Lengths are in the element diameter D (the pack's unit); the lattice spacing is
h = D / resolution.

Outputs (:class:`PackFlow`): Darcy permeability ``k = mu U / (dP/L)`` (U the superficial
velocity along the axis: the mass flux over uncut links per cell, see
:mod:`peclet.flow.solver`) in D^2 and in lattice units (cells^2), the Reynolds number
``Re = U D / nu`` of the run and its dP/L in lattice units, the porosity of the lattice, the
Kozeny constant ``K_K = eps^3 d_s^2 / (36 k (1 - eps)^2)`` with the Sauter diameter
``d_s = 6 V_p / A_p``, the Ergun viscous ratio ``(dP/L) / (150 mu U (1 - eps)^2 / (eps^3 d^2))
= eps^3 d^2 / (150 k (1 - eps)^2)`` with d = d_s and eps the bed voidage, and with the
envelope's volume-equivalent diameter ``d_env = (6 V_env / pi)^(1/3)`` and the voidage outside
the envelopes ``1 - f_env`` (Monte Carlo on the exact envelopes, 2e5 samples; the rings
counted as solid cylinders), and the drag on each element (momentum exchange on
the cut links, each link given to the element whose phi is lowest at the wall point).
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from peclet.core.validation import PecletArgumentError, check_float

from .correlations import ES_SPHERES, eisfeld_schnitzlein  # noqa: F401
from .domain import (BASE_BYTES, BYTES_PER_CELL, Y_MODES, check_lattice_memory,  # noqa: F401
                     column_window, lattice_dims, pack_domain, wrap_y)
from .lattice import C, MAGIC_DEFAULT, W
from .setup import (_AXIS, ThinWallWarning, _check_column_holds, drive,  # noqa: F401
                    pack_container, prepare, seam_fit, superficial, thinnest_wall)
from .solver import solve

__all__ = ["PackFlow", "pack_domain", "lattice_dims", "check_lattice_memory", "pack_container", "permeability", "richardson",
           "thinnest_wall", "ThinWallWarning", "Y_MODES", "eisfeld_schnitzlein", "seam_fit",
           "ES_SPHERES"]

@dataclass
class PackFlow:
    """The flow through a pack at one resolution (see the module docstring for definitions).

    k_D2, k_lattice: permeability in D^2 and in cells^2; dpdl_lattice: the driving dP/L
    (lattice units); Re: U D / nu; eps: lattice porosity of the domain; d_sauter, d_envelope
    (D, NaN without an envelope); kozeny; ergun_ratio_sauter, ergun_ratio_envelope; drag (N,)
    force on each element along the axis (lattice units, summed over its pieces in the
    domain), drag_cv (std/mean over elements wholly inside the window); solid_drag_balance
    (total wall force / total body force, 1 at steady state: the check that the body force is
    the drive k is taken from, box or column); flow: the
    :class:`~peclet.flow.solver.FlowResult`; info: the domain's parameters.
    """

    resolution: float
    k_D2: float
    k_lattice: float
    dpdl_lattice: float
    Re: float
    eps: float
    d_sauter: float
    d_envelope: float
    kozeny: float
    ergun_ratio_sauter: float
    ergun_ratio_envelope: float
    drag: np.ndarray
    drag_cv: float
    solid_drag_balance: float
    flow: object
    info: dict = field(default_factory=dict)

    def summary(self) -> dict:
        """The scalar results as a JSON-ready dict."""
        f = self.flow
        return {"resolution": self.resolution, "k_D2": self.k_D2, "k_lattice": self.k_lattice,
                "dpdl_lattice": self.dpdl_lattice, "Re": self.Re, "eps": self.eps,
                "d_sauter": self.d_sauter, "d_envelope": self.d_envelope,
                "kozeny": self.kozeny, "ergun_ratio_sauter": self.ergun_ratio_sauter,
                "ergun_ratio_envelope": self.ergun_ratio_envelope,
                "drag_mean": float(np.mean(self.drag)), "drag_cv": self.drag_cv,
                "solid_drag_balance": self.solid_drag_balance, "steps": f.steps,
                "balance_two_step": f.balance, "parity_swing": f.parity_swing,
                "tol": f.tol, "balance_tol": f.balance_tol,
                "converged": f.converged, "residual": f.residual, "seconds": f.seconds,
                "mlups": f.mlups, "fluid_nodes": f.geometry.n_fluid,
                "cut_links": int(len(f.geometry.link_q)),
                "thin_wall_links": f.geometry.thin_links, "fallback_links": f.fallback_links,
                "mass_drift": f.mass_drift, "mass_correction": f.mass,
                "k_D2_node_mean": self.k_D2 * float(f.U_nodes[_AXIS[self.info["axis"]]]
                                                    / f.U[_AXIS[self.info["axis"]]]),
                "convergence": "two-step means: relative change of the mean velocity per "
                f"check and its geometric tail < {f.tol:g}, |wall force / body force - 1| < "
                f"{f.balance_tol:g}",
                "lattice_cells": f.geometry.grid.n_cells,
                "memory_MiB": f.memory_bytes / 2.0 ** 20, **self.info}


def permeability(pack, resolution=16, axis="y", window=None, y_mode="wrap", nu=1.0 / 6.0,
                 magic=MAGIC_DEFAULT, scheme="linear", tol=1e-6, max_steps=100_000, Re=0.01,
                 progress=None, samples=8, area_n=160, mass="local", container=None,
                 seam_margin=1.0, balance_tol=None):
    """The flow through ``pack`` (a :class:`~peclet.packing.bed.freeze.Pack` or a path to one).

    resolution: cells per D (>= 4; a warning (:class:`ThinWallWarning`) names the thinnest
    wall when it gets fewer than 4 cells). axis: "x", "y" (the bed's axis, default) or "z"
    (a column: "y" only). Re: the target Reynolds number U D / nu of the run (the force is set
    from an estimate of k and then reported as run; 0.01 keeps inertia out of a Darcy
    permeability). container: see :func:`pack_container` (None reads the one ``peclet pack``
    recorded beside the pack file). seam_margin: distance (D, >= 0) from a wrapped window's
    seam beyond which the pressure is fitted (module docstring: a column section's dP/L; a box
    pack along y keeps the body force's and reports the fitted one beside it). balance_tol: see
    :func:`peclet.flow.solver.solve`. Other arguments: see :func:`pack_domain` and
    :func:`peclet.flow.solver.solve`. Returns a :class:`PackFlow`.
    """
    Re = check_float("Re", Re, 0.0, 10.0, lo_open=True)
    seam_margin = check_float("seam_margin", seam_margin, 0.0)
    st = prepare(pack, resolution, axis, window, y_mode, container, samples, area_n)
    pk, grid, geo, info, ax, res = st.pack, st.grid, st.geo, st.info, st.ax, st.res
    cont, eps, d_s, d_env = st.column, st.eps, st.d_s, st.d_env
    # the force from a Carman-Kozeny guess of k, so the run sits near the requested Re
    k_guess = max(eps ** 3 * d_s ** 2 / (180.0 * max(1.0 - eps, 1e-3) ** 2), 1e-6) * res ** 2
    U_target = Re * nu / res
    g = U_target * nu / k_guess
    F = np.zeros(3)
    F[ax] = g
    fr = solve(geo, F, nu=nu, magic=magic, scheme=scheme, tol=tol, max_steps=max_steps,
               progress=progress, mass=mass, balance_tol=balance_tol)
    U = superficial(st, fr)
    if not U > 0.0:
        raise FloatingPointError(f"no flow along {axis}: U = {U}")
    k_period = nu * U / g
    dpdl, up = drive(st, fr, g, U, nu, seam_margin)
    info.update(up)
    k_lu = nu * U / dpdl
    k_D2 = k_lu / res ** 2
    drag, inside, wall_drag = _element_drag(pk, fr, grid, ax, info, cont)
    total = float(fr.link_force[:, ax].sum())
    solid = eps < 1.0        # an empty section (a pipe) has no Kozeny or Ergun figures
    kozeny = eps ** 3 * d_s ** 2 / (36.0 * k_D2 * (1.0 - eps) ** 2) if solid else math.nan
    ergun = lambda d, e: e ** 3 * d ** 2 / (150.0 * k_D2 * (1.0 - e) ** 2) if e < 1.0 \
        else math.nan
    eps_env = math.nan
    if np.isfinite(d_env):
        eps_env = _envelope_voidage(pk, info["window"], cont)
    sel = drag[inside] if inside.any() else drag
    info.update({"eps_envelope": eps_env, "axis": axis, "nu": nu, "magic": magic,
                 "scheme": scheme, "force": g, "k_D2_period": k_period / res ** 2,
                 "dpdl_lattice_period": g,
                 "thinnest_wall_D": st.t_wall, "thinnest_wall": st.wall_name,
                 "elements_inside": int(inside.sum()), "U_lattice": U})
    if cont is not None:
        d_v = (6.0 * float(pk.ring_volume) / math.pi) ** (1.0 / 3.0)
        D_t = 2.0 * float(cont.radius)
        es, A_w, B_w = eisfeld_schnitzlein(U, eps, d_v * res, D_t * res, nu) if solid \
            else (math.nan, math.nan, math.nan)
        info.update({"D_t_over_d_p": D_t / d_v, "d_p_volume": d_v, "A_w": A_w, "B_w": B_w,
                     "ergun_wall_ratio": dpdl / es,
                     "ergun_ratio_volume": ergun(d_v, eps),
                     "wall_drag_share": wall_drag / total if total else math.nan,
                     "eps_core": st.eps_core, "porosity_nodes": "fluid nodes / nodes inside the "
                     "wall (near-wall region included)"})
    return PackFlow(resolution=res, k_D2=k_D2, k_lattice=k_lu, dpdl_lattice=dpdl,
                    Re=U * res / nu, eps=eps, d_sauter=d_s, d_envelope=d_env, kozeny=kozeny,
                    ergun_ratio_sauter=ergun(d_s, eps),
                    ergun_ratio_envelope=ergun(d_env, eps_env) if np.isfinite(d_env)
                    else math.nan,
                    drag=drag, drag_cv=float(np.std(sel) / np.mean(sel)) if np.mean(sel) != 0
                    else math.nan,
                    solid_drag_balance=total / (g * geo.n_fluid), flow=fr, info=info)


def _envelope_voidage(pk, window, cont, n=200_000, seed=0):
    """1 - (fraction of the window inside an element's envelope), Monte Carlo: the periodic
    box window (peclet.packing.analysis.geometry.cover_fractions) or, in a column, uniform points
    in the cylinder over the window."""
    from peclet.packing.analysis.geometry import PackGeometry, cover_fractions
    if cont is None:
        return 1.0 - cover_fractions(PackGeometry(pk), window, n)["f_env"]
    rng = np.random.default_rng(seed)
    R = float(cont.radius)
    cx, cz = cont.center_xz
    r = R * np.sqrt(rng.uniform(0.0, 1.0, n))
    t = rng.uniform(0.0, 2.0 * math.pi, n)
    pts = np.column_stack([cx + r * np.cos(t), rng.uniform(window[0], window[1], n),
                           cz + r * np.sin(t)])
    return 1.0 - float(np.mean(PackGeometry(pk).cover(pts)[1]))


def _element_drag(pack, fr, grid, ax, info, cont=None):
    """Drag along ``ax`` on each element: each cut link's momentum goes to the body whose
    field is lowest at the link's wall point (mapped back into the window): an element, or
    in a column its wall; summed in link order. Returns (drag (N,), inside (N,) bool: bounding
    sphere wholly inside the window, the wall's drag), relative to the mean pressure."""
    geo = fr.geometry
    pts = geo.wall_points()
    y0, y1 = info["window"]
    H = y1 - y0
    pts = wrap_y(pts, y0, H, info["y_mode"] if info["y_mode"] != "open" else "wrap")
    Lx, Lz = info["box"]
    b = pack.builder()
    R = pack.rotations()
    best = np.full(len(pts), np.inf)
    owner = np.full(len(pts), -1, np.int64)
    if cont is not None:
        cx, cz = cont.center_xz
        best = float(cont.radius) - np.hypot(pts[:, 0] - cx, pts[:, 2] - cz)
        owner[:] = -2
    rb = float(pack.bounding_radius) + 2.0 * grid.h
    shifts = (-1, 0, 1) if cont is None else (0,)
    yshifts = (-1, 0, 1) if info["container"] == "periodic" else (0,)
    for e, sx, sy, sz in itertools.product(range(pack.n), shifts, yshifts, shifts):
        c = pack.positions[e] + np.array([sx * Lx, sy * H, sz * Lz])
        d = pts - c
        near = np.flatnonzero((d * d).sum(1) <= rb * rb)
        if len(near) == 0:
            continue
        v = b.eval_root(pack.home_root, d[near] @ R[e])
        better = v < best[near]
        best[near[better]] = v[better]
        owner[near[better]] = e
    drag = np.zeros(pack.n)
    # the momentum exchange less its part at rest (rho0 = 1): -c_i (f*_o + f_i - 2 w_i). The
    # uniform pressure's force on a body vanishes only over a closed wetted surface; where
    # bodies touch (or touch the wall) the lattice lines run from one into the other without
    # a fluid node between, and the rest part, 2 w_i per link (10^4 times a link's drag at
    # Re 0.01), would be handed from body to body. Its sum over all bodies is zero (every
    # lattice line leaves the solid as often as it enters), so the total is unchanged.
    i = geo.link_dir
    f = fr.link_force[:, ax] + 2.0 * W[i] * C[i, ax]
    ok = owner >= 0
    np.add.at(drag, owner[ok], f[ok])
    wall = float(f[owner == -2].sum())
    ys = pack.positions[:, 1]
    inside = (ys - pack.bounding_radius >= y0) & (ys + pack.bounding_radius <= y1)
    return drag, inside, wall


def richardson(h, k):
    """Richardson extrapolation of k(h) = k0 + C h^p from 2 or 3 (h, k) pairs (any order).

    Three values give the observed order p = ln((k1 - k2)/(k2 - k3)) / ln(r) for a constant
    refinement ratio r (else solved numerically); two assume p = 2. Returns
    {"k0", "p", "assumed_p"} (p NaN and k0 the finest value when the differences do not
    shrink monotonically)."""
    h = np.asarray(h, np.float64)
    k = np.asarray(k, np.float64)
    order = np.argsort(-h)
    h, k = h[order], k[order]
    if len(h) < 2:
        raise PecletArgumentError("resolutions", "at least 2 resolutions", len(h))
    if len(h) == 2:
        p = 2.0
        r = h[0] / h[1]
        return {"k0": float(k[1] + (k[1] - k[0]) / (r ** p - 1.0)), "p": p, "assumed_p": True}
    h, k = h[-3:], k[-3:]
    d1, d2 = k[0] - k[1], k[1] - k[2]
    if d1 == 0.0 or d2 == 0.0 or d1 * d2 < 0 or abs(d2) >= abs(d1):
        return {"k0": float(k[2]), "p": math.nan, "assumed_p": False}
    from scipy.optimize import brentq
    f = lambda p: (h[0] ** p - h[1] ** p) / (h[1] ** p - h[2] ** p) - d1 / d2
    try:
        p = brentq(f, 0.05, 8.0)
    except ValueError:
        return {"k0": float(k[2]), "p": math.nan, "assumed_p": False}
    c = d2 / (h[1] ** p - h[2] ** p)
    return {"k0": float(k[2] - c * h[2] ** p), "p": float(p), "assumed_p": False}
