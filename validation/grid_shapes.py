"""Grid leaves (issue 41) against the analytic sphere, beside Yade's level-set tolerances.

    python -m validation.grid_shapes [--spacings 0.2,0.1,0.05] [--json FILE] [--quick]

Protocol (after Yade's ``checkLSdem``, which checks its level-set grains against analytic
twins at spacing 0.05 of a unit sphere: distance 0.5 %, normal 6 %, volume 0.4 %, area 2.5 %).
A unit sphere as a grid leaf made two ways, at each spacing h:

- ``callable``: the exact distance |p| - 1 sampled (:func:`grids.grid_from_callable`);
- ``mesh``: an icosphere of 20 480 faces (its chordal error 2.9e-4; ``--quick``: 5 120) read
  through an STL file and sampled by libigl with the winding-number sign
  (:func:`grids.grid_from_mesh`).

Measured: *distance*, the largest |phi - (|p| - 1)| over the points of 20 000 in the shell
0.75 < |p| < 1.25 that lie inside the lattice (relative to the radius; outside it the field is
the stated extension, not the interpolant); *normal*, the largest |n - p/|p|| of the unit
gradient there; *volume*, the implicit quadrature of the grid solid (tol 1e-6, one top cell per
lattice cell, or of 2^3 when that would pass the cell budget: :func:`grids.quadrature_layout`)
against 4/3 pi (and, for the mesh, against the mesh's own divergence-theorem
volume); *area*, the marching-cubes area of the grid's zero set at twice the lattice
resolution against 4 pi. Observed orders from successive spacings: log(e1 / e2) / log(h1 / h2).
Prints our figure beside Yade's tolerance; ``--json`` writes every number.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

#: Yade checkLSdem's tolerances at spacing 0.05 of a unit sphere (relative)
YADE = {"distance": 5e-3, "normal": 6e-2, "volume": 4e-3, "area": 2.5e-2}
SHELL = (0.75, 1.25)


def _shell_points(n=20_000, seed=7):
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    return u * rng.uniform(*SHELL, n)[:, None]


def sphere_leaf(builder, source, h, stl_path):
    """The unit sphere as a grid leaf from ``source`` ("callable" or "mesh") at spacing h."""
    from peclet.core.geom import grids
    if source == "callable":
        return grids.grid_from_callable(builder, lambda p: np.linalg.norm(p, axis=1) - 1.0,
                                        [-1.0] * 3, [1.0] * 3, h)
    return grids.grid_from_mesh(builder, stl_path, spacing=h)


def measure(source, h, stl_path):
    """One row: the errors of the grid sphere from ``source`` at spacing ``h`` (module notes)."""
    from peclet.core import geom
    b = geom.SceneBuilder()
    t0 = time.perf_counter()
    g = sphere_leaf(b, source, h, stl_path)
    t_build = time.perf_counter() - t0
    from peclet.core.geom.grids import quadrature_layout
    lo, hi, nq = quadrature_layout(b, g)        # top quadrature cells of whole lattice cells
    dims = b.node(g)[3][1:4].astype(int)
    half = 0.5 * (dims[0] - 1) * h
    p = _shell_points()
    p = p[np.all(np.abs(p) <= half, axis=1)]    # inside the lattice (the interpolant's errors)
    phi, grad = b.eval_root_grad(g, p)
    r = np.linalg.norm(p, axis=1)
    n = grad / np.linalg.norm(grad, axis=1)[:, None]
    t0 = time.perf_counter()
    props = b.body_properties(g, lo, hi, n=nq, tol=1e-6)
    t_quad = time.perf_counter() - t0
    _, _, area = geom.surface_mesh(b, g, lo, hi, int(2 * dims.max() - 1))
    row = dict(source=source, spacing=h, samples=int(np.prod(dims)),
               distance=float(np.abs(phi - (r - 1.0)).max()),
               normal=float(np.linalg.norm(n - p / r[:, None], axis=1).max()),
               volume=float(props.volume / (4.0 / 3.0 * math.pi) - 1.0),
               volume_error_estimate=float(props.volume_error / props.volume),
               area=float(area / (4.0 * math.pi) - 1.0),
               lipschitz_constant=float(b.lipschitz_constant(g)),
               build_s=t_build, quadrature_s=t_quad, quadrature_cells=props.diagnostics["cells"])
    if source == "mesh":
        from peclet.core.geom.grids import mesh_mass_properties
        ref = mesh_mass_properties(stl_path)
        row["volume_vs_mesh"] = float(props.volume / ref.volume - 1.0)
    return row


def orders(rows, key):
    """Observed orders of |key| between successive spacings of one source."""
    out = []
    for a, c in zip(rows, rows[1:]):
        ea, ec = abs(a[key]), abs(c[key])
        out.append(math.log(ea / ec) / math.log(a["spacing"] / c["spacing"])
                   if ea > 0 and ec > 0 else float("nan"))
    return out


def run(spacings, quick=False):
    import trimesh
    with tempfile.TemporaryDirectory() as tmp:
        stl = os.path.join(tmp, "sphere.stl")
        trimesh.creation.icosphere(subdivisions=4 if quick else 5, radius=1.0).export(stl)
        result = {}
        for source in ("callable", "mesh"):
            rows = [measure(source, h, stl) for h in spacings]
            result[source] = dict(rows=rows, **{f"order_{k}": orders(rows, k)
                                                for k in ("distance", "normal", "volume",
                                                          "area")})
    return result


def table(result):
    lines = [f"{'source':9s} {'h':>6s} {'distance':>9s} {'normal':>8s} {'volume':>9s} "
             f"{'area':>9s} {'L':>5s} {'quad s':>7s}"]
    for source, res in result.items():
        for row in res["rows"]:
            lines.append(f"{source:9s} {row['spacing']:6.3f} {row['distance']:9.2e} "
                         f"{row['normal']:8.2e} {row['volume']:+9.2e} {row['area']:+9.2e} "
                         f"{row['lipschitz_constant']:5.2f} {row['quadrature_s']:7.1f}")
        for k in ("distance", "normal", "volume", "area"):
            o = ", ".join(f"{v:.2f}" for v in res[f"order_{k}"])
            lines.append(f"  observed order of {k}: {o}")
    lines.append("Yade checkLSdem at h = 0.05: distance {distance:.1e}, normal {normal:.0e}, "
                 "volume {volume:.1e}, area {area:.1e} (relative)".format(**YADE))
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--spacings", default="0.2,0.1,0.05")
    ap.add_argument("--json", default=None)
    ap.add_argument("--quick", action="store_true", help="spacings 0.2, 0.1; a coarser mesh")
    a = ap.parse_args(argv)
    spacings = [0.2, 0.1] if a.quick else [float(v) for v in a.spacings.split(",")]
    result = run(spacings, quick=a.quick)
    print(table(result))
    if a.json:
        from peclet.core.files import write_json
        write_json(a.json, dict(protocol=__doc__, yade=YADE, **result))
    return result


if __name__ == "__main__":
    main()
