"""Permeability of a frozen pack: geometry from the exact trees, the flow, and what it means.

The domain (world frame of the pack: y up, periodic in x and z with sides ``pack.box``) is a
bulk window ``y in [y0, y1]`` cut out of the bed, by default the page's first window (1 D
above the floor, 0.8 D below the highest centre; :func:`peclet.packing.analysis.bulk_windows`).
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

The flow is driven along ``axis`` by a uniform body force, so dP/L = rho g (the body force
acts on the fluid like a mean pressure gradient). Lengths are in the element diameter D (the
pack's unit); the lattice spacing is h = D / resolution.

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

import math
import os
import warnings
from dataclasses import dataclass, field

import numpy as np

from peclet.core.validation import PecletArgumentError, check_choice, check_float, check_int

from .geometry import Grid, build_geometry
from .lattice import MAGIC_DEFAULT
from .solver import solve

__all__ = ["PackFlow", "pack_domain", "permeability", "richardson", "thinnest_wall",
           "ThinWallWarning", "Y_MODES"]

Y_MODES = ("mirror", "wrap", "open")
_AXIS = {"x": 0, "y": 1, "z": 2}
#: Leaf kinds whose thinnest dimension is read from the tree (param -> thickness).
_THICKNESS = {
    "sphere": lambda p: 2.0 * p[0],
    "box": lambda p: 2.0 * min(p[0], p[1], p[2]),
    "hollow_cylinder": lambda p: p[2],
    "hollow_cylinder_shell": lambda p: p[0] - p[1],
    "capsule": lambda p: 2.0 * p[0],
    "torus": lambda p: 2.0 * p[1],
}


class ThinWallWarning(UserWarning):
    """The resolution puts fewer than 4 cells across the thinnest wall of the element."""


@dataclass
class PackFlow:
    """The flow through a pack at one resolution (see the module docstring for definitions).

    k_D2, k_lattice: permeability in D^2 and in cells^2; dpdl_lattice: the driving dP/L
    (lattice units); Re: U D / nu; eps: lattice porosity of the domain; d_sauter, d_envelope
    (D, NaN without an envelope); kozeny; ergun_ratio_sauter, ergun_ratio_envelope; drag (N,)
    force on each element along the axis (lattice units, summed over its pieces in the
    domain), drag_cv (std/mean over elements wholly inside the window); solid_drag_balance
    (total wall force / total body force, 1 at steady state); flow: the
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
                "converged": f.converged, "residual": f.residual, "seconds": f.seconds,
                "mlups": f.mlups, "fluid_nodes": f.geometry.n_fluid,
                "cut_links": int(len(f.geometry.link_q)),
                "thin_wall_links": f.geometry.thin_links, "fallback_links": f.fallback_links,
                "mass_drift": f.mass_drift, "mass_correction": f.mass,
                "k_D2_node_mean": self.k_D2 * float(f.U_nodes[_AXIS[self.info["axis"]]]
                                                    / f.U[_AXIS[self.info["axis"]]]),
                "lattice_cells": f.geometry.grid.n_cells,
                "memory_MiB": f.memory_bytes / 2.0 ** 20, **self.info}


def thinnest_wall(pack):
    """(thickness in D, description) of the thinnest leaf of the element's tree (leaf scale
    applied; only leaf kinds with a clear thickness are read), or (inf, "") if none."""
    from peclet.core.geom.leaves import LEAVES_BY_KIND
    b = pack.builder()
    best, name = math.inf, ""
    for idx in range(b.num_nodes()):
        kind_id, _, _, params, _, _, scale = b.node(idx)
        spec = LEAVES_BY_KIND.get(int(kind_id))
        if spec is None or spec.name not in _THICKNESS:
            continue
        t = _THICKNESS[spec.name](list(params)) * float(scale)
        if t < best:
            best, name = t, f"node {idx} ({spec.name}, thickness {t:.4g} D)"
    return best, name


def pack_domain(pack, resolution, window=None, y_mode="wrap"):
    """(grid, phi, info) for a pack: the lattice over the window and the field on it.

    resolution: cells per D (>= 4). window: (y0, y1) in D, default the page's first bulk
    window. y_mode: see the module docstring. The box sides must be whole numbers of cells
    (to 1e-9 of a cell).
    """
    from peclet.packing.analysis import bulk_windows
    resolution = check_float("resolution", resolution, 4.0, 256.0)
    y_mode = check_choice("y_mode", y_mode, Y_MODES)
    Lx, Lz = (float(v) for v in pack.box)
    nx = int(round(Lx * resolution))
    h = Lx / nx
    nz = int(round(Lz / h))
    if abs(Lz / h - nz) > 1e-9 or nz < 2:
        raise PecletArgumentError("resolution", "a resolution that makes both box sides whole "
                                  f"numbers of cells (box {Lx:g} x {Lz:g} D)", resolution)
    if window is None:
        window = bulk_windows(pack)[0][0]
    if isinstance(window, (str, bytes)) or not hasattr(window, "__len__") or len(window) != 2:
        raise PecletArgumentError("window", "(y0, y1) in D with y1 > y0", window)
    y0 = check_float("window[0]", window[0])
    y1 = check_float("window[1]", window[1], y0, lo_open=True)
    ny_half = max(2, int(round((y1 - y0) / h)))
    H = ny_half * h
    ny = 2 * ny_half if y_mode == "mirror" else ny_half
    b = pack.builder()
    pos = pack.positions.copy()
    pos[:, 0] = np.mod(pos[:, 0], Lx)
    pos[:, 2] = np.mod(pos[:, 2], Lz)
    for p, q in zip(pos, pack.quaternions):
        b.add_instance(pack.home_root, translation=p, rotation=q)
    big = 1e6
    box = ((0.0, -big, 0.0), (Lx, big, Lz))

    def phi(points):
        pts = np.array(points, dtype=np.float64, copy=True)
        if y_mode == "mirror":
            t = np.mod(pts[:, 1] - y0, 2.0 * H)
            pts[:, 1] = y0 + np.where(t <= H, t, 2.0 * H - t)
        elif y_mode == "wrap":
            pts[:, 1] = y0 + np.mod(pts[:, 1] - y0, H)
        return b.eval_scene(pts, box=box, periodic=(True, False, True))

    grid = Grid(origin=(0.5 * h, y0 + 0.5 * h, 0.5 * h), h=h, dims=(nx, ny, nz),
                periodic=(True, y_mode != "open", True))
    info = {"window": [y0, y0 + H], "y_mode": y_mode, "h_D": h, "dims": [nx, ny, nz],
            "box": [Lx, Lz]}
    return grid, phi, info


def permeability(pack, resolution=16, axis="y", window=None, y_mode="wrap", nu=1.0 / 6.0,
                 magic=MAGIC_DEFAULT, scheme="linear", tol=1e-6, max_steps=100_000, Re=0.01,
                 progress=None, samples=8, area_n=160, mass="local"):
    """The flow through ``pack`` (a :class:`~peclet.packing.freeze.Pack` or a path to one).

    resolution: cells per D (>= 4; a warning (:class:`ThinWallWarning`) names the thinnest
    wall when it gets fewer than 4 cells). axis: "x", "y" (the bed's axis, default) or "z".
    Re: the target Reynolds number U D / nu of the run (the force is set from an estimate of
    k and then reported as run; 0.01 keeps inertia out of a Darcy permeability). Other
    arguments: see :func:`pack_domain` and :func:`peclet.flow.solver.solve`. Returns a
    :class:`PackFlow`.
    """
    from peclet.packing.freeze import Pack, load_pack
    pk = pack if isinstance(pack, Pack) else load_pack(pack)
    ax = _AXIS[check_choice("axis", axis, tuple(_AXIS))]
    Re = check_float("Re", Re, 0.0, 10.0, lo_open=True)
    grid, phi, info = pack_domain(pk, resolution, window, y_mode)
    t_wall, wall_name = thinnest_wall(pk)
    res = float(resolution)
    if t_wall * res < 4.0:
        msg = (f"the thinnest wall, {wall_name}, spans {t_wall * res:.2f} cells at D/{res:g} "
               "(fewer than 4): link-crossing tests keep it solid, but the flow next to it is "
               f"under-resolved; D/{math.ceil(4.0 / t_wall)} puts 4 cells across it")
        warnings.warn(msg, ThinWallWarning, stacklevel=2)
        info["thin_wall_warning"] = msg
    geo = build_geometry(grid, phi, samples=samples,
                         seams=(False, info["y_mode"] == "wrap", False))
    eps = geo.porosity
    d_s, d_env = _diameters(pk, area_n)
    # the force from a Carman-Kozeny guess of k, so the run sits near the requested Re
    k_guess = max(eps ** 3 * d_s ** 2 / (180.0 * max(1.0 - eps, 1e-3) ** 2), 1e-6) * res ** 2
    U_target = Re * nu / res
    g = U_target * nu / k_guess
    F = np.zeros(3)
    F[ax] = g
    fr = solve(geo, F, nu=nu, magic=magic, scheme=scheme, tol=tol, max_steps=max_steps,
               progress=progress, mass=mass)
    U = float(fr.U[ax])
    if not U > 0.0:
        raise FloatingPointError(f"no flow along {axis}: U = {U}")
    k_lu = nu * U / g
    k_D2 = k_lu / res ** 2
    drag, inside = _element_drag(pk, fr, grid, ax, info)
    total = float(fr.link_force[:, ax].sum())
    kozeny = eps ** 3 * d_s ** 2 / (36.0 * k_D2 * (1.0 - eps) ** 2)
    ergun = lambda d, e: e ** 3 * d ** 2 / (150.0 * k_D2 * (1.0 - e) ** 2)
    eps_env = math.nan
    if np.isfinite(d_env):
        from peclet.packing.analysis import PackGeometry, cover_fractions
        eps_env = 1.0 - cover_fractions(PackGeometry(pk), info["window"], 200_000)["f_env"]
    sel = drag[inside] if inside.any() else drag
    info.update({"eps_envelope": eps_env, "axis": axis, "nu": nu, "magic": magic,
                 "scheme": scheme, "force": g,
                 "thinnest_wall_D": t_wall, "thinnest_wall": wall_name,
                 "elements_inside": int(inside.sum())})
    return PackFlow(resolution=res, k_D2=k_D2, k_lattice=k_lu, dpdl_lattice=g,
                    Re=U * res / nu, eps=eps, d_sauter=d_s, d_envelope=d_env, kozeny=kozeny,
                    ergun_ratio_sauter=ergun(d_s, eps),
                    ergun_ratio_envelope=ergun(d_env, eps_env) if np.isfinite(d_env)
                    else math.nan,
                    drag=drag, drag_cv=float(np.std(sel) / np.mean(sel)),
                    solid_drag_balance=total / (g * geo.n_fluid), flow=fr, info=info)


def _diameters(pack, n):
    """(Sauter diameter 6 V / A, envelope volume-equivalent diameter) in D; A from the
    element's surface mesh (:func:`peclet.core.geom.mesh.surface_mesh`, O(h^2))."""
    from peclet.core.geom.mesh import surface_mesh
    r = float(pack.bounding_radius) * 1.02
    _, _, area = surface_mesh(pack.builder(), pack.home_root, [-r] * 3, [r] * 3, n)
    d_s = 6.0 * float(pack.ring_volume) / float(area)
    d_env = (6.0 * pack.envelope_volume / math.pi) ** (1.0 / 3.0) \
        if np.isfinite(pack.envelope_volume) else math.nan
    return d_s, d_env


def _element_drag(pack, fr, grid, ax, info):
    """Drag along ``ax`` on each element: each cut link's momentum goes to the element whose
    tree is lowest at the link's wall point (mapped back into the window), summed in link
    order. Returns (drag (N,), inside (N,) bool: bounding sphere wholly inside the window)."""
    geo = fr.geometry
    pts = geo.wall_points()
    y0, y1 = info["window"]
    H = y1 - y0
    if info["y_mode"] == "mirror":
        t = np.mod(pts[:, 1] - y0, 2.0 * H)
        pts[:, 1] = y0 + np.where(t <= H, t, 2.0 * H - t)
    else:
        pts[:, 1] = y0 + np.mod(pts[:, 1] - y0, H)
    Lx, Lz = info["box"]
    b = pack.builder()
    R = pack.rotations()
    best = np.full(len(pts), np.inf)
    owner = np.full(len(pts), -1, np.int64)
    rb = float(pack.bounding_radius) + 2.0 * grid.h
    for e in range(pack.n):
        c0 = pack.positions[e]
        for sx in (-1, 0, 1):
            for sz in (-1, 0, 1):
                c = c0 + np.array([sx * Lx, 0.0, sz * Lz])
                d = pts - c
                near = np.flatnonzero((d * d).sum(1) <= rb * rb)
                if len(near) == 0:
                    continue
                v = b.eval_root(pack.home_root, d[near] @ R[e])
                better = v < best[near]
                best[near[better]] = v[better]
                owner[near[better]] = e
    drag = np.zeros(pack.n)
    f = fr.link_force[:, ax]
    ok = owner >= 0
    np.add.at(drag, owner[ok], f[ok])
    ys = pack.positions[:, 1]
    inside = (ys - pack.bounding_radius >= y0) & (ys + pack.bounding_radius <= y1)
    return drag, inside


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
