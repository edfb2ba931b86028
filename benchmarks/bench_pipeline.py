"""Benchmark: the full `peclet pall-ring` command (48 rings, the page's 3700-step protocol).

Runs the command twice, each in a fresh interpreter: the first pays whatever Numba compilation
the on-disk cache does not cover ("cold"; pass --clear-cache to empty peclet's __pycache__
first, i.e. a fresh-machine start), the second runs from a warm cache. Prints a table of the
stage timings and the page's acceptance ranges, and writes benchmarks/results/pipeline.json.

    python benchmarks/bench_pipeline.py [--rings 48] [--steps-scale 1] [--threads 2]
                                        [--clear-cache] [--runs 2]
Targets (issue 6): <= 120 s cold, <= 90 s warm on a 2-core machine.
"""
import argparse
import json
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]

CHECKS = [  # (label, getter, lo, hi) — the ranges for the full-size run
    ("porosity eps (3 windows)", lambda r: [w["eps"] for w in r["pack"]["windows"]], 0.78, 0.82),
    ("f_env", lambda r: [r["pack"]["f_env"]], 0.54, 0.61),
    ("mean coordination", lambda r: [r["pack"]["z_mean"]], 3.3, 4.6),
    ("rattlers", lambda r: [r["pack"]["rattlers"]], 0, 0),
    ("max overlap / wall", lambda r: [r["pack"]["max_overlap_wall"]], 0.0, 0.10),
    ("lowest probe (floor y=0)", lambda r: [r["pack"]["lowest_probe"]], -0.012, 10.0),
]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rings", type=int, default=48)
    ap.add_argument("--steps-scale", type=float, default=1.0)
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--runs", type=int, default=2)
    ap.add_argument("--clear-cache", action="store_true")
    a = ap.parse_args()
    if a.clear_cache:
        for d in (ROOT / "peclet").rglob("__pycache__"):
            shutil.rmtree(d, ignore_errors=True)
    runs = []
    for k in range(a.runs):
        out = tempfile.mkdtemp(prefix="bench-pall-")
        cmd = [sys.executable, "-m", "peclet.cli", "pall-ring", "--out", out, "--rings",
               str(a.rings), "--steps-scale", str(a.steps_scale), "--quiet"]
        if a.threads:
            cmd += ["--threads", str(a.threads)]
        t0 = time.perf_counter()
        # the sweep computed in every run (the results cache off): stage times, not reads
        p = subprocess.run(cmd, capture_output=True, text=True,
                           env=dict(os.environ, PECLET_CACHE_DIR="off"))
        wall = time.perf_counter() - t0
        if p.returncode != 0:
            print(p.stdout, p.stderr, file=sys.stderr)
            raise SystemExit(f"run {k} failed with code {p.returncode}")
        with open(os.path.join(out, "results.json")) as fh:
            res = json.load(fh)
        runs.append(dict(label="cold" if k == 0 else "warm", wall_s=wall,
                         stages=res["timing"], out=out, results=res))
        print(p.stdout)
    print(f"\n{'run':<6}{'wall s':>9}" + "".join(f"{s:>15}" for s in runs[0]["stages"]))
    for r in runs:
        print(f"{r['label']:<6}{r['wall_s']:>9.1f}"
              + "".join(f"{v:>15.2f}" for v in r["stages"].values()))
    res = runs[-1]["results"]
    print("\nacceptance (last run):")
    checks = []
    for lbl, get, lo, hi in CHECKS:
        vals = get(res)
        ok = all(lo <= v <= hi for v in vals)
        checks.append(dict(check=lbl, values=vals, lo=lo, hi=hi, ok=ok))
        print(f"  {lbl:<28} {', '.join(f'{v:.4g}' for v in vals):<28} in [{lo}, {hi}]: "
              f"{'OK' if ok else 'FAIL'}")
    summary = dict(rings=a.rings, steps_scale=a.steps_scale, threads=a.threads,
                   cpu_count=os.cpu_count(),
                   runs=[{k: v for k, v in r.items() if k != "results"} for r in runs],
                   checks=checks, targets=dict(cold_s=120, warm_s=90))
    dst = ROOT / "benchmarks" / "results" / "pipeline.json"
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from _report import write_json

    write_json(dst, summary)
    print(f"\nwrote {dst}")


if __name__ == "__main__":
    main()
