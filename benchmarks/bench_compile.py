"""Where a cold first run's compile time goes: per Numba kernel, how many specialisations.

Runs, in a child process with an empty Numba cache directory, the page's element measurement
and a few DEM steps of a small page pack (``pack("pall_ring", count=8, max_steps=3)``), with
every ``Dispatcher.compile`` timed. Prints, per kernel, its new compilations (one per distinct
signature: a callee is compiled again for every literal value or tuple type a caller passes it)
and their inclusive seconds (a kernel's time includes the kernels it compiles inside it), and for
kernels compiled more than once, the argument positions whose types differ. Writes
benchmarks/results/compile.json.

Run:  python benchmarks/bench_compile.py [--top 25]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _report  # noqa: E402

CHILD = r"""
import json, sys, time, collections
from numba.core.dispatcher import Dispatcher
rows = collections.defaultdict(list)
orig = Dispatcher.compile
def timed(self, sig):
    n0 = len(self.overloads)
    t = time.perf_counter()
    try:
        return orig(self, sig)
    finally:
        if len(self.overloads) > n0:
            f = self.py_func
            rows[f"{f.__module__}.{f.__qualname__}"].append(
                [time.perf_counter() - t, [str(a) for a in sig]])
Dispatcher.compile = timed
t0 = time.perf_counter()
from peclet.packing import pack
pack("pall_ring", "box:3.5", count=8, protocol="page", progress=False, max_steps=3)
json.dump({"total": time.perf_counter() - t0, "rows": rows}, open(sys.argv[1], "w"))
"""


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--top", type=int, default=25)
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "rows.json")
        env = dict(os.environ, NUMBA_CACHE_DIR=os.path.join(tmp, "numba"))
        subprocess.run([sys.executable, "-c", CHILD, out], env=env, check=True)
        data = json.load(open(out))
    kernels = []
    for name, rows in data["rows"].items():
        diff = sorted({i for _, s in rows for i in range(len(s))
                       if len({str(r[1][i]) if i < len(r[1]) else "" for r in rows}) > 1})
        kernels.append(dict(kernel=name, compilations=len(rows),
                            seconds=sum(t for t, _ in rows), differing_args=diff))
    kernels.sort(key=lambda k: -k["seconds"])
    _report.write("compile", dict(total_seconds=data["total"], kernels=kernels))
    print(_report.table([(k["kernel"], k["compilations"], f"{k['seconds']:.1f}",
                          ",".join(map(str, k["differing_args"])) or "-")
                         for k in kernels[:a.top]],
                        ["kernel (inclusive times)", "compiled", "s", "args that differ"]))
    print(f"cold first run of the page's element + 3 DEM steps: {data['total']:.0f} s")


if __name__ == "__main__":
    main()
