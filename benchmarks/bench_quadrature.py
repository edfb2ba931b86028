"""Implicit quadrature: the page's scene_particle.build on the Pall ring, and accuracy per second.

Run: python benchmarks/bench_quadrature.py   (writes benchmarks/results/quadrature.json)
Reference: the page's engine takes 23 s for this build on this 2-core machine, errors ~1e-4.
Targets (issue 3): build <= 2 s warm, mass properties within 1e-8 relative.
"""
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from _report import table, write  # noqa: E402
import page_steps  # noqa: E402
from peclet.core import geom  # noqa: E402
from peclet.dem import scene_particle  # noqa: E402

BOUNDS = ([-0.56] * 3, [0.56] * 3)


def timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def main():
    b, ring = page_steps.b, page_steps.ring
    rows, res = [], {"ring": []}
    _, cold = timed(lambda: scene_particle.build(b, ring, bounds=BOUNDS, n=32))
    sp, warm = timed(lambda: scene_particle.build(b, ring, bounds=BOUNDS, n=8))
    res["build_cold_s"], res["build_warm_s"] = cold, warm
    rows.append(["scene_particle.build, Pall ring, n=8 tol=1e-6 (cold / warm)",
                 f"{cold:.1f} s / {warm:.1f} s", f"V={sp.volume:.9f} +- {sp.volume_error:.1e}"])
    for n, tol in ((8, 1e-6), (8, 1e-7), (8, 1e-8), (8, 1e-9)):
        p, dt = timed(lambda: b.body_properties(ring, *BOUNDS, n=n, tol=tol))
        res["ring"].append(dict(n=n, tol=tol, volume=p.volume, volume_error=p.volume_error,
                                principal=p.principal.tolist(), com=p.com.tolist(), seconds=dt,
                                cells=p.diagnostics["cells"]))
        rows.append([f"Pall ring body_properties n={n} tol={tol:g}", f"{dt:.1f} s",
                     f"V={p.volume:.9f} +- {p.volume_error:.1e}, I={np.round(p.principal, 8)}"])
    q = [0.3, -0.5, 0.2, 0.78]
    shapes = {"sphere": ("sphere", [0.5], 4 / 3 * np.pi * 0.125),
              "torus": ("torus", [0.4, 0.12], 2 * np.pi ** 2 * 0.4 * 0.0144),
              "box": ("box", [0.3, 0.2, 0.4], 0.192)}
    for name, (kind, prm, exact) in shapes.items():
        s = geom.SceneBuilder()
        leaf = s.add_leaf(kind, prm, translation=[0.07, -0.05, 0.11], rotation=q)
        res[name] = []
        for tol in (1e-5, 1e-7, 1e-9):
            p, dt = timed(lambda: s.body_properties(leaf, [-0.75] * 3, [0.75] * 3, n=8,
                                                    tol=tol))
            err = abs(p.volume - exact) / exact
            res[name].append(dict(tol=tol, rel_error=err, rel_estimate=p.volume_error / exact,
                                  seconds=dt))
            rows.append([f"{name} (offset, rotated) tol={tol:g}", f"{dt:.2f} s",
                         f"rel error {err:.1e}, estimate {p.volume_error / exact:.1e}"])
    print(table(rows, ["measurement", "time", "result"]))
    print("written", write("quadrature", res))


if __name__ == "__main__":
    main()
