"""Shared benchmark output: an atomic JSON file under benchmarks/results and a printed table."""
from __future__ import annotations

import json
import os
import platform
import time
from pathlib import Path

import numba

RESULTS = Path(__file__).resolve().parent / "results"


def machine() -> dict:
    return {"cpus": os.cpu_count(), "numba_threads": numba.config.NUMBA_NUM_THREADS,
            "python": platform.python_version(), "numba": numba.__version__,
            "date": time.strftime("%Y-%m-%d %H:%M:%S")}


def write(name: str, payload: dict) -> Path:
    """Write ``payload`` (plus machine info) to results/<name>.json atomically."""
    return write_json(RESULTS / f"{name}.json", {"machine": machine(), **payload})


def read(name: str) -> dict:
    """results/<name>.json as written by :func:`write`, without its machine info."""
    with open(RESULTS / f"{name}.json") as f:
        d = json.load(f)
    d.pop("machine", None)
    return d


def write_json(path, data) -> Path:
    """``data`` as indented JSON at ``path``, atomically (peclet.core.files.atomic_write)."""
    from peclet.core.files import atomic_write

    def dump(tmp):
        with open(tmp, "w") as f:
            json.dump(data, f, indent=2, default=float)

    atomic_write(path, dump)
    return Path(path)


def table(rows, headers) -> str:
    cols = [headers] + [[str(c) for c in r] for r in rows]
    w = [max(len(r[i]) for r in cols) for i in range(len(headers))]
    line = lambda r: "  ".join(c.rjust(w[i]) if i else c.ljust(w[i]) for i, c in enumerate(r))
    return "\n".join([line(headers), "  ".join("-" * x for x in w)] + [line(r) for r in cols[1:]])


def best_of(fn, repeats=5) -> float:
    """Fastest wall time of ``repeats`` calls (s): the least noisy figure on a shared machine."""
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best
