"""A drum run's outputs: results.json, the ParaView time series of its frames and its figures
(the snapshots and the dynamic angle), from the samples and frames :mod:`.drum` records."""
from __future__ import annotations

import math
import os

import numpy as np

from peclet.core.files import write_json
from peclet.core.outputs import clear_outputs

from .regimes import G, measure
from .series import grains_mesh, write_series


def write_outputs(out, res, drum, frames, snaps, samples, figures, previous):
    """Write a drum run's outputs into ``out`` (results.json, the ParaView series, the
    snapshot and angle figures), the earlier run's ``previous`` removed first."""
    os.makedirs(out, exist_ok=True)
    clear_outputs(out, previous)
    files = ["results.json"]
    if frames:
        _write_series(out, drum, frames)
        files += ["drum.pvd", "frames/"]
    if figures:
        _snapshot_figure(os.path.join(out, "snapshots.png"), drum, snaps, res)
        _angle_figure(os.path.join(out, "angle.png"), samples, res)
        files += ["snapshots.png", "angle.png"]
    res["files"] = files
    write_json(os.path.join(out, "results.json"), res)


def _write_series(out, drum, frames):
    R = drum.spec.radius * drum.d
    L = drum.spec.length * drum.d
    om = drum.omega

    def mesh_of(f):
        X, V = f["X"], f["V"]
        vr = V - om * np.column_stack([-X[:, 1], X[:, 0], np.zeros(len(X))])
        th = np.linspace(0, 2 * np.pi, 65)[:-1] + f["turned"]
        rims = [np.column_stack([R * np.cos(th), R * np.sin(th), np.full(64, z)])
                for z in (-0.5 * L, 0.5 * L)]
        return grains_mesh(X, {"radius": drum.radii, "velocity": V,
                               "speed": np.sqrt((V * V).sum(1)),
                               "relative_speed": np.sqrt((vr * vr).sum(1)),
                               "shape_id": np.asarray(f["shape"], np.int32)}, rims)

    write_series(out, "drum", frames, mesh_of)


def _snapshot_figure(path, drum, snaps, res):
    from peclet.core.figures import save_png, subplots
    from matplotlib.collections import PatchCollection
    from matplotlib.patches import Circle

    R = drum.spec.radius * drum.d
    vmax = max(drum.omega * R, 0.5 * math.sqrt(G * drum.d) * drum.d)
    n = max(1, len(snaps))
    fig, axes = subplots(1, n, figsize=(3.2 * n, 3.4), squeeze=False)
    for ax, f in zip(axes[0], snaps):
        X, V = f["X"], f["V"]
        order = np.argsort(X[:, 2])
        sp = np.sqrt((V * V).sum(1))[order]
        pc = PatchCollection([Circle((x, y), r) for (x, y), r in
                              zip(X[order, :2], drum.radii[order])], cmap="viridis")
        pc.set_array(sp)
        pc.set_clim(0, vmax)
        ax.add_collection(pc)
        ax.add_patch(Circle((0, 0), R, fill=False, lw=1.2, color="k"))
        a = f["turned"]
        ax.plot([0, R * math.cos(a)], [0, R * math.sin(a)], "k:", lw=0.6)
        s = measure(X, V, drum.radii, R, drum.omega, drum.d)
        if np.isfinite(s["slope"]):
            xx = np.linspace(-R, R, 2)
            ax.plot(xx, s["slope"] * xx + s["intercept"], "r-", lw=1)
        ax.set_xlim(-1.05 * R, 1.05 * R)
        ax.set_ylim(-1.05 * R, 1.05 * R)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        ang = "" if not np.isfinite(s["angle"]) else f", {s['angle']:.1f}°"
        ax.set_title(f"rev {f['turned'] / (2 * math.pi):.2f}{ang}", fontsize=9)
    fig.suptitle(f"{res['element']}, Fr = {res['froude']:.3g}, mu = {drum.spec.mu:g}: "
                 f"{res['regime']}", fontsize=10)
    fig.colorbar(pc, ax=list(axes[0]), shrink=0.8, label="speed (D/time)")
    save_png(fig, path, dpi=110)


def _angle_figure(path, samples, res):
    from peclet.core.figures import save_png, subplots

    fig, ax = subplots(figsize=(6, 3.2))
    for ph, c in (("warmup", "0.6"), ("measure", "C0")):
        s = [x for x in samples if x["phase"] == ph]
        ax.plot([x["revolutions"] for x in s], [x["angle"] for x in s], ".", ms=2, color=c,
                label=ph)
    m = res["angle"]["mean"]
    if np.isfinite(m):
        ax.axhline(m, color="C3", lw=1, label=f"mean {m:.1f}°")
    ax.set_xlabel("revolutions")
    ax.set_ylabel("surface angle (degrees)")
    ax.set_title(f"Fr = {res['froude']:.3g}: {res['regime']}", fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_png(fig, path, dpi=110)
