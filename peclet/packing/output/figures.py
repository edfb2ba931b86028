"""Figures of the pipeline (matplotlib, PNG), one function per figure.

Every function takes plain arrays, writes ``path`` atomically and returns it. World frame: y up;
3-D plots show world y as the vertical axis.

No global state is touched: each figure comes from :mod:`peclet.core.figures` (a
:class:`matplotlib.figure.Figure` on its own Agg canvas, never ``pyplot``), so importing or
using this module leaves the user's backend (``matplotlib.get_backend()``) and pyplot's figure
list as they were (a notebook keeps its inline backend).
"""
from __future__ import annotations

import matplotlib
import numpy as np
from matplotlib.colors import Normalize
from mpl_toolkits.mplot3d import Axes3D  # noqa: F401  (registers the "3d" projection)
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

from peclet.core.figures import new_figure, save_png
from peclet.core.files import atomic_write

from ..bed.freeze import rotation_matrices, unit_quaternions

__all__ = ["ring_views", "kinetic_energy", "pack_by_height", "orientation_histogram",
           "voidage_sweep", "pour_animation"]

_STYLE = {"figure.dpi": 130, "font.size": 9, "axes.axisbelow": True,
          "figure.facecolor": "white", "savefig.bbox": "tight"}

#: Published bed voidage of 25 mm Pall rings (Billet & Schultes 1999; Stichlmair et al. 1989).
BANDS = {"metal / plastic 25 mm Pall rings": (0.90, 0.95, "#4c72b0", "#33517d"),
         "ceramic 25 mm Pall rings": (0.74, 0.78, "#c44e52", "#8c3439")}


def _height_colours(y):
    """viridis colours of heights ``y`` (N,) scaled to their range."""
    y = np.asarray(y, float)
    return matplotlib.colormaps["viridis"](Normalize(y.min(), y.max() + 1e-12)(y))


def _shaded(tri, color, light=(0.4, 0.5, 0.75)):
    """Per-face colours: ``color`` (any matplotlib colour) Lambert-shaded by the face normal
    (triangles ``tri`` (F, 3, 3) in plot coordinates), so 3-D meshes read as solids."""
    rgb = np.asarray(matplotlib.colors.to_rgb(color))
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1), 1e-300)[:, None]
    lam = np.abs(n @ (np.asarray(light) / np.linalg.norm(light)))
    k = (0.45 + 0.55 * lam)[:, None]
    return np.clip(np.c_[rgb[None, :] * k, np.ones(len(tri))], 0.0, 1.0)


def ring_views(verts, faces, path, extent=0.6):
    """The element from outside and down the bore (mesh in its authoring frame, axis y)."""
    with matplotlib.rc_context(_STYLE):
        fig = new_figure((5.4, 3.0))
        for k, (elev, azim, ttl) in enumerate([(22, 35, "outside"), (78, 20, "down the bore")]):
            ax = fig.add_subplot(1, 2, k + 1, projection="3d")
            # plot (x, z, y) so that the element axis y is vertical on screen
            tri = verts[faces][:, :, [0, 2, 1]]
            ax.add_collection3d(Poly3DCollection(tri, facecolors=_shaded(tri, "#8ea9c4"),
                                                 edgecolor="none"))
            for lim in (ax.set_xlim, ax.set_ylim, ax.set_zlim):
                lim(-extent, extent)
            ax.set_box_aspect((1, 1, 1))
            ax.set_axis_off()
            ax.view_init(elev=elev, azim=azim)
            ax.set_title(ttl, fontsize=8)
        return save_png(fig, path)


def kinetic_energy(t, ke, phases, dt, path):
    """Kinetic energy against time, log scale, protocol phases marked (``phases`` as
    :meth:`Protocol.phases`: [(label, first step)])."""
    t = np.asarray(t, float)
    ke = np.asarray(ke, float)
    with matplotlib.rc_context(_STYLE):
        fig = new_figure((6.0, 2.4))
        ax = fig.add_subplot(1, 1, 1)
        floor = max(ke[ke > 0].min() if np.any(ke > 0) else 1e-12, 1e-12)
        ax.semilogy(t, np.maximum(ke, floor), color="#4c72b0", lw=1.1)
        top = ke.max() if ke.size else 1.0
        for lbl, s in phases:
            ax.axvline(s * dt, color="0.75", lw=0.7, zorder=0)
            ax.text(s * dt + 0.01 * max(t.max(initial=dt), dt), 0.6 * top, lbl, fontsize=7,
                    color="0.35")
        ax.set_xlabel("time")
        ax.set_ylabel("kinetic energy")
        ax.grid(alpha=0.3)
        return save_png(fig, path)


def _draw_probes(ax, rotations, shell, positions, colours, extent, elev, **scatter_kw):
    """Scatter every body's probes (home-frame ``shell`` turned by its rotation and moved to
    its position) on a 3-D axis, y up, in the box [0, Lx] x [0, Lz] x [0, top]."""
    w = np.einsum("nij,mj->nmi", rotations, np.asarray(shell, float)) + positions[:, None, :]
    ax.scatter(w[..., 0].ravel(), w[..., 2].ravel(), w[..., 1].ravel(),
               c=np.repeat(colours, w.shape[1], axis=0), **scatter_kw)
    Lx, Lz, top = extent
    ax.set_xlim(0, Lx)
    ax.set_ylim(0, Lz)
    ax.set_zlim(0, top)
    ax.set_box_aspect((Lx, Lz, top))
    ax.set_axis_off()
    ax.view_init(elev=elev, azim=-62)


def pack_by_height(positions, rotations, shell, box, path):
    """The frozen pack: every body drawn as its own surface probes (``shell`` (M, 3), home
    frame) placed by its rotation (N, 3, 3) and position, coloured by the height of its centre.

    Probes rather than meshes: one scatter of N x M points renders in about a second, where
    the page's per-body marching-cubes meshes cost matplotlib tens of seconds at 48 rings.
    """
    P = np.asarray(positions, float)
    Lx, Lz = box
    with matplotlib.rc_context(_STYLE):
        fig = new_figure((4.2, 4.6))
        ax = fig.add_subplot(1, 1, 1, projection="3d")
        col = _height_colours(P[:, 1])
        _draw_probes(ax, rotations, shell, P, col, (Lx, Lz, P[:, 1].max() + 0.6), elev=16,
                     s=1.2, depthshade=True, linewidths=0)
        ax.set_title("frozen pack (surface probes), coloured by height", fontsize=8)
        return save_png(fig, path)


def orientation_histogram(cos, path, bins=8):
    """Histogram (density) of |cos theta| of the element axes from vertical, with the isotropic
    expectation (uniform density 1)."""
    with matplotlib.rc_context(_STYLE):
        fig = new_figure((3.6, 2.8))
        ax = fig.add_subplot(1, 1, 1)
        ax.hist(np.asarray(cos, float), bins=np.linspace(0, 1, bins + 1), density=True,
                color="#8ea9c4", edgecolor="w")
        ax.axhline(1.0, color="#c44e52", lw=1.4, label="isotropic")
        ax.set_xlabel(r"$|\cos\theta|$ of the ring axis from vertical")
        ax.set_ylabel("density")
        ax.legend(fontsize=8, frameon=False)
        ax.grid(alpha=0.3)
        return save_png(fig, path)


def voidage_sweep(rows, eps, t_over_d, path):
    """Bed voidage 1 - f_env s(t) against wall thickness t/D (``rows`` from
    :func:`~peclet.packing.analysis.geometry.wall_sweep`, error bars eps_err), the measured pack as a
    point, and the published bands."""
    a = np.array([r["t_over_d"] for r in rows])
    e = np.array([r["eps"] for r in rows])
    de = np.array([r["eps_err"] for r in rows])
    with matplotlib.rc_context(_STYLE):
        fig = new_figure((5.0, 3.2))
        ax = fig.add_subplot(1, 1, 1)
        for lbl, (lo, hi, c, tc) in BANDS.items():
            ax.axhspan(lo, hi, color=c, alpha=0.15)
            ax.text(0.10, 0.5 * (lo + hi), lbl, fontsize=7, color=tc, va="center")
        ax.errorbar(a, e, yerr=de, fmt="o-", color="#333333", lw=1.2, ms=4, capsize=2,
                    label=r"$1 - f_{env}\,s(t)$, $f_{env}$ measured, $s$ by quadrature")
        ax.plot([t_over_d], [eps], "o", ms=9, color="#dd8452",
                label=r"this pack (measured $\varepsilon$)")
        ax.set_xlabel("wall thickness $t/D$")
        ax.set_ylabel(r"bed voidage $\varepsilon$")
        ax.legend(fontsize=7, frameon=False, loc="upper center", bbox_to_anchor=(0.5, -0.2),
                  ncol=2)
        ax.grid(alpha=0.3)
        return save_png(fig, path)


def pour_animation(frames, times, shell, box, path, n_frames=60, fps=14, probes=90):
    """The pour as a GIF: each body drawn as its own shell probes (every k-th of ``shell``,
    about ``probes`` per body), coloured by its starting height. ``frames`` is
    [(positions (N, 3), quaternions (N, 4) x y z w)], ``times`` their times."""
    from matplotlib import animation

    if len(frames) == 0:
        raise ValueError("frames must not be empty")
    Lx, Lz = box
    sel = np.linspace(0, len(frames) - 1, min(n_frames, len(frames))).astype(int)
    probe = np.asarray(shell, float)[::max(1, len(shell) // probes)]
    P0 = np.asarray(frames[0][0], float)
    col = _height_colours(P0[:, 1])
    ymax = max(float(np.asarray(f[0])[:, 1].max()) for f in frames) + 0.8
    with matplotlib.rc_context(_STYLE):
        fig = new_figure((3.4, 4.0))
        ax = fig.add_subplot(111, projection="3d")

        def draw(k):
            ax.clear()
            Pk, Qk = frames[sel[k]]
            R = rotation_matrices(unit_quaternions(Qk, "frames"))
            _draw_probes(ax, R, probe, np.asarray(Pk, float), col, (Lx, Lz, ymax), elev=14,
                         s=0.8, depthshade=False)
            ax.set_title("t = %5.2f" % times[sel[k]], fontsize=8)
            return []

        anim = animation.FuncAnimation(fig, draw, frames=len(sel), blit=False)

        def write(tmp):
            anim.save(tmp, writer=animation.PillowWriter(fps=fps))
        return atomic_write(path, write)
