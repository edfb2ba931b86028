"""Benchmark: the page's scene_particle.build on the Pall ring (cold and warm), and the
volume error reached per second on a closed-form solid. Writes benchmarks/results/quadrature.json.

Run: python benchmarks/bench_quadrature.py [--ring]   (--ring runs the Pall-ring build; slow)
"""
import json
import os
import sys
import tempfile
import time

import numpy as np

from peclet.core import geom


def _atomic_json(path, obj):
    d = os.path.dirname(path)
    os.makedirs(d, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=d, suffix=".json")
    with os.fdopen(fd, "w") as f:
        json.dump(obj, f, indent=2)
    os.replace(tmp, path)


def sphere_rows():
    rows = []
    b = geom.SceneBuilder()
    s = b.add_leaf("sphere", [0.45], translation=[0.05, -0.1, 0.07])
    V = 4 / 3 * np.pi * 0.45 ** 3
    for tol in (1e-4, 1e-7, 1e-10, 1e-13):
        t = time.perf_counter()
        p = b.body_properties(s, [-0.6] * 3, [0.6] * 3, n=8, tol=tol)
        rows.append({"solid": "sphere", "tol": tol, "seconds": time.perf_counter() - t,
                     "rel_volume_error": abs(p.volume / V - 1),
                     "rel_volume_estimate": p.volume_error / V})
    return rows


R_O, H, T = 0.5, 1.0, 0.12
R_I = R_O - T
NWIN, YWIN = 4, 0.24
WR, WA, WT = 0.16, 0.17, 0.13
WEB = (0.40, 0.06, 0.06)
def qy(a):
    return [0.0, float(np.sin(0.5 * a)), 0.0, float(np.cos(0.5 * a))]
def pall_ring(b, certified=True):
    if certified:
        tube = b.add_leaf("hollow_cylinder", [R_O, H, T])
    else:
        tube = b.add_leaf("hollow_cylinder_shell", [R_O, R_I, H],
                          rotation=[float(np.sin(np.pi / 4)), 0.0, 0.0, float(np.cos(np.pi / 4))])
    wins = []
    for row, ysign in enumerate((+1, -1)):
        for k in range(NWIN):
            phi = 2 * np.pi * k / NWIN + (np.pi / NWIN if row else 0.0)
            wins.append(b.add_leaf("box", [WR, WA, WT],
                                   translation=[R_O * np.cos(phi), ysign * YWIN,
                                                R_O * np.sin(phi)],
                                   rotation=qy(-phi)))
    w = wins[0]
    for x in wins[1:]:
        w = b.add_union(w, x)
    shell = b.add_difference(tube, w)
    return b.add_union(
        b.add_union(shell, b.add_leaf("box", list(WEB), translation=[0.0, +YWIN, 0.0])),
        b.add_leaf("box", list(WEB), translation=[0.0, -YWIN, 0.0], rotation=qy(np.pi / 2)))


def ring_rows():
    from peclet.dem import scene_particle
    rows = []
    for label in ("cold", "warm"):
        b = geom.SceneBuilder()
        ring = pall_ring(b)
        t = time.perf_counter()
        sp = scene_particle.build(b, ring, bounds=([-0.56] * 3, [0.56] * 3), n=32,
                                  shell_resolution=112, target_shell_points=1200)
        rows.append({"run": label, "seconds": time.perf_counter() - t, "volume": sp.volume,
                     "volume_error": sp.volume_error, "principal": sp.principal.tolist(),
                     "com": sp.com.tolist(), **sp.spacing})
    return rows


def main():
    out = {"sphere": sphere_rows()}
    print("%-8s %8s %10s %12s %12s" % ("solid", "tol", "seconds", "rel err", "estimate"))
    for r in out["sphere"]:
        print("%-8s %8.0e %10.3f %12.3e %12.3e" % (r["solid"], r["tol"], r["seconds"],
                                                 r["rel_volume_error"], r["rel_volume_estimate"]))
    if "--ring" in sys.argv:
        out["ring"] = ring_rows()
        for r in out["ring"]:
            print("ring %-5s %8.2f s  V=%.12f  est %.2e  median NN %.4f  p90 %.4f"
                  % (r["run"], r["seconds"], r["volume"], r["volume_error"],
                     r["median_spacing"], r["p90_spacing"]))
    _atomic_json(os.path.join(os.path.dirname(__file__), "results", "quadrature.json"), out)


if __name__ == "__main__":
    main()
