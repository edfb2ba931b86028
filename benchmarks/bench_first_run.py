"""A new user's first minutes: clone, install into a fresh venv, run the main job cold and warm.

Clones this repository (its committed HEAD) into a temporary directory, creates a fresh venv
(with the system site packages, so that the dependencies already on this machine are not
downloaded again: what is timed is our install, compilation and run, not the network), installs
the clone into it with the README's command, and with an empty ``NUMBA_CACHE_DIR`` times

1. ``peclet pall-ring --out R1``   (cold: every kernel compiles, an empty results cache),
2. ``peclet pall-ring --out R2``   (warm: the kernels from Numba's cache, Step 6's sweep from
   the results cache that run 1 filled, :mod:`peclet.core.results_cache`),
3. the same with ``PECLET_CACHE_DIR=off`` (warm kernels, the sweep computed again),
4. optionally (``--tests``) the README's test command (the fast tier), cold (its own empty
   Numba cache; the suite keeps its own results cache).

Targets (issue 27, 2 cores): cold main job <= 60 s, warm no slower than before, cold tests
<= 4 min. Writes benchmarks/results/first_run.json and prints a table. Run on a quiet machine:
every figure is a wall time.

Run:  python benchmarks/bench_first_run.py [--tests]
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _report  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def timed(cmd, cwd, env):
    t = time.perf_counter()
    r = subprocess.run(cmd, cwd=cwd, env=env, shell=True, stdout=subprocess.PIPE,
                       stderr=subprocess.STDOUT, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"{cmd} failed ({r.returncode}):\n{r.stdout[-3000:]}")
    return time.perf_counter() - t, r.stdout


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tests", action="store_true", help="also time the test command cold")
    a = ap.parse_args(argv)
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        clone = os.path.join(tmp, "peclet")
        subprocess.run(["git", "clone", "-q", ROOT, clone], check=True)
        venv = os.path.join(tmp, "venv")
        subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", venv],
                       check=True)
        env = dict(os.environ, PATH=os.path.join(venv, "bin") + os.pathsep + os.environ["PATH"],
                   NUMBA_CACHE_DIR=os.path.join(tmp, "numba"),
                   PECLET_CACHE_DIR=os.path.join(tmp, "results"))
        env.pop("PYTHONPATH", None)
        rows["install"], _ = timed("pip install -q -e .", clone, env)
        rows["pall_ring_cold"], out = timed("peclet pall-ring --out R1 --quiet", clone, env)
        rows["pall_ring_warm"], _ = timed("peclet pall-ring --out R2 --quiet", clone, env)
        rows["pall_ring_warm_no_results_cache"], _ = timed(
            "peclet pall-ring --out R3 --quiet", clone, dict(env, PECLET_CACHE_DIR="off"))
        if a.tests:
            env_t = dict(env, NUMBA_CACHE_DIR=os.path.join(tmp, "numba_tests"))
            rows["tests_cold"], _ = timed("pip install -q -e '.[test]' && python -m pytest -n auto "
                                          "-q -x -p no:cacheprovider", clone, env_t)
    _report.write("first_run", dict(seconds=rows, targets=dict(pall_ring_cold=60.0,
                                                                tests_cold=240.0)))
    print(_report.table([(k, f"{v:.0f}") for k, v in rows.items()], ["step", "seconds"]))


if __name__ == "__main__":
    main()
