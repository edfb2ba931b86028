"""``peclet stir``: the stirred column (issue 22, item 4), at a reduced size.

The page's run (22,121 grains, 5 revolutions) is ``benchmarks/bench_stir.py``; here the same
column with grains of radius 1.0 (1,416 grains, the same fill height) runs a fraction of a
revolution.
"""
import math
import os

import meshio
import numba
import numpy as np
import pytest

from peclet.cli import main
from peclet.dem import Simulation
from peclet.packing.experiments.stir import (StirSpec, StirredColumn, TIP_RADIUS, IMPELLER_Y, build_trees,
                                 lacey)

CAP = int(numba.config.NUMBA_NUM_THREADS)


def _small(**kw):
    base = dict(grain_radius=1.0, revolutions=0.25, settle=0.5, frames=3, seed=2)
    base.update(kw)
    return StirSpec(**base).checked()


def test_the_impeller_and_column_have_the_page_dimensions():
    b, column, impeller = build_trees(_small())
    # blade 0 lies along +x at the impeller's height: its tip at radius 16
    on = b.eval_root(impeller, np.array([[TIP_RADIUS - 1e-6, IMPELLER_Y, 0.0],
                                         [TIP_RADIUS + 1e-6, IMPELLER_Y, 0.0]]))
    assert on[0] < 0.0 < on[1]
    # the blade, pitched 45 degrees about x: its thin side (0.35) and its 1.8 side mixed
    half_extent_y = 0.35 * math.cos(math.pi / 4) + 1.8 * math.sin(math.pi / 4)
    y = IMPELLER_Y + half_extent_y
    assert b.eval_root(impeller, np.array([[10.0, y + 1e-6, 0.0]]))[0] > 0.0
    # the column: flat floor at y = 0, wall at radius 20, dome above y = 24
    c = b.eval_root(column, np.array([[0.0, 1e-9, 0.0], [19.999, 5.0, 0.0], [0.0, 43.99, 0.0],
                                      [0.0, -1e-9, 0.0], [20.001, 5.0, 0.0]]))
    assert np.all(c[:3] < 0.0) and np.all(c[3:] > 0.0)


def test_lacey_is_zero_segregated_and_one_random():
    rng = np.random.default_rng(0)
    n = 20000
    r = 20.0 * np.sqrt(rng.uniform(size=n))
    th = rng.uniform(0, 2 * np.pi, n)
    X = np.column_stack([r * np.cos(th), rng.uniform(0, 10, n), r * np.sin(th)])
    upper = (X[:, 1] >= 5.0).astype(np.int8)          # the slab boundary at 5 of [0, 10]
    assert lacey(X, upper, 20.0, 10.0) == pytest.approx(0.0, abs=1e-12)
    mixed = rng.integers(0, 2, n).astype(np.int8)
    assert lacey(X, mixed, 20.0, 10.0) == pytest.approx(1.0, abs=0.1)
    assert math.isnan(lacey(X, np.zeros(n, np.int8), 20.0, 10.0))


def test_a_reduced_stir_mixes_keeps_every_grain_and_writes_its_series(tmp_path, capsys):
    out = tmp_path / "stir"
    rc = main(["stir", "--grain-radius", "1.0", "--revolutions", "0.25", "--settle", "0.5",
               "--frames", "3", "--seed", "2", "--out", str(out), "--quiet"])
    assert rc == 0
    table = capsys.readouterr().out
    assert "Lacey index" in table
    import json
    res = json.loads((out / "results.json").read_text())
    assert res["grains"] == 1416
    assert res["escaped_max"] == 0
    assert res["min_wall_sdf"] > 0.0
    # a quarter turn already mixes: the index rises well above its segregated start
    assert res["lacey_start"] < 0.2 and res["lacey_end"] > res["lacey_start"] + 0.1
    assert 0.0 < res["peak_speed_over_tip"] < 3.0
    for f in ("lacey.png", "snapshot.png", "stir.pvd"):
        assert (out / f).stat().st_size > 0
    pvd = (out / "stir.pvd").read_text()
    frames = sorted((out / "frames").glob("frame_*.vtu"))
    assert len(frames) == pvd.count("<DataSet") >= 3
    m = meshio.read(frames[-1])
    assert len(m.cells_dict["vertex"]) == 1416
    assert set(m.point_data) >= {"velocity", "species", "radius"}


def _run(spec, steps, threads, save_at=None, path=None):
    numba.set_num_threads(threads)
    try:
        col = StirredColumn(spec)
        sim = col.build()
        for _ in range(100):
            sim.step()
        col.turn(spec.omega)
        if save_at is None:
            for _ in range(steps):
                sim.step()
            return sim
        for _ in range(save_at):
            sim.step()
        sim.save(path)
        sim = Simulation.load(path)
        for _ in range(steps - save_at):
            sim.step()
        return sim
    finally:
        numba.set_num_threads(CAP)


@pytest.mark.skipif(CAP < 2, reason="needs 2 numba threads")
def test_a_stir_run_is_the_same_at_one_and_two_threads():
    spec = _small()
    a = _run(spec, 150, 1)
    b = _run(spec, 150, 2)
    assert a.state_hash() == b.state_hash()
    assert np.array_equal(a.get_wall_transform(1)[1], b.get_wall_transform(1)[1])


def test_a_stir_saved_and_resumed_mid_rotation_equals_the_uninterrupted_run(tmp_path):
    spec = _small()
    ref = _run(spec, 150, 1)
    res = _run(spec, 150, 1, save_at=61, path=str(tmp_path / "mid.npz"))
    assert ref.state_hash() == res.state_hash()
    q = ref.get_wall_transform(1)[1]
    assert np.array_equal(q, res.get_wall_transform(1)[1])
    # the impeller turned about y by omega t
    assert 2.0 * math.atan2(q[1], q[3]) == pytest.approx(spec.omega * 150 * spec.dt, rel=1e-9)


def _same_results(a, b):
    import json

    strip = lambda r: json.dumps({k: v for k, v in r.items()  # noqa: E731
                                  if k not in ("seconds", "ms_per_step", "files")},
                                 sort_keys=True)
    assert strip(a) == strip(b)


def test_a_stir_run_stopped_and_resumed_through_its_checkpoint_is_bit_for_bit(tmp_path,
                                                                               capsys):
    """run_stir's checkpoints (peclet.packing.bed.checkpoint, the format pack runs and the
    drum use): stopped at the settle's end, then mid-rotation, then finished by
    ``peclet stir --resume``, the run's results, frames and state hash are the uninterrupted
    run's; an option given with --resume must have the run's value."""
    import json

    from peclet.packing.experiments.stir import resume_stir, run_stir

    spec = _small()
    ref_out = tmp_path / "ref"
    ref = run_stir(spec, out=str(ref_out), progress=False, figures=False)
    out = tmp_path / "run"
    a = run_stir(spec, out=str(out), progress=False, figures=False, checkpoint_every=100,
                 max_steps=250)
    assert a == dict(complete=False, steps_done=250, checkpoint=str(out / "checkpoint"))
    assert sorted(os.listdir(out / "checkpoint")) == ["checkpoint.json", "ckpt-000000250",
                                                      "spec.json"]
    b = resume_stir(str(out), progress=False, figures=False, max_steps=431)
    assert b["steps_done"] == 431
    state = json.loads((out / "checkpoint" / "ckpt-000000431" / "state.json").read_text())
    assert state["k"] == 431 and state["angle"] > 0.0          # mid-rotation
    rc = main(["stir", "--resume", str(out), "--quiet", "--seed", "3"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and err[0].startswith(
        "peclet stir: error: --seed must be the resumed run's 2"), err
    rc = main(["stir", "--resume", str(out), "--quiet", "--no-figures", "--grain-radius",
               "1.0"])
    assert rc == 0, capsys.readouterr().err
    res = json.loads((out / "results.json").read_text())
    assert res["state_hash"] == ref["state_hash"]
    _same_results(res, json.loads((ref_out / "results.json").read_text()))
    fa = sorted((out / "frames").glob("frame_*.vtu"))
    fb = sorted((ref_out / "frames").glob("frame_*.vtu"))
    assert [f.name for f in fa] == [f.name for f in fb] and len(fa) == 4   # settled + 3
    for x, y in zip(fa, fb):
        mx, my = meshio.read(x), meshio.read(y)
        assert np.array_equal(mx.points, my.points)
        assert np.array_equal(mx.point_data["velocity"], my.point_data["velocity"])
        assert np.array_equal(mx.point_data["species"], my.point_data["species"])
    assert (out / "stir.pvd").read_text() == (ref_out / "stir.pvd").read_text()
    assert not (out / "checkpoint").exists()


CASES = [
    (["--grain-radius", "0"], "--grain-radius", "[0.05, 2]"),
    (["--grain-radius", "nan"], "--grain-radius", "finite"),
    (["--count", "1.5"], "--count", "an integer"),
    (["--count", "0"], "--count", "[1, 500000]"),
    (["--count", "400000", "--grain-radius", "1"], "--count", "a count the column holds"),
    (["--radius", "10"], "--radius", "[17, 1000]"),
    (["--omega", "-1"], "--omega", "(0, 100]"),
    (["--dt", "0"], "--dt", "(0, 0.02]"),
    (["--restitution", "1.5"], "--restitution", "[0, 1]"),
    (["--mu", "inf"], "--mu", "finite"),
    (["--revolutions", "0"], "--revolutions", "(0, 100]"),
    (["--frames", "-1"], "--frames", "[0, 10000]"),
    (["--threads", "0"], "--threads", "NUMBA_NUM_THREADS"),
]


@pytest.mark.parametrize("argv,flag,phrase", CASES, ids=[" ".join(c[0]) for c in CASES])
def test_bad_input_is_one_line_naming_the_flag(tmp_path, capsys, argv, flag, phrase):
    out = tmp_path / "run"
    rc = main(["stir", "--out", str(out), "--quiet"] + argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    assert len(err) == 1, err
    assert err[0].startswith(f"peclet stir: error: {flag} must"), err
    assert phrase in err[0], err
    assert not out.exists()
