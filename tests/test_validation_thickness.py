"""The thickness study's machinery at tiny size (validation/thickness.py runs the full study):
two thicknesses x two seeds of 9 rings, then the table's columns checked for consistency."""
import json
import math

import pytest

from validation import thickness as T

pytestmark = pytest.mark.heavy      # the heavy tier (conftest.py: --tier)

TINY = T.Study(thicknesses=(0.1, 0.12), seeds=(1, 2), count=9, box=3.0, drop=2.0,
               samples=20_000)


@pytest.fixture(scope="module")
def study():
    packs = T.run_packs(TINY, workers=1)
    rows, answer = T.summarize(TINY, packs)
    return packs, rows, answer


def test_every_pack_is_measured(study):
    packs, _, _ = study
    assert [(p["t"], p["seed"]) for p in packs] == [(0.1, 1), (0.1, 2), (0.12, 1), (0.12, 2)]
    for p in packs:
        assert p["complete"] and p["steps"] > 0
        assert p["eps"] + p["solid"] == 1.0                 # measured eps = 1 - solid fraction
        assert 0.0 <= p["double"] <= 1.0 - p["eps"] and p["max_depth"] >= 0.0
        # Eq. 2's f_env is N V_env / V_bed: solid fraction / s
        assert p["f_eq2"] == pytest.approx(p["solid"] / _s(p["t"]), rel=1e-12)
    # the probe count follows the wall (neither is thin enough to need more than 1200)
    assert {p["probes"] for p in packs} == {1200}


def _s(t):
    from peclet.packing.analysis import geometry as analysis

    return analysis.wall_sweep([t], 0.0, make=T.ring, n=32, tol=1e-6)[0]["s"]


def test_columns_are_consistent(study):
    packs, rows, answer = study
    assert [r["t"] for r in rows] == [0.1, 0.12] and all(r["n"] == 2 for r in rows)
    ref = rows[1]
    assert answer["t_ref"] == 0.12
    # at t_ref the prediction IS the measurement (Eq. 2 from its own f_env), per seed
    assert ref["eps_pred"] == pytest.approx(ref["eps"], abs=1e-12)
    assert ref["diff"] == pytest.approx(0.0, abs=1e-12)
    for r in rows:
        assert r["solid"] == pytest.approx(1.0 - r["eps"])
        assert r["eps_pred"] == pytest.approx(1.0 - answer["f_ref"] * r["s"], abs=1e-12)
        assert r["diff"] == pytest.approx(r["eps"] - r["eps_pred"], abs=1e-12)
        assert r["f_env"] == pytest.approx(r["solid"] / r["s"], rel=1e-12)
        assert r["eps_ci"] >= 0 and r["f_env_ci"] >= 0 and math.isfinite(r["diff_ci"])
        assert r["max_depth_over_t"] == pytest.approx(r["max_depth"] / r["t"])
    # a thinner ring has less solid per envelope
    assert rows[0]["s"] < rows[1]["s"]
    # the answer is built from the numbers
    s = answer["sentence"]
    assert s.startswith("No:" if answer["significant"] else "Yes within")
    assert f"{answer['slope']:+.3f}" in s and "p = " in s


def test_table_and_json(study, tmp_path):
    packs, rows, answer = study
    text = T.table(rows, answer)
    head = text.splitlines()[0]
    for c in T.COLUMNS:
        assert c in head
    assert len(text.splitlines()) == 2 + len(rows) and "(ref)" in text
    from peclet.core.files import write_json

    p = write_json(tmp_path / "t.json", dict(rows=rows, answer=answer, packs=packs))
    back = json.loads(open(p).read())
    assert back["answer"]["sentence"] == answer["sentence"]


def test_statistics_helpers():
    m, h, n = T.mean_ci([1.0, 2.0, 3.0])
    assert (m, n) == (2.0, 3) and h == pytest.approx(4.302653 / math.sqrt(3), rel=1e-6)
    d, h, p = T.welch([1.0, 2.0, 3.0], [1.0, 2.0, 3.0])
    assert d == 0.0 and p == pytest.approx(1.0)
    b, bh, bp = T.slope([0.0, 1.0, 2.0, 3.0], [1.0, 3.0, 5.0, 7.0 + 1e-9])
    assert b == pytest.approx(2.0) and bp < 1e-6
