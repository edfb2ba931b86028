"""A pack's flow problem, set up once and measured after every solve: the pack and the container
its domain comes from, the lattice and its geometry, the porosity and the cross-section, the
element's diameters (:func:`prepare`, a :class:`FlowSetup`); from a solve, the superficial
velocity (:func:`superficial`) and the driving dP/L with the seam's share (:func:`drive`).

:func:`peclet.flow.permeability.permeability` runs one solve on it; :func:`peclet.flow.curve.
pressure_drop_curve` runs one per Reynolds number on the same geometry. Conventions (window,
seam, column sections, where dP/L comes from) are those of :mod:`peclet.flow.permeability`;
a triply periodic pack (a grown bed, :class:`~peclet.flow.domain.PeriodicCell`) has neither a
window nor a seam: its lattice is one whole period and the body force is the exact dP/L along
x, y or z.
"""
from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass, field

import numpy as np

from peclet.core.validation import PecletArgumentError, check_choice

from .domain import PeriodicCell, check_lattice_memory, pack_domain
from .geometry import build_geometry

__all__ = ["FlowSetup", "prepare", "superficial", "drive", "pack_container", "thinnest_wall",
           "ThinWallWarning", "seam_fit", "AXES"]

#: Axis name -> index.
AXES = _AXIS = {"x": 0, "y": 1, "z": 2}
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


def pack_container(pack, container=None):
    """(container, source): the container a pack was made in, for the flow.

    ``container``: None (default: read from the ``results.json`` that ``peclet pack`` writes
    beside its ``pack.npz``, when ``pack`` is a path and that file names the pack's container;
    else the periodic box), "box" (the pack's periodic box), a spec "column:N" (N element
    diameters, as ``peclet pack --container``), a :class:`~peclet.packing.bed.containers.Container`
    or the spec dict of ``results.json``; a :class:`~peclet.flow.domain.PeriodicCell` is
    returned as it is. Returns (a column Container bound to the element's
    diameter, or None for the periodic box; a phrase saying where it came from). Only boxes
    and columns are accepted (PecletArgumentError naming ``container``); a column must hold the
    pack: its analysis period is the pack's box and every element centre is inside it.
    """
    from peclet.packing.bed.containers import Container, parse_container
    from peclet.packing.bed.freeze import Pack
    source = "argument"
    d = 1.0
    if isinstance(container, PeriodicCell):
        return container, source
    if container is None:
        container, source = "box", "default (periodic box)"
        if not isinstance(pack, Pack):
            side = os.path.join(os.path.dirname(os.path.abspath(os.fspath(pack))),
                                "results.json")
            if os.path.isfile(side):
                import json
                try:
                    with open(side) as fh:
                        doc = json.load(fh)
                    spec = doc["spec"]["container"]
                    if isinstance(spec, (dict, str)):
                        d = float(doc.get("analysis", {}).get("d_elem", 1.0))
                        container, source = spec, f"{side} (spec.container)"
                except (ValueError, KeyError, TypeError, OSError):
                    pass
    if isinstance(container, str) and container.strip() == "box":
        return None, source
    cont = parse_container(container)
    if cont.kind == "box":
        return None, source
    if cont.kind != "column":
        raise PecletArgumentError("container", "box or column:N (peclet.flow runs periodic "
                                  "boxes and column sections)", cont.label())
    if not isinstance(container, Container):
        cont = cont.bound(d)
    pk = pack if isinstance(pack, Pack) else None
    if pk is not None:
        _check_column_holds(pk, cont)
    return cont, source


def _check_column_holds(pk, cont):
    Lx, Lz = cont.period
    if not np.allclose(pk.box, (Lx, Lz), rtol=1e-9, atol=1e-12):
        raise PecletArgumentError("container", f"the column the pack was made in (its period, "
                                  f"{Lx:g} x {Lz:g}, is the pack's box)", cont.label(),
                                  f"the pack's box is {pk.box[0]:g} x {pk.box[1]:g}")
    cx, cz = cont.center_xz
    r = np.hypot(pk.positions[:, 0] - cx, pk.positions[:, 2] - cz)
    if np.any(r >= cont.radius):
        raise PecletArgumentError("container", "a column holding every element centre",
                                  cont.label(), f"a centre {r.max():.4g} from the axis, radius "
                                  f"{cont.radius:g}")


def seam_fit(flow, info, margin):
    """The fluid-averaged pressure of each lattice plane normal to y (p = rho c_s^2, lattice
    units), fitted by a line over the planes more than ``margin`` (D) from the wrapped
    window's seam (y0 = y1). Returns {"slope" (pressure per cell), "slope_se" (its standard
    error), "planes" (used), "planes_total"}; slope NaN with fewer than 4 planes."""
    geo = flow.geometry
    ny = geo.grid.dims[1]
    h = geo.grid.h
    j = geo.ijk[:, 1]
    cnt = np.bincount(j, minlength=ny).astype(np.float64)
    p = np.bincount(j, weights=flow.rho, minlength=ny) / np.maximum(cnt, 1.0) / 3.0
    js = np.arange(ny)
    dist = h * np.minimum(js + 0.5, ny - 0.5 - js)
    use = (dist >= margin) & (cnt > 0)
    out = {"planes": int(use.sum()), "planes_total": int(ny), "slope": math.nan,
           "slope_se": math.nan}
    if use.sum() < 4:
        return out
    x = js[use].astype(np.float64)
    y = p[use]
    A = np.column_stack([np.ones_like(x), x - x.mean()])
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    res = y - A @ coef
    se = math.sqrt(float(res @ res) / (len(x) - 2) / float(((x - x.mean()) ** 2).sum()))
    out.update(slope=float(coef[1]), slope_se=se)
    return out


def _seam_shares(flow, info, margin, g):
    """The seam's share of the drive fitted beyond 0.5, 1 and 1.5 times ``margin`` (those
    with at least 4 planes): {margin in D: share}. Its spread shows how far the plane
    pressure wanders from a line (pore-scale structure) beyond what the fit's standard error
    says."""
    out = {}
    for m in (0.5 * margin, margin, 1.5 * margin):
        f = seam_fit(flow, info, m)
        if math.isfinite(f["slope"]):
            out[f"{m:g}"] = f["slope"] / g
    return out



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




@dataclass
class FlowSetup:
    """One pack's flow problem (:func:`prepare`). pack (Pack), container (a column Container,
    a :class:`~peclet.flow.domain.PeriodicCell` or None for the box), column (the column
    Container or None), cell (True for a triply periodic pack), grid, geo (LatticeGeometry),
    info (the domain's parameters, as :class:`~peclet.flow.permeability.PackFlow`'s), axis and
    ax (its index), res (cells per D of the lattice: 1 / h; a box side not a whole number of
    cells at the requested resolution rounds it), area_lu (the cross-section normal to the
    axis, cells^2), eps (porosity: the lattice's fluid fraction, of the nodes inside the wall
    in a column), eps_core (a column's, > 1 D from the wall), d_s and d_env (Sauter and
    envelope-volume diameters, D), t_wall and wall_name (the thinnest wall)."""
    pack: object
    container: object
    column: object
    cell: bool
    grid: object
    geo: object
    info: dict
    axis: str
    ax: int
    res: float
    area_lu: float
    eps: float
    eps_core: float
    d_s: float
    d_env: float
    t_wall: float
    wall_name: str
    extra: dict = field(default_factory=dict)


def prepare(pack, resolution=16, axis="y", window=None, y_mode="wrap", container=None,
            samples=8, area_n=160, stacklevel=3):
    """The :class:`FlowSetup` of ``pack`` (a Pack or a path to any pack file peclet writes,
    :func:`peclet.flow.packs.load_flow_pack`) at ``resolution`` cells per D along ``axis``
    (arguments as :func:`peclet.flow.permeability.permeability`); warns
    (:class:`ThinWallWarning`) when the thinnest wall gets fewer than 4 cells."""
    from .packs import load_flow_pack
    pk, found, source = load_flow_pack(pack)
    ax = _AXIS[check_choice("axis", axis, tuple(_AXIS))]
    if container is None and found is not None:
        cont = found
    else:
        cont, source = pack_container(pack if found is None else pk, container)
    cell = isinstance(cont, PeriodicCell)
    column = None if cell else cont
    if column is not None:
        _check_column_holds(pk, column)
        if axis != "y":
            raise PecletArgumentError("axis", "y (a column section: the flow runs along the "
                                      "column's axis; its wall closes x and z)", axis)
    check_lattice_memory(pk, resolution, window, y_mode, cont)   # before any work
    grid, phi, info = pack_domain(pk, resolution, window, y_mode, cont)
    info["container_source"] = source
    info["resolution_requested"] = float(resolution)
    res = 1.0 / grid.h
    t_wall, wall_name = thinnest_wall(pk)
    if t_wall * res < 4.0:
        msg = (f"the thinnest wall, {wall_name}, spans {t_wall * res:.2f} cells at D/{res:g} "
               "(fewer than 4): link-crossing tests keep it solid, but the flow next to it is "
               f"under-resolved; D/{math.ceil(4.0 / t_wall)} puts 4 cells across it")
        warnings.warn(msg, ThinWallWarning, stacklevel=stacklevel)
        info["thin_wall_warning"] = msg
    geo = build_geometry(grid, phi, samples=samples,
                         seams=(False, info["y_mode"] == "wrap" and not cell, False))
    nx, ny, nz = grid.dims
    eps_core = math.nan
    if column is not None:
        # the column's own cross-section: its area exactly, its nodes for the porosity
        R_lu = float(column.radius) / grid.h
        area_lu = math.pi * R_lu * R_lu
        lat = np.arange(nx) - 0.5 * (nx - 1)
        r2 = lat[:, None] ** 2 + lat[None, :] ** 2
        eps = geo.n_fluid / (int(np.count_nonzero(r2 < R_lu * R_lu)) * ny)
        core = r2 < (R_lu - res) ** 2
        core_cells = np.zeros(nx * nz, bool)
        core_cells[(core.T).reshape(-1)] = True      # flat index x + nx z (square lattice)
        fl = geo.ijk[:, 0] + nx * geo.ijk[:, 2]
        n_core = int(core.sum()) * ny
        eps_core = float(np.count_nonzero(core_cells[fl]) / n_core) if n_core else math.nan
    else:
        area_lu = float(grid.n_cells / grid.dims[ax])
        eps = geo.porosity
    d_s, d_env = _diameters(pk, area_n)
    return FlowSetup(pack=pk, container=cont, column=column, cell=cell, grid=grid, geo=geo,
                     info=info, axis=axis, ax=ax, res=res, area_lu=area_lu, eps=eps,
                     eps_core=eps_core, d_s=d_s, d_env=d_env, t_wall=t_wall,
                     wall_name=wall_name)


def superficial(setup, fr):
    """The superficial velocity along the axis (lattice units): the flux over uncut links
    through a lattice plane (FlowResult.U times the cells of a plane) over the cross-section."""
    g = setup.grid
    return float(fr.U[setup.ax]) * (g.n_cells / g.dims[setup.ax]) / setup.area_lu


def drive(setup, fr, g, U, nu, seam_margin=1.0):
    """(dP/L in lattice units, updates for ``info``) of a solve driven by the body force
    density ``g`` (superficial velocity ``U``, viscosity ``nu``): the body force itself where
    it is exact (a box across y, a triply periodic cell, a mirrored window); along y of a
    wrapped window the seam's share is fitted away from it (:func:`seam_fit`): a column takes
    dP/L = g - slope, a box keeps g (whole period) and reports the seam-free k beside it
    (:mod:`peclet.flow.permeability`)."""
    info = setup.info
    res = setup.res
    up = {}
    out = g
    if setup.cell:
        up["dpdl_source"] = ("body force (exact: the pack is triply periodic and the lattice "
                             "one whole period)")
    elif info["y_mode"] == "wrap" and setup.ax == 1:
        seam = seam_fit(fr, info, seam_margin)
        up.update({"seam_margin_D": seam_margin, "seam_planes": seam["planes"],
                   "seam_share": seam["slope"] / g, "seam_share_se": seam["slope_se"] / g,
                   "k_D2_seam_free": nu * U / (g - seam["slope"]) / res ** 2,
                   "seam_share_by_margin": _seam_shares(fr, info, seam_margin, g)})
        if setup.column is not None and math.isfinite(seam["slope"]):
            out = g - seam["slope"]
            up["dpdl_source"] = "body force minus the pressure slope away from the seam"
        elif setup.column is not None:
            up["dpdl_source"] = (f"body force (whole period, seam included: fewer than 4 "
                                 f"lattice planes lie {seam_margin:g} D or more from the "
                                 "seam)")
        else:
            up["dpdl_source"] = ("body force (whole period of the wrapped window, seam "
                                 "included; k_D2_seam_free beside it)")
    elif info["y_mode"] == "wrap":
        up["dpdl_source"] = ("body force (exact: the structure is periodic along the flow; "
                             "the seam lies along it)")
    else:
        up["dpdl_source"] = "body force (exact for the mirrored period)"
    return out, up
