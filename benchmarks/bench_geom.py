"""Geometry-core throughput: eval_root / eval_root_grad on the Pall ring, and the scene query.

Run: python benchmarks/bench_geom.py   (writes benchmarks/results/geom.json)
Reference: the page's engine evaluates ~1.0 M Pall-ring points/s on this 2-core machine.
Targets: >= 5 M points/s at 2 threads; gradients at no worse than half that rate.
"""
import sys
from pathlib import Path

import numba
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from _report import best_of, table, write  # noqa: E402
import page_steps  # noqa: E402


def main():
    b, ring = page_steps.b, page_steps.ring
    g = np.random.default_rng(0)
    pts = g.uniform(-0.75, 0.75, (2_000_000, 3))
    b.eval_root(ring, pts[:100]), b.eval_root_grad(ring, pts[:100])
    threads = [t for t in (1, 2) if t <= numba.config.NUMBA_NUM_THREADS]
    rows, res = [], {}
    for t in threads:
        numba.set_num_threads(t)
        tv = best_of(lambda: b.eval_root(ring, pts))
        tg = best_of(lambda: b.eval_root_grad(ring, pts))
        res[f"eval_root_mpts_{t}t"] = len(pts) / tv / 1e6
        res[f"eval_root_grad_mpts_{t}t"] = len(pts) / tg / 1e6
        rows.append([f"Pall ring eval_root, {t} thread(s)", f"{len(pts) / tv / 1e6:.2f} M pts/s",
                     f"{len(pts) / tv / 1e6 / 1.0:.1f}x page"])
        rows.append([f"Pall ring eval_root_grad, {t} thread(s)", f"{len(pts) / tg / 1e6:.2f} M pts/s",
                     f"{tv / tg:.2f} of value rate"])

    # scene query: 1000 Pall-ring instances in an 8^3 periodic box, points over the box
    numba.set_num_threads(threads[-1])
    sb = page_steps.geom.SceneBuilder()
    r = page_steps.pall_ring(sb)
    for k in range(1000):
        sb.add_instance(r, translation=g.uniform(0, 8, 3), rotation=g.normal(size=4))
    box, per = (np.zeros(3), np.full(3, 8.0)), (True, False, True)
    q = g.uniform(0, 8, (20_000, 3))
    sb.eval_scene(q[:10], box=box, periodic=per), sb.eval_scene(q[:10], box=box, periodic=per,
                                                                 method="brute")
    tp = best_of(lambda: sb.eval_scene(q, box=box, periodic=per), 3)
    qb = q[:2000]
    tb = best_of(lambda: sb.eval_scene(qb, box=box, periodic=per, method="brute"), 1)
    same = np.array_equal(sb.eval_scene(qb, box=box, periodic=per),
                          sb.eval_scene(qb, box=box, periodic=per, method="brute"))
    rate_p, rate_b = len(q) / tp, len(qb) / tb
    res.update(scene_pruned_pts_per_s=rate_p, scene_brute_pts_per_s=rate_b,
               scene_speedup=rate_p / rate_b, scene_bitwise_equal=bool(same),
               scene_instances=1000, scene_images=9000)
    rows.append([f"scene query, 1000 rings x 9 images, pruned ({threads[-1]}t)",
                 f"{rate_p / 1e3:.1f} k pts/s", f"{rate_p / rate_b:.0f}x brute force"])
    rows.append(["scene query, brute force", f"{rate_b / 1e3:.2f} k pts/s",
                 "bitwise equal" if same else "MISMATCH"])
    print(table(rows, ["measurement", "rate", "ratio"]))
    print("written", write("geom", res))


if __name__ == "__main__":
    main()
