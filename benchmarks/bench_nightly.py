"""CPU per example of the nightly's quadrature certificate, straightforward vs shared levels.

    python benchmarks/bench_nightly.py [--examples N] [--seed S] [--repeats R]
                                       [--replay DIR] [--breakdown]

The examples are those the nightly's quadrature shards search (the same strategy): ``N``
drawn by Hypothesis from a fixed seed (generation only, no database), or with ``--replay DIR``
the ones saved under the shards' keys in an example database (e.g. a nightly's uploaded
``OUT_DIR/hypothesis/examples``). Each example is certified by
:func:`peclet_verify.mass.properties.quadrature_convergence` with ``fast=False`` (every
tolerance level on its own: what the nightly ran before) and ``fast=True`` (the levels share
the box check and the integrated cells), interleaved, ``R`` times each; an example's CPU is
the least of its repeats, measured with ``time.process_time`` (the CPU of every thread of the
process, so other work on a shared machine inflates it less than wall time, though not at
all: cache and memory-bandwidth contention remain). Every example's verdict, figure and
counterexample text is listed for both paths; the run fails (exit 1) if any differs.

``--breakdown`` also times, for the straightforward path, the closed form, the build and bound,
and each tolerance level (with the cells it integrates), and for the shared path what each
level adds: where the time goes.

Output: a table, and ``benchmarks/results/bench_nightly.json``.
"""
from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _report  # noqa: E402

TOLS = (1e-3, 1e-4, 1e-5)
#: Examples the nightly profile gives the quadrature certificate (all shards together).
NIGHTLY_EXAMPLES = 2000


def _strategy():
    from peclet_verify.mass import strategies as MS
    return MS.closed_form_solids(MS.CLOSED_FORM_KINDS)


def draw(n, seed_):
    """``n`` examples of the shards' strategy, drawn by Hypothesis from ``seed_`` (generation
    phase only, no database: the same examples on every run of the same Hypothesis)."""
    from hypothesis import HealthCheck, Phase, given, seed, settings
    out = []

    @seed(seed_)
    @settings(max_examples=n, database=None, deadline=None, phases=[Phase.generate],
              derandomize=False, suppress_health_check=list(HealthCheck))
    @given(_strategy())
    def collect(recipe):
        out.append(recipe)
    collect()
    return out


def replayed(directory):
    """The examples saved in the example database ``directory`` under the keys of the
    quadrature shards (read-only)."""
    from peclet_verify import registry as REG
    from peclet_verify import search as S
    from peclet_verify.profiles import SHARDS, make_settings
    out = []

    def record(recipe):
        out.append(recipe)
        return S.PropertyResult("record", True, status=S.NOT_APPLICABLE)
    settings_ = make_settings("nightly", replay=directory)
    for shard in range(1, SHARDS + 1):
        S.search(record, _strategy(), settings=settings_,
                 name=f"{REG.title('quadrature')} [shard {shard}/{SHARDS}]")
    return out


def _verdict(res):
    return (res.status, res.worst, res.worst_name, res.counterexample,
            repr(sorted(res.details.items())))


def certify(recipe, fast):
    """(CPU seconds, result) of one certificate of ``recipe``."""
    from peclet_verify.mass.properties import quadrature_convergence
    t = time.process_time()
    res = quadrature_convergence(recipe, fast=fast)
    return time.process_time() - t, res


def breakdown(recipe):
    """CPU by step of one example: {"closed form", "build", "ref <tol>", "shared <tol>"} in
    seconds and the cells each level integrates ("cells <tol>"); None without a closed form."""
    from peclet_verify.mass.properties import closed_form
    row = {}
    t = time.process_time()
    exact = closed_form(recipe)
    row["closed form"] = time.process_time() - t
    if exact is None:
        return None
    t = time.process_time()
    b, root = recipe.build()
    c, r, _ = b.node_bound(root)
    lo, hi = c - 1.02 * r, c + 1.02 * r
    row["build"] = time.process_time() - t
    for label, cache in (("ref", None), ("shared", {})):
        for tol in TOLS:
            kw = {} if cache is None else {"cache": cache}
            t = time.process_time()
            p = b.body_properties(root, lo, hi, n=32, tol=tol, **kw)
            row[f"{label} {tol:g}"] = time.process_time() - t
            row[f"cells {tol:g}"] = p.diagnostics["cells"]
    return row


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--examples", type=int, default=60)
    ap.add_argument("--seed", type=int, default=20251124)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--replay", default=None, help="an example database directory")
    ap.add_argument("--breakdown", action="store_true")
    ap.add_argument("--quiet", action="store_true", help="no per-example table")
    a = ap.parse_args(argv)

    examples = replayed(a.replay) if a.replay else draw(a.examples, a.seed)
    source = f"replay of {a.replay}" if a.replay else f"{len(examples)} drawn, seed {a.seed}"
    if not examples:
        print(f"no examples ({source})")
        return 0
    # JIT warm-up (and the closed forms' imports) outside the timings
    for fast in (False, True):
        certify(examples[0], fast)

    rows, differ = [], []
    from tqdm import tqdm
    for i, recipe in enumerate(tqdm(examples, desc="examples", unit="ex", file=sys.stderr)):
        cpu = {False: math.inf, True: math.inf}
        res = {}
        for _ in range(a.repeats):
            for fast in (False, True):
                dt, res[fast] = certify(recipe, fast)
                cpu[fast] = min(cpu[fast], dt)
        same = _verdict(res[False]) == _verdict(res[True])
        if not same:
            differ.append(i)
        row = dict(index=i, kind=recipe.root.kind, status_before=res[False].status,
                   status_after=res[True].status, worst_before=res[False].worst,
                   worst_after=res[True].worst, cpu_before=cpu[False], cpu_after=cpu[True],
                   identical=same)
        if a.breakdown:
            row["breakdown"] = breakdown(recipe)
        rows.append(row)

    if not a.quiet:
        print(_report.table([(r["index"], r["kind"], r["status_before"], r["status_after"],
                              f"{r['worst_before']:.3e}", f"{r['worst_after']:.3e}",
                              f"{r['cpu_before']:.3f}", f"{r['cpu_after']:.3f}",
                              "yes" if r["identical"] else "NO") for r in rows],
                            ["#", "kind", "before", "after", "figure before", "figure after",
                             "CPU s before", "CPU s after", "identical"]))
    before = [r["cpu_before"] for r in rows]
    after = [r["cpu_after"] for r in rows]
    kinds = sorted({r["kind"] for r in rows})
    per_kind = {k: (len([r for r in rows if r["kind"] == k]),
                    statistics.mean(r["cpu_before"] for r in rows if r["kind"] == k),
                    statistics.mean(r["cpu_after"] for r in rows if r["kind"] == k))
                for k in kinds}
    print(f"\n{source}; CPU = least of {a.repeats} repeats (time.process_time), indicative "
          "on a shared machine")
    print(_report.table([(k, n, f"{b:.3f}", f"{f:.3f}", f"{b / f:.2f}")
                         for k, (n, b, f) in per_kind.items()] +
                        [("all", len(rows), f"{statistics.mean(before):.3f}",
                          f"{statistics.mean(after):.3f}",
                          f"{sum(before) / sum(after):.2f}")],
                        ["kind", "examples", "CPU s/ex before", "CPU s/ex after", "ratio"]))
    statuses = {s: sum(r["status_before"] == s for r in rows)
                for s in sorted({r["status_before"] for r in rows})}
    print(f"verdicts before {statuses}; identical (status, figure, text, details) for "
          f"{len(rows) - len(differ)} / {len(rows)}" + (f"; DIFFER: {differ}" if differ else ""))
    print(f"at the nightly's {NIGHTLY_EXAMPLES} examples (mean x {NIGHTLY_EXAMPLES}): "
          f"{statistics.mean(before) * NIGHTLY_EXAMPLES / 60:.1f} CPU-min before, "
          f"{statistics.mean(after) * NIGHTLY_EXAMPLES / 60:.1f} after")
    if a.breakdown:
        steps = [k for k in next(r["breakdown"] for r in rows if r["breakdown"])]
        applicable = [r["breakdown"] for r in rows if r["breakdown"]]
        print("\nwhere the time goes (mean over the examples with a closed form; CPU s, "
              "cells integrated):")
        print(_report.table([(k, f"{statistics.mean(b[k] for b in applicable):.4g}")
                             for k in steps], ["step", "mean"]))
    path = _report.write("bench_nightly", {
        "source": source, "repeats": a.repeats, "tols": TOLS, "rows": rows,
        "mean_cpu_before": statistics.mean(before), "mean_cpu_after": statistics.mean(after),
        "per_kind": per_kind, "differ": differ})
    print(f"wrote {path}")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
