"""The velocity field for ParaView (VTI image data, VTU points) and a slice figure.

Velocities are written in lattice units (cells per step) and also scaled by ``scale`` when
given; coordinates are world (the pack's D). Both files are written atomically.

- VTI: the whole box of nodes (solid nodes carry u = 0 and ``fluid`` = 0), point data
  ``velocity`` (3 components) and ``speed``; base64 binary with a UInt64 header, so any VTK
  reader (ParaView) opens it; :func:`read_vti` reads it back (the tests do).
- VTU (meshio): one vertex cell per fluid node with ``velocity`` and ``speed``.
"""
from __future__ import annotations

import base64
import os
import xml.etree.ElementTree as ET

import numpy as np

from peclet.core.files import atomic_write, check_writable_path, write_text
from peclet.core.validation import PecletArgumentError, check_choice

__all__ = ["write_vti", "read_vti", "write_vtu", "slice_figure", "full_field", "curve_figure",
           "curve_table"]


def full_field(flow):
    """(u (nz, ny, nx, 3), fluid (nz, ny, nx) bool) of a FlowResult on the whole grid."""
    geo = flow.geometry
    nx, ny, nz = geo.grid.dims
    u = np.zeros((nx * ny * nz, 3))
    fluid = geo.cell >= 0
    u[fluid] = flow.u
    return u.reshape(nz, ny, nx, 3), fluid.reshape(nz, ny, nx)


def _b64(a):
    raw = np.ascontiguousarray(a).tobytes()
    return base64.b64encode(np.uint64(len(raw)).tobytes() + raw).decode("ascii")


def write_vti(path, flow):
    """Write the velocity field of ``flow`` (a FlowResult) as a VTK ImageData file."""
    path = check_writable_path(path, "path")
    g = flow.geometry.grid
    nx, ny, nz = g.dims
    u, fluid = full_field(flow)
    speed = np.sqrt((u * u).sum(-1))
    ext = f"0 {nx - 1} 0 {ny - 1} 0 {nz - 1}"
    org = " ".join(repr(float(v)) for v in g.origin)
    sp = " ".join([repr(float(g.h))] * 3)
    body = (
        '<?xml version="1.0"?>\n'
        '<VTKFile type="ImageData" version="1.0" byte_order="LittleEndian" '
        'header_type="UInt64">\n'
        f'  <ImageData WholeExtent="{ext}" Origin="{org}" Spacing="{sp}">\n'
        f'    <Piece Extent="{ext}">\n'
        '      <PointData Scalars="speed" Vectors="velocity">\n'
        '        <DataArray type="Float64" Name="velocity" NumberOfComponents="3" '
        f'format="binary">{_b64(u.astype("<f8"))}</DataArray>\n'
        '        <DataArray type="Float64" Name="speed" format="binary">'
        f'{_b64(speed.astype("<f8"))}</DataArray>\n'
        '        <DataArray type="UInt8" Name="fluid" format="binary">'
        f'{_b64(fluid.astype(np.uint8))}</DataArray>\n'
        '      </PointData>\n    </Piece>\n  </ImageData>\n</VTKFile>\n')
    return write_text(path, body)


def read_vti(path):
    """Read a VTI written by :func:`write_vti`: dict with dims (nx, ny, nz), origin, spacing
    and each point array reshaped to (nz, ny, nx[, components])."""
    if not os.path.isfile(path):
        raise PecletArgumentError("path", "an existing .vti file", path)
    root = ET.parse(path).getroot()
    img = root.find("ImageData")
    if root.get("type") != "ImageData" or img is None:
        raise PecletArgumentError("path", "a VTK ImageData file", path)
    e = [int(v) for v in img.get("WholeExtent").split()]
    dims = (e[1] + 1, e[3] + 1, e[5] + 1)
    out = {"dims": dims, "origin": [float(v) for v in img.get("Origin").split()],
           "spacing": [float(v) for v in img.get("Spacing").split()]}
    types = {"Float64": "<f8", "UInt8": "u1"}
    for da in img.iter("DataArray"):
        raw = base64.b64decode(da.text.strip())
        n = int(np.frombuffer(raw[:8], "<u8")[0])
        a = np.frombuffer(raw[8:8 + n], types[da.get("type")])
        comp = int(da.get("NumberOfComponents", "1"))
        shape = (dims[2], dims[1], dims[0]) + ((comp,) if comp > 1 else ())
        out[da.get("Name")] = a.reshape(shape)
    return out


def write_vtu(path, flow):
    """Write the fluid nodes of ``flow`` as VTU vertices with ``velocity`` and ``speed``."""
    import meshio
    path = check_writable_path(path, "path")
    geo = flow.geometry
    pts = geo.grid.points(geo.ijk)
    n = len(pts)
    mesh = meshio.Mesh(pts, [("vertex", np.arange(n, dtype=np.int64).reshape(-1, 1))],
                       point_data={"velocity": flow.u,
                                   "speed": np.sqrt((flow.u ** 2).sum(1))})
    atomic_write(path, lambda tmp: meshio.write(tmp, mesh, file_format="vtu"))
    return path


def slice_figure(path, flow, plane="xy", index=None, title=None):
    """A PNG of the speed |u| on one lattice plane (``plane`` "xy", "yz" or "xz"; ``index``
    the node index along the third axis, default the middle), solids grey; drawn through
    :mod:`peclet.core.figures` (the user's matplotlib backend is left alone)."""
    from peclet.core.figures import save_png, subplots
    plane = check_choice("plane", plane, ("xy", "yz", "xz"))
    path = check_writable_path(path, "path")
    u, fluid = full_field(flow)
    s = np.sqrt((u * u).sum(-1))
    g = flow.geometry.grid
    nx, ny, nz = g.dims
    if plane == "xy":
        i = nz // 2 if index is None else int(index)
        img, mask, ext, lab = s[i], fluid[i], (0, nx, 0, ny), ("x", "y")
    elif plane == "yz":
        i = nx // 2 if index is None else int(index)
        img, mask, ext, lab = s[:, :, i].T, fluid[:, :, i].T, (0, nz, 0, ny), ("z", "y")
    else:
        i = ny // 2 if index is None else int(index)
        img, mask, ext, lab = s[:, i, :], fluid[:, i, :], (0, nx, 0, nz), ("x", "z")
    h = g.h
    o = g.origin
    ax_o = {"x": o[0], "y": o[1], "z": o[2]}
    extent = (ax_o[lab[0]] + h * (ext[0] - 0.5), ax_o[lab[0]] + h * (ext[1] - 0.5),
              ax_o[lab[1]] + h * (ext[2] - 0.5), ax_o[lab[1]] + h * (ext[3] - 0.5))
    fig, ax = subplots(figsize=(6, 6 * (ext[3] - ext[2]) / max(ext[1] - ext[0], 1)))
    im = ax.imshow(np.ma.masked_where(~mask, img), origin="lower", extent=extent,
                   cmap="viridis", interpolation="nearest")
    ax.imshow(np.where(mask, np.nan, 1.0), origin="lower", extent=extent, cmap="Greys",
              vmin=0, vmax=2, interpolation="nearest")
    ax.set_xlabel(f"{lab[0]} / D")
    ax.set_ylabel(f"{lab[1]} / D")
    ax.set_title(title or f"|u| on the {plane} plane, index {i} (lattice units)")
    fig.colorbar(im, ax=ax, label="|u| (cells/step)", shrink=0.8)
    save_png(fig, path, dpi=110, bbox_inches="tight")
    return path


def curve_figure(path, curve, title=None):
    """The friction factor f = (dP/L) D^2 / (mu U) against Re (log-log) of a
    :class:`~peclet.flow.curve.Curve`: the steady points, the Forchheimer fit, Ergun (Sauter
    diameter) and, for spheres, Eisfeld & Schnitzlein (their wall terms in a column, else the
    unconfined limit). Drawn on its own canvas (peclet.core.figures: the user's matplotlib
    backend is not touched); written atomically."""
    from peclet.core.figures import save_png, subplots

    from .correlations import eisfeld_schnitzlein, ergun

    check_writable_path("path", path)
    ok = [p for p in curve.points if p.status == "steady"]
    fig, ax = subplots(figsize=(6.0, 4.2))
    lo = min([p.Re_target for p in curve.points] + [p.Re for p in ok])
    hi = max([p.Re_target for p in curve.points] + [p.Re for p in ok])
    re = np.geomspace(lo / 2.0, hi * 2.0, 200)
    e = curve.eps
    ax.plot(re, ergun(re, e, curve.d_sauter, 1.0)[0] / re, "-", color="0.4",
            label=f"Ergun (150, 1.75), d = Sauter {curve.d_sauter:.3f} D")
    if curve.spheres:
        es = eisfeld_schnitzlein(re, e, curve.d_volume, curve.D_t, 1.0)[0] / re
        wall = f"D_t/d_p = {curve.D_t / curve.d_volume:.2f}" if np.isfinite(curve.D_t) \
            else "no wall"
        ax.plot(re, es, "--", color="C2", label=f"Eisfeld & Schnitzlein ({wall})")
    if curve.fit is not None:
        f = curve.fit
        ax.plot(re, f["A"] + f["B"] * re, ":", color="C1",
                label=f"Forchheimer fit: k = {f['k_D2']:.4g} D^2, beta = {f['beta_D']:.3g}/D")
    ax.plot([p.Re for p in ok], [p.f for p in ok], "o", color="C0",
            label=f"lattice Boltzmann, D/{curve.resolution:.3g}")
    bad = [p for p in curve.points if p.status != "steady"]
    for p in bad:
        ax.axvline(p.Re_target, color="C3", lw=0.6, alpha=0.5)
    if bad:
        ax.plot([], [], "-", color="C3", lw=0.6, label="not steady / not run (target Re)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("Re = rho U D / mu")
    ax.set_ylabel("f = (dP/L) D^2 / (mu U)")
    ax.set_title(title or f"pressure drop, eps = {e:.3f}", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    save_png(fig, path, dpi=110)
    return path


def curve_table(curve):
    """The points of a :class:`~peclet.flow.curve.Curve` as a text table, the fit under it."""
    head = ["Re target", "Re", "Re/(1-eps)", "f = dP/L D^2/(mu U)", "/ Ergun", "/ E&S",
            "steps", "max|u|/c_s", "nu", "status"]
    rows = []
    for p in curve.points:
        ok = p.status == "steady"
        fmt = lambda v, f: (f.format(v) if ok else "-")
        rows.append([f"{p.Re_target:.4g}", fmt(p.Re, "{:.4g}"), fmt(p.Re_mod, "{:.4g}"),
                     fmt(p.f, "{:.5g}"), fmt(p.dpdl / p.ergun, "{:.3f}"),
                     fmt(p.dpdl / p.es, "{:.3f}") if np.isfinite(p.es) else "-",
                     str(p.iterations), f"{p.mach:.3f}" if np.isfinite(p.mach) else "-",
                     f"{p.nu:.3g}" if np.isfinite(p.nu) else "-",
                     p.status + ("" if ok else f": {p.reason}")])
    w = [max(len(r[i]) for r in [head] + rows) for i in range(len(head) - 1)]
    line = lambda r: "  ".join([c.rjust(w[i]) for i, c in enumerate(r[:-1])] + [r[-1]])
    out = [line(head), "  ".join("-" * x for x in w) + "  ------"] + [line(r) for r in rows]
    f = curve.fit
    if f is not None:
        se = (lambda v: "n/a with 2 points") if f["points"] < 3 else (lambda v: f"{v:.2g}")
        out.append(f"Forchheimer fit dP/L = (mu/k) U + beta rho U^2 over {f['points']} steady "
                   f"points: k = {f['k_D2']:.5g} D^2 (+- {se(f['k_se'])}), beta = "
                   f"{f['beta_D']:.4g} / D (+- {se(f['beta_se'])}), rms relative residual "
                   f"{f['rms_rel']:.2e}")
    else:
        out.append("Forchheimer fit: fewer than 2 steady points")
    return "\n".join(out)
