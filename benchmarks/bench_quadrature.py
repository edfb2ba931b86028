"""Implicit quadrature: the page's scene_particle.build on the Pall ring, and accuracy per second.

Run: python benchmarks/bench_quadrature.py   (writes benchmarks/results/quadrature.json)
Reference: the page's engine takes 23 s for this build on this 2-core machine, errors ~1e-4.
Errors are against the ring's exact mass properties (tests/test_quadrature._pall_ring_exact)
and the leaves' closed forms (peclet.core.geom.leaves.closed_form_mass_properties).
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
from peclet.core.geom.leaves import closed_form_mass_properties  # noqa: E402
from peclet.dem import scene_particle  # noqa: E402

BOUNDS = ([-0.56] * 3, [0.56] * 3)


def timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def main():
    from test_quadrature import _pall_ring_exact          # the ring by hand (scipy quad)
    b, ring = page_steps.b, page_steps.ring
    v_ex, _, i_ex = _pall_ring_exact()
    rows, res = [], {"ring": [], "ring_exact_volume": v_ex}
    page = dict(bounds=BOUNDS, n=32, shell_resolution=112, target_shell_points=1200)
    _, cold = timed(lambda: scene_particle.build(b, ring, **page))
    sp, warm = timed(lambda: scene_particle.build(b, ring, **page))
    err = abs(sp.volume - v_ex) / v_ex
    res.update(build_cold_s=cold, build_warm_s=warm, build_volume_rel_error=err,
               build_volume_rel_estimate=sp.volume_error / v_ex, shell=sp.spacing)
    rows.append(["scene_particle.build, the page's call (cold / warm)",
                 f"{cold:.1f} s / {warm:.2f} s",
                 f"V rel error {err:.1e} (estimate {sp.volume_error / v_ex:.1e}), "
                 f"{len(sp.shell)} probes, median spacing {sp.spacing['median_spacing']:.4f}"])
    for tol in (1e-6, 1e-7, 1e-8, 1e-9, 1e-10):
        p, dt = timed(lambda: b.body_properties(ring, *BOUNDS, n=32, tol=tol))
        ev = abs(p.volume - v_ex) / v_ex
        ei = float(np.abs(np.sort(np.diag(p.inertia)) - np.sort(i_ex)).max() / i_ex.max())
        res["ring"].append(dict(n=32, tol=tol, volume=p.volume, rel_error=ev,
                                rel_estimate=p.volume_error / v_ex, inertia_rel_error=ei,
                                seconds=dt, cells=p.diagnostics["cells"],
                                digits_per_second=float(-np.log10(max(ev, 1e-16)) / dt)))
        rows.append([f"Pall ring body_properties n=32 tol={tol:g}", f"{dt:.2f} s",
                     f"V rel error {ev:.1e} (estimate {p.volume_error / v_ex:.1e}), "
                     f"inertia {ei:.1e}"])
    q = [0.3, -0.5, 0.2, 0.78]
    shapes = {"sphere": ("sphere", [0.5]), "torus": ("torus", [0.4, 0.12]),
              "box": ("box", [0.3, 0.2, 0.4])}
    for name, (kind, prm) in shapes.items():
        exact = closed_form_mass_properties(kind, prm).volume
        s = geom.SceneBuilder()
        leaf = s.add_leaf(kind, prm, translation=[0.07, -0.05, 0.11], rotation=q)
        res[name] = []
        for tol in (1e-5, 1e-7, 1e-9):
            p, dt = timed(lambda: s.body_properties(leaf, [-0.75] * 3, [0.75] * 3, n=32,
                                                    tol=tol))
            err = abs(p.volume - exact) / exact
            res[name].append(dict(tol=tol, rel_error=err, rel_estimate=p.volume_error / exact,
                                  seconds=dt))
            rows.append([f"{name} (offset, rotated) tol={tol:g}", f"{dt:.2f} s",
                         f"rel error {err:.1e}, estimate {p.volume_error / exact:.1e}"])
    from test_quadrature import _TILTED_TUBE, _TURNED_TUBE, _tube_properties
    for name, tube in (("tube turned about z (grazing lines)", _TURNED_TUBE),
                       ("tube tilted 11 deg (rim outline touching)", _TILTED_TUBE)):
        res[name] = []
        for tol in (1e-3, 1e-5):
            (p, exact), dt = timed(lambda: _tube_properties(tube, tol))
            err = abs(p.volume - exact) / exact
            res[name].append(dict(tol=tol, rel_error=err, rel_estimate=p.volume_error / exact,
                                  seconds=dt))
            rows.append([f"{name} tol={tol:g}", f"{dt:.2f} s",
                         f"rel error {err:.1e}, estimate {p.volume_error / exact:.1e}"])
    print(table(rows, ["measurement", "time", "result"]))
    print("written", write("quadrature", res))


if __name__ == "__main__":
    main()
