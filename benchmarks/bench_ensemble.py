"""Benchmark: an ensemble of the page's pack (48 Pall rings, box 3.5 D, seeds 1-16) through
peclet.ensemble's embedded LocalCluster against a serial loop of the same realizations.

The serial loop runs in this process at the machine's full Numba thread count (the best a
single pack can do); the ensemble runs workers x 1 Numba thread = cores. Both wall times
include measuring the element (once per process) and, for the ensemble, starting the cluster.
Every realization's state hash must be equal in the two (determinism across processes and
thread counts). Prints the timings and the summary table (mean, standard error, 95% Student-t
interval of eps, f_env, Z over the seeds); writes benchmarks/results/ensemble.json.

    python benchmarks/bench_ensemble.py [--seeds 1-16] [--steps-scale 1] [--count 48]
                                        [--mc-samples 400000] [--workers W]
Target (issue 15): ensemble / serial wall-time ratio >= 1.7 on 2 cores.
"""
import argparse
import os
import sys
import tempfile
import time

from _report import table, write

from peclet.ensemble import machine_cores, make_specs, parse_seeds, realize, run, summarize


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", default="1-16")
    ap.add_argument("--steps-scale", type=float, default=1.0)
    ap.add_argument("--count", type=int, default=48)
    ap.add_argument("--mc-samples", type=int, default=400_000)
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--serial-threads", type=int, default=None,
                    help="Numba threads of the serial loop (default: all cores)")
    a = ap.parse_args()
    specs = make_specs(parse_seeds(a.seeds), element="pall_ring", container="box:3.5",
                       count=a.count, steps_scale=a.steps_scale, mc_samples=a.mc_samples)
    cores = machine_cores()
    serial_threads = a.serial_threads or cores

    load0 = os.getloadavg()
    t0 = time.perf_counter()
    serial = []
    for k, s in enumerate(specs):
        serial.append(realize(s, threads=serial_threads)[0])
        print(f"serial {k + 1}/{len(specs)}: {time.perf_counter() - t0:.1f} s", file=sys.stderr,
              flush=True)
    t_serial = time.perf_counter() - t0

    with tempfile.TemporaryDirectory(prefix="bench-ensemble-") as out:
        t0 = time.perf_counter()
        rows = run(specs, out, n_workers=a.workers, progress=True)
        t_dask = time.perf_counter() - t0

    load1 = os.getloadavg()
    same = [r["state_hash"] == s["state_hash"] for r, s in zip(rows, serial)]
    pts = summarize(rows)
    p = pts[0]
    ratio = t_serial / t_dask
    print(table([["serial loop", f"{t_serial:.1f}", f"{t_serial / len(specs):.1f}", "1.00"],
                 ["LocalCluster", f"{t_dask:.1f}", f"{t_dask / len(specs):.1f}",
                  f"{ratio:.2f}"]],
                ["run", "wall s", "s / pack", "speed-up"]))
    print(f"\n{len(specs)} realizations, {cores} cores (serial loop at {serial_threads} Numba "
          f"threads, ensemble at 1 per worker; load average {load0[0]:.1f} -> {load1[0]:.1f}); "
          f"state hashes equal to the serial "
          f"run's: {sum(same)}/{len(same)}; target speed-up >= 1.7\n")
    summ = [[name, f"{p[f'{name}_mean']:.4f}", f"{p[f'{name}_se']:.4f}",
             f"[{p[f'{name}_ci_lo']:.4f}, {p[f'{name}_ci_hi']:.4f}]",
             f"{min(r[f] for r in rows):.4f} .. {max(r[f] for r in rows):.4f}"]
            for f, name in (("eps", "eps"), ("f_env", "f_env"), ("z_mean", "Z"))]
    print(table(summ, ["figure", "mean", "std error", "95% interval (t)", "range"]))
    # the default comparison (the serial loop at every core) keeps the name; another
    # serial thread count is a separate record
    name = "ensemble" if serial_threads == cores else f"ensemble_serial{serial_threads}"
    path = write(name, dict(
        seeds=a.seeds, count=a.count, steps_scale=a.steps_scale, mc_samples=a.mc_samples,
        cores=cores, serial_threads=serial_threads, serial_s=t_serial, ensemble_s=t_dask,
        speedup=ratio, load_average=[load0[0], load1[0]], hashes_equal=int(sum(same)),
        realizations=len(specs), summary=p,
        rows=[{k: r[k] for k in ("seed", "state_hash", "eps", "f_env", "z_mean")}
              for r in rows]))
    print(f"\nwrote {path}")
    return 0 if all(same) else 1


if __name__ == "__main__":
    sys.exit(main())
