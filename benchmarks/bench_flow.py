"""The D3Q19 flow solver (peclet.flow, issue 25): lattice updates per second and memory.

Run: python benchmarks/bench_flow.py   (writes benchmarks/results/flow.json; ~1 min)

A simple cubic sphere array (c = 0.216, L = 48 cells: 94 k fluid nodes) is stepped a fixed
200 steps (after a 20-step warm-up that compiles) at 1 and 2 Numba threads, each in its own
process (NUMBA_NUM_THREADS). MLUPS = fluid node updates per second / 1e6, best of 3. Memory:
FlowResult.memory_bytes, the sizes of the arrays the stepping holds (two population buffers,
the pull table, the wall-rule table, the geometry's per-node and per-link arrays). The bits
of the final field are compared across the thread counts.
"""
import json
import os
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import table, write  # noqa: E402

CHILD = r"""
import hashlib, json, math, time, sys
import numpy as np
from peclet.flow import Grid, build_geometry, solve
L, c = 48, 0.216
a = L * (3 * c / (4 * math.pi)) ** (1 / 3)
def phi(p):
    d = p - 0.5 * (L - 1)
    d -= L * np.round(d / L)
    return np.sqrt((d * d).sum(1)) - a
geo = build_geometry(Grid((0., 0., 0.), 1.0, (L, L, L), (True, True, True)), phi)
solve(geo, [1e-6, 0, 0], tol=1e-30, max_steps=20, check_every=10)
best = None
for _ in range(3):
    r = solve(geo, [1e-6, 0, 0], tol=1e-30, max_steps=200, check_every=100)
    best = r if best is None or r.seconds < best.seconds else best
n = geo.n_fluid
k = len(geo.link_q)
mem = best.memory_bytes
print(json.dumps({"fluid_nodes": n, "cut_links": k, "mlups": best.mlups,
                  "seconds": best.seconds, "bytes": mem, "bytes_per_node": mem / n,
                  "hash": hashlib.sha256(best.u.tobytes()).hexdigest()[:16]}))
"""


def main():
    rows, out = [], {}
    for t in ("1", "2"):
        env = dict(os.environ, NUMBA_NUM_THREADS=t)
        p = subprocess.run([sys.executable, "-c", CHILD], env=env, capture_output=True,
                           text=True, check=True)
        r = json.loads(p.stdout.strip().splitlines()[-1])
        out[f"threads_{t}"] = r
        rows.append([t, r["fluid_nodes"], f"{r['mlups']:.2f}", f"{r['seconds']:.2f}",
                     f"{r['bytes'] / 2**20:.1f}", f"{r['bytes_per_node']:.0f}", r["hash"]])
    out["same_bits"] = out["threads_1"]["hash"] == out["threads_2"]["hash"]
    print(table(rows, ["threads", "fluid nodes", "MLUPS", "s / 200 steps", "MiB",
                       "B / node", "u hash"]))
    print(f"same bits at 1 and 2 threads: {out['same_bits']}")
    write("flow", out)


if __name__ == "__main__":
    main()
