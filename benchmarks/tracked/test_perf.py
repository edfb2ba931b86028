"""Tracked benchmarks (pytest-benchmark): speed AND accuracy, compared commit against commit.

    python -m pytest benchmarks/tracked --benchmark-only          # one run, a table
    scripts/bench-compare REV_A REV_B [THRESHOLD]                 # fails on a slowdown

Each benchmark warms the JIT in its setup, so the timed rounds measure steady state; cold
compilation is timed on its own (a fresh Numba cache in a subprocess). Accuracy rides along in
``extra_info`` (the ring's quadrature error against its exact volume), so a faster commit that
lost digits shows it in the same table.
"""
import os
import subprocess
import sys
import tempfile

import numpy as np
import pytest

pytestmark = pytest.mark.benchmark(min_rounds=3, warmup=False)


def test_eval_root_pall_ring(benchmark, page_ring):
    b, root = page_ring
    pts = np.random.default_rng(0).uniform(-0.75, 0.75, (500_000, 3))
    b.eval_root(root, pts[:10])                         # JIT warm-up outside the timing
    out = benchmark(b.eval_root, root, pts)
    benchmark.extra_info["points"] = len(pts)
    assert np.isfinite(out).all()


def test_quadrature_pall_ring_tol_1e8(benchmark, page_ring):
    b, root = page_ring
    b.body_properties(root, *page_ring.bounds, n=32, tol=1e-6)        # warm-up
    p = benchmark.pedantic(b.body_properties, args=(root, *page_ring.bounds),
                           kwargs=dict(n=32, tol=1e-8), rounds=3, iterations=1)
    v_exact = _exact_ring_volume(page_ring)
    benchmark.extra_info["volume_rel_error"] = abs(p.volume - v_exact) / v_exact
    benchmark.extra_info["volume_rel_estimate"] = p.volume_error / v_exact
    assert abs(p.volume - v_exact) <= 1e-6 * v_exact


def test_dem_step_settled_page_bed(benchmark, page_particle):
    from peclet.packing.bed.pour import Protocol, pour

    pr = pour(page_particle, n=48, box=3.5, seed=5, protocol=Protocol(), progress=False)
    sim = pr.sim
    sim.step(2e-3)

    def steps():
        for _ in range(20):
            sim.step(2e-3)

    benchmark.pedantic(steps, rounds=3, iterations=1)
    benchmark.extra_info["steps_per_round"] = 20
    benchmark.extra_info["contacts"] = int(sim.num_contacts())


def test_cold_compile_and_first_ring(benchmark):
    """Import, compile every kernel the ring's evaluation needs, evaluate: a fresh Numba cache."""
    code = ("from peclet.packing.bed import elements; import numpy as np; r = elements.pall_ring(); "
            "r.builder.eval_root(r.root, np.zeros((4, 3)))")

    def cold():
        with tempfile.TemporaryDirectory() as d:
            env = dict(os.environ, NUMBA_CACHE_DIR=d)
            subprocess.run([sys.executable, "-c", code], check=True, env=env, timeout=600)

    benchmark.pedantic(cold, rounds=1, iterations=1)


def _exact_ring_volume(ring):
    """The ring's volume from its closed form: tube minus four windows, plus the webs' parts
    inside the bore, computed by the test suite's exact reference (scipy quad)."""
    here = os.path.dirname(os.path.abspath(__file__))
    sys.path.insert(0, os.path.join(here, "..", "..", "tests"))
    from test_quadrature import _pall_ring_exact

    return _pall_ring_exact()[0]
