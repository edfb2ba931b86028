"""``peclet drum`` (issue 22, item 4): the rotating drum's physics, determinism and bad input.

- A grain glued to the wall (its rotation locked, wall friction 2, Fr = 1e-3) is carried at
  omega R, to 1 %: it cannot roll and does not slip, so it moves as the wall at its contact.
- A drum run (fill, settle, turn) gives the same state hash at 1 and 2 threads, and a run saved
  mid-rotation and loaded goes on bit for bit as the uninterrupted one (wall pose included).
- At Fr = 4 the bed centrifuges (a ring stuck to the wall), measured by the regime criteria.
- Bad input to ``peclet drum``: one line naming the flag, exit code 2, nothing written.
- Checkpoints: a run stopped at a phase boundary and again mid-rotation, or interrupted by
  Ctrl-C in ``peclet drum``, and resumed gives the uninterrupted run's state hash, samples
  and frames; ``--resume`` refuses what is not a drum run, parts of two runs and options
  whose values differ from the run's (one line naming the flag, exit code 2).
"""
import math
import os

import numba
import numpy as np
import pytest

from peclet.cli import main
from peclet.dem import Simulation
from peclet.packing.experiments.drum import Drum, DrumSpec, add_drum_wall, classify, measure, run_drum

CAP = int(numba.config.NUMBA_NUM_THREADS)


def _small(**kw):
    base = dict(radius=4, length=3, ends="caps", fill=0.25, froude=0.1, mu=0.5, wall_mu=1.0,
                revolutions=0.2, warmup=0.0, frames=0, seed=3)
    base.update(kw)
    return DrumSpec(**base).checked()


def test_a_grain_glued_to_the_wall_moves_at_omega_r():
    spec = _small(froude=1e-3, ribs=0, wall_mu=2.0, e=0.0)
    sim = Simulation(1)
    sim.set_gravity(0.0, -9.81, 0.0)
    sim.set_material_params(0.0, 0.0, 0.5)
    w = add_drum_wall(sim, spec, 1.0)
    r, R = 0.5, spec.radius
    sid = sim.add_sphere_shape(r)
    sim.set_positions(np.array([[0.0, -(R - r) + 1e-3, 0.0]]))
    sim.set_shape_ids(np.array([sid], np.int32))
    m = 4.0 / 3.0 * math.pi * r ** 3
    sim.set_inv_mass(np.array([1.0 / m]))
    sim.set_inv_inertia(np.zeros((1, 3)))             # glued: it cannot roll
    sim.set_domain([-R - 2, -R - 2, -2.0], [R + 2, R + 2, 2.0])
    om, dt = spec.omega, 4e-3
    for _ in range(50):
        sim.step(dt)
    sim.set_wall_velocity(w, angular=(0.0, 0.0, om))
    for _ in range(100):                              # friction takes it along (~0.01 time)
        sim.step(dt)
    p0 = sim.get_positions()[0].copy()
    a0 = math.atan2(p0[1], p0[0])
    n = 400
    for _ in range(n):
        sim.step(dt)
    p, v = sim.get_positions()[0], sim.get_velocities()[0]
    rc = math.hypot(p[0], p[1])
    assert rc == pytest.approx(R - r, abs=0.01)        # still on the wall
    # it does not slip and cannot roll: every point of it, the contact point too, moves as
    # the wall there, at omega R (to 1 %), straight along the wall
    assert float(np.linalg.norm(v)) == pytest.approx(om * R, rel=0.01)
    assert abs(float(np.dot(v[:2], p[:2]))) / rc < 1e-3 * om * R
    # so it goes round the axis at omega R / (R - r): the angle it turned, to 1 %
    turned = math.atan2(p[1], p[0]) - a0
    assert turned == pytest.approx(om * R / (R - r) * n * dt, rel=0.01)


def _run(spec, steps, threads, save_at=None, path=None):
    numba.set_num_threads(threads)
    try:
        d = Drum(spec)
        d.build(settle_max=300)
        d.turn(d.omega)
        if save_at is None:
            d.step(steps)
            return d.sim
        d.step(save_at)
        d.sim.save(path)
        sim = Simulation.load(path)
        for _ in range(steps - save_at):
            sim.step(d.dt)
        return sim
    finally:
        numba.set_num_threads(CAP)


@pytest.mark.skipif(CAP < 2, reason="needs 2 numba threads")
def test_a_drum_run_is_the_same_at_one_and_two_threads():
    spec = _small()
    a = _run(spec, 300, 1)
    b = _run(spec, 300, 2)
    assert a.num_particles() > 20
    assert a.state_hash() == b.state_hash()
    ta, qa = a.get_wall_transform(0)
    tb, qb = b.get_wall_transform(0)
    assert np.array_equal(qa, qb) and np.array_equal(ta, tb)


def test_a_drum_saved_and_resumed_mid_rotation_equals_the_uninterrupted_run(tmp_path):
    spec = _small()
    ref = _run(spec, 300, 1)
    res = _run(spec, 300, 1, save_at=137, path=str(tmp_path / "mid.npz"))
    assert ref.state_hash() == res.state_hash()
    assert np.array_equal(ref.get_wall_transform(0)[1], res.get_wall_transform(0)[1])
    # the drum did turn between the save and the end
    q = ref.get_wall_transform(0)[1]
    assert 2.0 * math.atan2(q[2], q[3]) == pytest.approx(spec.omega * 300 * Drum(spec).dt,
                                                        rel=1e-9)


def test_at_froude_four_the_bed_centrifuges(tmp_path):
    spec = _small(radius=5, fill=0.35, froude=4.0, revolutions=0.5, warmup=1.0, frames=3,
                  snapshots=2)
    res = run_drum(spec, out=str(tmp_path / "run"), progress=False)
    assert res["regime"] == "centrifuging", res["criteria"]
    assert "centrifuging" in res["mellmann"]
    names = set(os.listdir(tmp_path / "run"))
    assert {"results.json", "snapshots.png", "angle.png", "drum.pvd", "frames"} <= names
    assert len(os.listdir(tmp_path / "run" / "frames")) == 3


def test_the_regime_criteria_on_made_up_samples():
    base = dict(coverage=0.5, corotating=0.5, airborne=0.0, flowing=0.3, s_shape=0.01,
                high=0.0)
    assert classify([dict(base)] * 4)[0] == "rolling"
    assert classify([dict(base, s_shape=0.08)] * 4)[0] == "cascading"
    assert classify([dict(base, flowing=0.0)] * 2 + [dict(base)] * 2)[0] == "slumping"
    assert classify([dict(base, airborne=0.05)] * 4)[0] == "cataracting"
    assert classify([dict(base, high=0.3, corotating=0.97)] * 4)[0] == "centrifuging"
    assert classify([dict(base, flowing=0.0, corotating=1.0)] * 4)[0] == "slumping"


def test_the_surface_of_a_tilted_bed_gives_its_angle():
    # grains filling a 30-degree-tilted half of a drum of R = 10, in a 3 D slice
    rng = np.random.default_rng(0)
    P = rng.uniform(-10, 10, size=(40000, 3))
    P[:, 2] = rng.uniform(0, 3, len(P))
    t = math.tan(math.radians(30.0))
    keep = (np.hypot(P[:, 0], P[:, 1]) < 9.5) & (P[:, 1] < t * P[:, 0] - 1.0)
    P = P[keep][:3000]
    s = measure(P, np.zeros_like(P), np.full(len(P), 0.02), 10.0, 0.1)
    assert s["angle"] == pytest.approx(30.0, abs=1.5)


CASES = [
    (["--radius", "1"], "--radius", "[3, 200]"),
    (["--radius", "abc"], "--radius", "a number"),
    (["--length", "0"], "--length", "[1, 200]"),
    (["--fill", "0"], "--fill", "(0, 0.8]"),
    (["--fill", "0.9"], "--fill", "(0, 0.8]"),
    (["--froude", "0"], "--froude", "(0, 100]"),
    (["--froude", "nan"], "--froude", "finite"),
    (["--froude", "1000"], "--froude", "(0, 100]"),
    (["--mu", "-1"], "--mu", "[0, 10]"),
    (["--restitution", "2"], "--restitution", "[0, 1]"),
    (["--wall-restitution", "-0.1"], "--wall-restitution", "[0, 1]"),
    (["--wall-mu", "nan"], "--wall-mu", "finite"),
    (["--grain-mm", "0", "--rpm", "10"], "--grain-mm", "(0, 10000]"),
    (["--rpm", "1e9"], "--rpm", "(0, 100000]"),
    (["--seed", "1.5"], "--seed", "an integer"),
    (["--ends", "open"], "--ends", "caps"),
    (["--polydispersity", "0.5"], "--polydispersity", "[0, 0.5)"),
    (["--revolutions", "0"], "--revolutions", "(0, 100]"),
    (["--ribs", "-1"], "--ribs", "[0, 720]"),
    (["--threads", "0"], "--threads", "NUMBA_NUM_THREADS"),
    (["--element", "no_such_thing"], "--element", ""),
]


@pytest.mark.parametrize("argv,flag,phrase", CASES, ids=[" ".join(c[0]) for c in CASES])
def test_bad_input_is_one_line_naming_the_flag(tmp_path, capsys, argv, flag, phrase):
    out = tmp_path / "run"
    args = ["drum", "--out", str(out), "--quiet"]
    if "--froude" not in argv and "--rpm" not in argv:
        args += ["--froude", "0.01"]
    rc = main(args + argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    assert len(err) == 1, err
    assert err[0].startswith(f"peclet drum: error: {flag} must"), err
    assert phrase in err[0], err
    assert not out.exists()


def test_rpm_and_froude_together_or_neither_are_refused(tmp_path, capsys):
    out = tmp_path / "run"
    with pytest.raises(SystemExit) as ex:
        main(["drum", "--out", str(out), "--froude", "0.1", "--rpm", "10"])
    assert ex.value.code == 2
    assert main(["drum", "--out", str(out)]) == 2
    assert "--froude must be given, or --rpm" in capsys.readouterr().err
    assert not out.exists()


def test_a_drum_shorter_than_a_grain_is_refused_before_work(tmp_path, capsys):
    out = tmp_path / "run"
    rc = main(["drum", "--out", str(out), "--froude", "0.01", "--length", "1",
               "--polydispersity", "0.4", "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and "--length must be at least a grain's" in err, err
    assert not out.exists()


def test_a_fill_the_drum_cannot_hold_is_refused_before_work(tmp_path, capsys):
    out = tmp_path / "run"
    rc = main(["drum", "--out", str(out), "--froude", "0.01", "--fill", "0.8",
               "--polydispersity", "0.4", "--radius", "3", "--length", "2", "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and "--fill must be" in err, err
    assert not out.exists()


# ---------------------------------------------------------------- checkpoints and --resume
def test_run_phases_from_a_stop_adds_the_same_numbers_as_the_uninterrupted_loop():
    from peclet.packing.experiments.series import Phase, run_phases

    phases = [Phase("a", 0.3, 5), Phase("b", 0.0, 0), Phase("c", 1.7, 4), Phase("d", 0.9, 3)]
    dt = 0.0123

    class World:                     # owns the clock, as a Simulation does
        def __init__(self, time):
            self.time = time

        def step(self):
            self.time += dt

    times = {0: 0.5}                 # the world's time after step k (what a checkpoint saves)

    def trace(start, time):
        log, speed, world = [], [None], World(time)

        def step():
            world.step()
            log.append(("step", speed[0]))
            times.setdefault(sum(1 for e in log if e[0] == "step") + (start or (0,))[0],
                             world.time)

        run_phases(phases, dt, step, lambda om: speed.__setitem__(0, om),
                   lambda: world.time - 0.5, lambda k, t, a, ph: log.append((k, t, a, ph.name)),
                   start=start)
        return log

    full = trace(None, 0.5)
    assert full[1][1] == (0.5 + dt) - 0.5     # the world's time since the phases began
    for stop in range(0, 13):
        k, a = full[2 * stop - 1][::2] if stop else (0, 0.0)
        # from any stop (the world's clock restored), the rest of the run: the same steps at
        # the same speeds and the same clock and angle, bit for bit (floats compared with ==)
        assert trace((k, a), times[k]) == full[2 * stop:], stop
    assert full[-1][0] == 12


#: The small drum the resume tests run: 37 grains, a warm-up of 159 steps then 318 measured
#: (a phase boundary at 159), about 600 settle steps.
RESUME = dict(radius=4, length=3, fill=0.25, froude=0.1, mu=0.5, wall_mu=1.0,
              revolutions=0.1, warmup=0.05, frames=3, snapshots=2, seed=3)
RESUME_ARGV = ["--radius", "4", "--length", "3", "--fill", "0.25", "--froude", "0.1",
               "--mu", "0.5", "--wall-mu", "1.0", "--revolutions", "0.1", "--warmup", "0.05",
               "--frames", "3", "--snapshots", "2", "--seed", "3"]


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The uninterrupted run (no checkpoints) and its output directory."""
    out = tmp_path_factory.mktemp("drum_ref") / "run"
    res = run_drum(DrumSpec(**RESUME), out=str(out), progress=False, figures=False)
    return res, out


def _same_results(a, b):
    import json

    strip = lambda r: json.dumps({k: v for k, v in r.items()  # noqa: E731
                                  if k not in ("seconds", "ms_per_step", "files")},
                                 sort_keys=True)
    assert strip(a) == strip(b)


def _same_frames(a, b):
    import meshio

    fa = sorted((a / "frames").glob("frame_*.vtu"))
    fb = sorted((b / "frames").glob("frame_*.vtu"))
    assert [f.name for f in fa] == [f.name for f in fb] and len(fa) == 3
    for x, y in zip(fa, fb):
        mx, my = meshio.read(x), meshio.read(y)
        assert np.array_equal(mx.points, my.points)
        assert np.array_equal(mx.point_data["velocity"], my.point_data["velocity"])
    assert (a / "drum.pvd").read_text() == (b / "drum.pvd").read_text()


def test_a_drum_stopped_at_a_phase_boundary_and_mid_rotation_resumes_bit_for_bit(reference,
                                                                                  tmp_path):
    import json

    from peclet.packing.experiments.drum import resume_drum

    ref, ref_out = reference
    assert ref["steps"] == 477 and ref["grains"] == 37
    out = tmp_path / "run"
    # stop at the end of the warm-up (a phase boundary), then mid-rotation, then finish
    a = run_drum(DrumSpec(**RESUME), out=str(out), progress=False, figures=False,
                 checkpoint_every=100, max_steps=159)
    assert a == dict(complete=False, steps_done=159, checkpoint=str(out / "checkpoint"))
    assert not (out / "results.json").exists()
    b = resume_drum(str(out), progress=False, figures=False, max_steps=237)
    assert b["complete"] is False and b["steps_done"] == 237
    ptr = json.loads((out / "checkpoint" / "checkpoint.json").read_text())
    state = json.loads((out / "checkpoint" / ptr["latest"] / "state.json").read_text())
    assert ptr["step"] == state["k"] == 237
    # mid-rotation: the drum was turning at the stop, by omega dt a step since the warm-up
    om, dt = DrumSpec(**RESUME).checked().omega, 0.004
    assert state["angle"] == pytest.approx(237 * om * dt, rel=1e-12) and state["angle"] > 0.1
    c = resume_drum(str(out / "checkpoint"), progress=False, figures=False)
    assert c["state_hash"] == ref["state_hash"]
    _same_results(c, ref)
    _same_frames(out, ref_out)
    assert not (out / "checkpoint").exists()          # removed at the end
    saved = json.loads((out / "results.json").read_text())
    assert saved["state_hash"] == ref["state_hash"]


def test_peclet_drum_interrupted_by_ctrl_c_resumes_with_the_uninterrupted_bits(
        reference, tmp_path, capsys, monkeypatch):
    import json

    from peclet.packing.experiments import drum as dr

    ref, ref_out = reference
    out = tmp_path / "run"
    real, calls = dr.Drum.step, [0]

    def step(self, k=1):
        calls[0] += 1
        if calls[0] == 250:                       # Ctrl-C in the 250th turning step
            raise KeyboardInterrupt
        return real(self, k)

    monkeypatch.setattr(dr.Drum, "step", step)
    rc = main(["drum", *RESUME_ARGV, "--out", str(out), "--quiet", "--no-figures",
               "--checkpoint-every", "100"])
    err = capsys.readouterr().err
    assert rc == 130 and "resumes it" in err and "--resume" in err, err
    ptr = json.loads((out / "checkpoint" / "checkpoint.json").read_text())
    assert ptr["step"] == 200                    # the last multiple of 100 before the stop
    assert not (out / "results.json").exists()
    monkeypatch.setattr(dr.Drum, "step", real)
    # a new run into it is refused, pointing at --resume
    assert main(["drum", *RESUME_ARGV, "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "--out must be a new or empty directory" in err and "--resume" in err, err
    # the run's own options may be repeated with --resume (same values)
    rc = main(["drum", "--resume", str(out), "--quiet", "--no-figures", "--froude", "0.1",
               "--seed", "3"])
    assert rc == 0, capsys.readouterr().err
    res = json.loads((out / "results.json").read_text())
    assert res["state_hash"] == ref["state_hash"]
    _same_frames(out, ref_out)
    assert not (out / "checkpoint").exists()


def _to_earlier_drum_format(cdir):
    """Rewrite the checkpoint in ``cdir`` as the drum wrote them before the shared format:
    ``step-<k>/`` whose ``state.json`` holds the hashes, the spec in ``checkpoint.json``, no
    ``spec.json`` or ``run.json``."""
    import json

    ptr = json.loads((cdir / "checkpoint.json").read_text())
    spec = json.loads((cdir / "spec.json").read_text())
    step = cdir / ptr["latest"]
    run = json.loads((step / "run.json").read_text())
    state = json.loads((step / "state.json").read_text())
    name = f"step-{ptr['step']:010d}"
    step.rename(cdir / name)
    (cdir / name / "run.json").unlink()
    state["sha256"] = {f: h for f, h in run["sha256"].items() if f != "state.json"}
    (cdir / name / "state.json").write_text(json.dumps(state))
    (cdir / "spec.json").unlink()
    (cdir / "checkpoint.json").write_text(json.dumps(dict(
        kind=ptr["kind"], run=ptr["run"], latest=name, step=ptr["step"], spec=spec["spec"])))


def test_a_drum_checkpoint_of_the_earlier_format_still_resumes_bit_for_bit(reference,
                                                                           tmp_path):
    """Checkpoints share one format with pack runs (peclet.packing.bed.checkpoint); an
    interrupted run checkpointed in the drum's earlier format still resumes, bit for bit, and
    goes on in the shared format."""
    import json

    from peclet.packing.experiments.drum import resume_drum

    ref, ref_out = reference
    out = tmp_path / "run"
    run_drum(DrumSpec(**RESUME), out=str(out), progress=False, figures=False,
             checkpoint_every=100, max_steps=159)
    cdir = out / "checkpoint"
    assert sorted(os.listdir(cdir)) == ["checkpoint.json", "ckpt-000000159", "spec.json"]
    assert sorted(os.listdir(cdir / "ckpt-000000159")) == ["arrays.npz", "run.json", "sim.npz",
                                                           "state.json"]
    _to_earlier_drum_format(cdir)
    b = resume_drum(str(out), progress=False, figures=False, max_steps=237)
    assert b["steps_done"] == 237
    assert sorted(os.listdir(cdir)) == ["checkpoint.json", "ckpt-000000237", "spec.json"]
    assert "spec" not in json.loads((cdir / "checkpoint.json").read_text())
    _to_earlier_drum_format(cdir)
    c = resume_drum(str(out), progress=False, figures=False)
    assert c["state_hash"] == ref["state_hash"]
    _same_results(c, ref)
    _same_frames(out, ref_out)
    assert not cdir.exists()


@pytest.fixture(scope="module")
def settled_checkpoint(tmp_path_factory):
    """A run stopped right after its settle (the checkpoint of step 0)."""
    out = tmp_path_factory.mktemp("drum_ckpt") / "run"
    r = run_drum(DrumSpec(**RESUME), out=str(out), progress=False, figures=False,
                 checkpoint_every=100, max_steps=0)
    assert r["steps_done"] == 0
    return out


RESUME_CASES = [
    (["--froude", "0.2"], "--froude", "the resumed run's 0.1"),
    (["--mu", "0.7"], "--mu", "the resumed run's 0.5"),
    (["--seed", "4"], "--seed", "the resumed run's 3"),
    (["--rpm", "30"], "--rpm", "(Froude 0.1 at 3 mm)"),
    (["--ends", "periodic"], "--ends", "the resumed run's 'caps'"),
    (["--mu", "-1"], "--mu", "[0, 10]"),                 # checked before it is compared
    (["--checkpoint-every", "-5"], "--checkpoint-every", "[0, 1e+09]"),
]


@pytest.mark.parametrize("argv,flag,phrase", RESUME_CASES,
                         ids=[" ".join(c[0]) for c in RESUME_CASES])
def test_resuming_with_other_parameters_is_one_line_naming_the_flag(settled_checkpoint,
                                                                      capsys, argv, flag,
                                                                      phrase):
    before = sorted(os.listdir(settled_checkpoint / "checkpoint"))
    rc = main(["drum", "--resume", str(settled_checkpoint), "--quiet"] + argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    assert len(err) == 1, err
    assert err[0].startswith(f"peclet drum: error: {flag} must"), err
    assert phrase in err[0], err
    assert sorted(os.listdir(settled_checkpoint / "checkpoint")) == before
    assert not (settled_checkpoint / "results.json").exists()


def _not_a_drum_run(tmp_path, kind):
    import json

    d = tmp_path / kind.replace(" ", "_")
    d.mkdir()
    if kind == "empty":
        return d, "no checkpoint/checkpoint.json in it"
    if kind == "pack checkpoint":
        (d / "checkpoint").mkdir()
        (d / "checkpoint" / "checkpoint.json").write_text(json.dumps(
            dict(kind="peclet pack checkpoint", run="x", latest=None, step=0)))
        return d, "not a drum checkpoint's (kind 'peclet pack checkpoint')"
    if kind == "finished run":
        (d / "results.json").write_text("{}")
        return d, "a finished run"
    if kind == "missing":
        return d / "nope", "it does not exist"
    if kind == "file":
        (d / "f.json").write_text("{}")
        return d / "f.json", "it is a file"
    raise AssertionError(kind)


@pytest.mark.parametrize("kind", ["empty", "pack checkpoint", "finished run", "missing",
                                  "file"])
def test_resuming_what_is_not_a_drum_run_is_one_line(tmp_path, capsys, kind):
    path, phrase = _not_a_drum_run(tmp_path, kind)
    rc = main(["drum", "--resume", str(path), "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    assert len(err) == 1, err
    assert err[0].startswith("peclet drum: error: --resume must be a drum run's output "
                             "directory"), err
    assert phrase in err[0], err


def test_a_checkpoint_assembled_from_two_runs_is_refused(settled_checkpoint, tmp_path, capsys):
    import json
    import shutil

    d = tmp_path / "mixed"
    shutil.copytree(settled_checkpoint, d)
    p = d / "checkpoint" / "checkpoint.json"
    ptr = json.loads(p.read_text())
    p.write_text(json.dumps(dict(ptr, run="0" * 32)))      # another run's pointer
    rc = main(["drum", "--resume", str(d), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and "parts of two runs" in err, err


def test_the_published_protocol_is_the_lethe_drum_in_grain_units():
    """validation/drum.py's published run: R 69 mm, L 185 mm of 5.95 mm grains at 2.198 rad/s
    (Fr = omega^2 R / g), 6000 grains, monodisperse, caps."""
    from validation.drum import LETHE, LETHE_WALLS, PUBLISHED
    from peclet.packing.experiments.drum import grain_count, _grains

    spec = DrumSpec(warmup=0.1, revolutions=0.1, ribs=LETHE_WALLS["smooth"], **LETHE).checked()
    assert spec.radius == pytest.approx(69.0 / 5.95)
    assert spec.length == pytest.approx(185.0 / 5.95)
    assert spec.froude == pytest.approx(2.198 ** 2 * 0.069 / 9.81, rel=1e-12)
    assert spec.froude == pytest.approx(PUBLISHED["froude"], rel=1e-12)
    assert spec.ends == "caps" and spec.polydispersity == 0.0 and spec.ribs == 0
    assert grain_count(spec, _grains(spec)) == 6000
    # g = 9.81 D/time^2 makes the time unit sqrt(D / 1 m) s: omega back in rad/s is 2.198
    assert spec.omega / math.sqrt(0.00595) == pytest.approx(2.198, rel=1e-12)
