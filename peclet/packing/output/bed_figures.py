"""Figures of a packed bed: the radial and axial voidage profiles and a rendered view of the bed.

Drawn through :mod:`peclet.core.figures` (a Figure on its own Agg canvas: no pyplot state, no
backend switch), saved as PNG atomically.

The bed view is a small z-buffer rasteriser (one Numba kernel) over SHADED SURFACE MESHES: the
element's home mesh (:func:`peclet.packing.output.export.element_mesh`) is moved by every pose and its
triangles are filled with Lambert-shaded colours, nearest surface winning per pixel. It renders
thousands of elements in seconds, where matplotlib's 3-D polygons cost minutes; the kernel
loops in a fixed order, so the image is the same at any thread count.
"""
from __future__ import annotations

import math

import numpy as np
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize
from numba import njit

from peclet.core.figures import new_figure, save_png
from peclet.core.validation import PecletArgumentError, check_bool, check_float, check_int

from ..analysis.profiles import de_klerk_voidage

__all__ = ["radial_profile_figure", "axial_profile_figure", "bed_view", "render_bed"]

_RC = dict(dpi=130)


def _save(fig, path):
    return save_png(fig, path, dpi=_RC["dpi"], bbox_inches="tight")


def _style(ax):
    ax.grid(alpha=0.3, lw=0.6)
    ax.tick_params(labelsize=8)
    for s in ("top", "right"):
        ax.spines[s].set_visible(False)


def radial_profile_figure(prof, path, sphere=False, eps_bulk=0.39, title=None):
    """eps(z) against the distance from the wall z (element diameters), with a +-2 s.e. band;
    for a bed of spheres (``sphere``) also de Klerk's correlation with bulk ``eps_bulk``.
    ``prof`` as returned by :func:`peclet.packing.analysis.profiles.radial_profile`."""
    z = np.asarray(prof["z"], float)
    e = np.asarray(prof["eps"], float)
    se = np.asarray(prof["eps_se"], float)
    fig = new_figure(figsize=(6.4, 3.3))
    ax = fig.add_subplot(1, 1, 1)
    ax.fill_between(z, e - 2 * se, e + 2 * se, color="#4c72b0", alpha=0.25, lw=0,
                    label=r"$\pm 2$ standard errors")
    ax.plot(z, e, color="#4c72b0", lw=1.3, label=r"this bed (exact point sampling)")
    if check_bool("sphere", sphere):
        # the two branches meet at z = 0.637 continuously only for eps_b near 0.36: drawn apart
        zmax = float(prof["z_edges"][-1])
        branches = (np.linspace(0.0, 0.637, 200), np.linspace(0.637 + 1e-9, zmax, 600))
        for k, zz in enumerate(branches):
            ax.plot(zz, de_klerk_voidage(zz, eps_bulk), color="#c44e52", lw=1.3, ls="--",
                    label=rf"de Klerk (2003), $\varepsilon_b$ = {eps_bulk:.3g}" if k else None)
    ax.set_xlim(0, float(prof["z_edges"][-1]))
    ax.set_ylim(0, 1.02)
    ax.set_xlabel(r"distance from the wall $z$ / element diameter")
    ax.set_ylabel(r"voidage $\varepsilon(z)$")
    w = float(np.max(np.abs(np.diff(prof["z_edges"]))))
    ax.set_title(title or f"radial voidage profile (shells {w:.3g} D, "
                 f"{prof['n_per_shell']} points each)", fontsize=9)
    ax.legend(fontsize=7.5, frameon=False, loc="upper right")
    _style(ax)
    return _save(fig, path)


def axial_profile_figure(prof, path, d_elem=1.0, floor_y=0.0, bulk=None, title=None):
    """Slab voidage against height above the floor (element diameters), height vertical.
    ``bulk`` (a :func:`~peclet.packing.analysis.profiles.bulk` result) adds the bulk value with its
    standard error and greys the cropped floor and free-surface zones."""
    y = (np.asarray(prof["y"], float) - floor_y) / d_elem
    e = np.asarray(prof["eps"], float)
    se = np.asarray(prof["eps_se"], float)
    fig = new_figure(figsize=(3.6, 4.6))
    ax = fig.add_subplot(1, 1, 1)
    ax.fill_betweenx(y, e - 2 * se, e + 2 * se, color="#4c72b0", alpha=0.25, lw=0)
    ax.plot(e, y, color="#4c72b0", lw=1.1, label="slab voidage")
    if bulk is not None:
        lo, hi = (bulk["windows"][0, 0] - floor_y) / d_elem, (bulk["windows"][-1, 1] - floor_y) \
            / d_elem
        ax.axhspan(y.min() - 1, lo, color="0.85", zorder=0)
        ax.axhspan(hi, y.max() + 1, color="0.85", zorder=0, label="cropped zones")
        ax.plot([bulk["eps"]] * 2, [lo, hi], color="#c44e52", lw=1.6,
                label=rf"bulk $\varepsilon$ = {bulk['eps']:.3f} $\pm$ {bulk['eps_se']:.3f}")
    ax.set_ylim(y.min(), y.max())
    ax.set_xlim(0, 1.02)
    ax.set_xlabel(r"voidage $\varepsilon$")
    ax.set_ylabel("height above the floor / element diameter")
    ax.set_title(title or "axial voidage profile", fontsize=9)
    ax.legend(fontsize=7, frameon=False, loc="upper center", bbox_to_anchor=(0.5, -0.13))
    _style(ax)
    return _save(fig, path)


# ---------------------------------------------------------------------- the rasteriser
@njit(cache=True)
def _raster(vh, faces, rot, pos, rgb, view, scale, x0, y0, light, img, zbuf):
    """Fill ``img`` (H, W, 3) with every element's triangles, Lambert-shaded, nearest first.

    vh (V, 3) home vertices; faces (F, 3); rot (N, 3, 3) home -> world; pos (N, 3); rgb (N, 3)
    element colours; view (3, 3) world -> screen rows (right, up, toward the viewer); a world
    point maps to pixel ((s0 - x0) * scale, (y0 - s1) * scale) with depth s2.
    """
    H, W = zbuf.shape
    nv = vh.shape[0]
    sv = np.empty((nv, 3))
    for e in range(rot.shape[0]):
        M = np.zeros((3, 3))
        t = np.zeros(3)
        for a in range(3):
            for b in range(3):
                t[a] += view[a, b] * pos[e, b]
                for c in range(3):
                    M[a, b] += view[a, c] * rot[e, c, b]
        for k in range(nv):
            for a in range(3):
                sv[k, a] = M[a, 0] * vh[k, 0] + M[a, 1] * vh[k, 1] + M[a, 2] * vh[k, 2] + t[a]
        for f in range(faces.shape[0]):
            i, j, k = faces[f, 0], faces[f, 1], faces[f, 2]
            ux, uy, uz = sv[j, 0] - sv[i, 0], sv[j, 1] - sv[i, 1], sv[j, 2] - sv[i, 2]
            wx, wy, wz = sv[k, 0] - sv[i, 0], sv[k, 1] - sv[i, 1], sv[k, 2] - sv[i, 2]
            nx, ny, nz = uy * wz - uz * wy, uz * wx - ux * wz, ux * wy - uy * wx
            nn = math.sqrt(nx * nx + ny * ny + nz * nz)
            if nn == 0.0:
                continue
            lam = abs(nx * light[0] + ny * light[1] + nz * light[2]) / nn
            c = 0.38 + 0.62 * lam
            ax_, ay_ = (sv[i, 0] - x0) * scale, (y0 - sv[i, 1]) * scale
            bx_, by_ = (sv[j, 0] - x0) * scale, (y0 - sv[j, 1]) * scale
            cx_, cy_ = (sv[k, 0] - x0) * scale, (y0 - sv[k, 1]) * scale
            area = (bx_ - ax_) * (cy_ - ay_) - (by_ - ay_) * (cx_ - ax_)
            if area == 0.0:
                continue
            p0 = max(int(math.floor(min(ax_, bx_, cx_))), 0)
            p1 = min(int(math.ceil(max(ax_, bx_, cx_))), W - 1)
            q0 = max(int(math.floor(min(ay_, by_, cy_))), 0)
            q1 = min(int(math.ceil(max(ay_, by_, cy_))), H - 1)
            for q in range(q0, q1 + 1):
                py = q + 0.5
                for p in range(p0, p1 + 1):
                    px = p + 0.5
                    l0 = ((bx_ - px) * (cy_ - py) - (by_ - py) * (cx_ - px)) / area
                    l1 = ((cx_ - px) * (ay_ - py) - (cy_ - py) * (ax_ - px)) / area
                    l2 = 1.0 - l0 - l1
                    if l0 < 0.0 or l1 < 0.0 or l2 < 0.0:
                        continue
                    d = l0 * sv[i, 2] + l1 * sv[j, 2] + l2 * sv[k, 2]
                    if d > zbuf[q, p]:
                        zbuf[q, p] = d
                        for a in range(3):
                            img[q, p, a] = c * rgb[e, a]


def _view_matrix(elev, azim):
    """Rows: screen right, screen up, toward the viewer; world y is up."""
    a, e = math.radians(azim), math.radians(elev)
    toward = np.array([math.cos(e) * math.sin(a), math.sin(e), math.cos(e) * math.cos(a)])
    right = np.cross([0.0, 1.0, 0.0], toward)
    right /= np.linalg.norm(right)
    return np.ascontiguousarray(np.vstack([right, np.cross(toward, right), toward]))


def render_bed(pack, home_mesh, colours, width=900, elev=18.0, azim=30.0, keep=None,
               supersample=2):
    """RGB image (H, W, 3) in [0, 1] of the bed's shaded meshes on white, and its height.

    ``home_mesh`` (verts, faces) in the home frame; ``colours`` (N, 3) RGB per element; ``keep``
    an optional boolean mask of the elements to draw (e.g. a cut-away). The view is orthographic
    from elevation ``elev`` and azimuth ``azim`` (degrees); rendered at ``supersample`` times the
    size and averaged down to smooth the edges.
    """
    width = check_int("width", width, 64, 8000)
    ss = check_int("supersample", supersample, 1, 4)
    v, f = (np.ascontiguousarray(a) for a in home_mesh)
    sel = np.ones(pack.n, bool) if keep is None else np.asarray(keep, bool)
    rot = np.ascontiguousarray(pack.rotations()[sel])
    pos = np.ascontiguousarray(pack.positions[sel])
    rgb = np.ascontiguousarray(np.asarray(colours, float)[sel][:, :3])
    view = _view_matrix(elev, azim)
    # the screen extent from the bounding spheres of the drawn elements
    s = pos @ view.T
    r = pack.bounding_radius
    lo, hi = s.min(axis=0) - r, s.max(axis=0) + r
    W = width * ss
    scale = W / (hi[0] - lo[0])
    H = int(math.ceil((hi[1] - lo[1]) * scale))
    img = np.ones((H, W, 3))
    zbuf = np.full((H, W), -np.inf)
    light = view @ np.array([-0.35, 0.8, 0.5])
    light /= np.linalg.norm(light)
    _raster(v.astype(np.float64), f.astype(np.int64), rot, pos, rgb, view, scale,
            float(lo[0]), float(hi[1]), light, img, zbuf)
    H2 = H // ss
    img = img[:H2 * ss].reshape(H2, ss, width, ss, 3).mean(axis=(1, 3))
    return img


def bed_view(pack, home_mesh, path, cutaway_center_xz=None, floor_y=0.0, d_elem=1.0,
             width=700, title=None):
    """The bed rendered as shaded surface meshes, coloured by the height of each element's
    centre above the floor (element diameters). With ``cutaway_center_xz`` (a column's axis)
    a second panel shows the half of the bed behind the vertical plane through the axis
    facing the viewer, which opens the wall layers and the core to view."""
    d = check_float("d_elem", d_elem, 0.0, lo_open=True)
    hgt = (pack.positions[:, 1] - floor_y) / d
    norm = Normalize(float(hgt.min()), float(hgt.max()) + 1e-12)
    cmap = ScalarMappable(norm=norm, cmap="viridis")
    col = cmap.to_rgba(hgt)[:, :3]
    azim = 30.0
    panels = [("the bed", None)]
    if cutaway_center_xz is not None:
        c = np.asarray(cutaway_center_xz, float).reshape(2)
        toward = _view_matrix(0.0, azim)[2]
        # keep elements behind the plane through the axis, normal toward the viewer
        keep = (pack.positions[:, 0] - c[0]) * toward[0] + (pack.positions[:, 2] - c[1]) \
            * toward[2] <= 0.0
        if not keep.any():
            raise PecletArgumentError("cutaway_center_xz", "an axis with elements behind it",
                                      cutaway_center_xz)
        panels.append(("cut-away half (plane through the axis)", keep))
    imgs = [render_bed(pack, home_mesh, col, width=width, azim=azim, keep=k) for _, k in panels]
    hmax = max(im.shape[0] for im in imgs)
    fig = new_figure(figsize=(3.4 * len(panels) + 0.8, 3.4 * hmax / width + 0.7))
    for k, ((ttl, _), im) in enumerate(zip(panels, imgs)):
        ax = fig.add_subplot(1, len(panels), k + 1)
        ax.imshow(im, interpolation="lanczos")
        ax.set_axis_off()
        ax.set_title(ttl, fontsize=8)
    fig.colorbar(cmap, ax=fig.axes, shrink=0.7, pad=0.02,
                 label="height of the centre above the floor / D")
    if title:
        fig.suptitle(title, fontsize=9)
    return _save(fig, path)
