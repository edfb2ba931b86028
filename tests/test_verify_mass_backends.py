"""The mass-property family of the certifier: peclet's quadrature passes against the closed
forms, the planted overclaiming engine fails (in a real certification run, and only there), a
child-process engine answers like the in-process one."""
import os
import subprocess
import sys

import numpy as np
import pytest

from peclet_verify import planted
from peclet_verify.geometry import strategies as GS
from peclet_verify.mass.backend import (PecletMassBackend, SubprocessMassBackend, check_backend,
                                        child_command, load_backend)
from peclet_verify.mass.properties import closed_form_world, mass_properties_certificate
from peclet_verify.report import load_report

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MASS_FILE = os.path.join(ROOT, "properties", "test_certify_mass.py")
TORUS = GS.TreeRecipe(GS.LeafCall("torus", (0.8, 0.3), GS.Transform(
    (0.1, 0.2, -0.3), (0.0, 0.3826834323650898, 0.0, 0.9238795325112867), 1.3)))
CAPSULE = GS.TreeRecipe(GS.LeafCall("capsule", (0.4, 0.3), GS.Transform(
    (0.3, 0.0, 0.1), (0.2, 0.0, 0.0, 0.9797958971132712), 0.8)))


def test_closed_form_world_moves_the_leaf_table_forms():
    v, com, inertia = closed_form_world(TORUS)
    R, r = 0.8, 0.3
    assert abs(v - 2 * np.pi ** 2 * R * r * r * 1.3 ** 3) < 1e-12
    assert np.allclose(com, (0.1, 0.2, -0.3)) and np.allclose(inertia, inertia.T)


@pytest.mark.parametrize("recipe", [TORUS, CAPSULE], ids=["torus", "capsule"])
def test_peclet_quadrature_passes_and_the_overclaim_fails(recipe):
    good = mass_properties_certificate(recipe, PecletMassBackend())
    assert good.status == "passed", good.counterexample
    bad = mass_properties_certificate(recipe, planted.OverclaimingVolumeMassBackend())
    assert bad.status == "failed" and bad.worst > 1e3
    assert "CLAIM VIOLATED" in bad.counterexample


def test_an_engine_that_does_not_converge_at_its_stated_order_fails():
    class Stuck(PecletMassBackend):
        name = "stuck at 1e-5"

        def mass_properties(self, *a):
            v, com, inertia, _ = super().mass_properties(*a)
            return v * (1 + 1e-5), com, inertia        # claims nothing
    res = mass_properties_certificate(TORUS, Stuck())
    assert res.status == "failed" and "allowed" in res.counterexample


def test_unusable_answers_fail_with_the_answer_shown():
    class Nan(PecletMassBackend):
        name = "nan-mass"

        def mass_properties(self, *a):
            return float("nan"), np.zeros(3), np.eye(3)
    res = mass_properties_certificate(TORUS, Nan())
    assert res.status == "failed" and "non-finite" in res.counterexample


def test_child_process_mass_backend_answers_like_the_in_process_one():
    be = SubprocessMassBackend(child_command(), timeout=300)
    try:
        assert be.resolutions == PecletMassBackend.resolutions and be.order == 1.0
        b, root = TORUS.build()
        ni, nr, _, _ = b.encode()
        c, r, _ = b.node_bound(root)
        args = (ni, nr, root, c - 1.02 * r, c + 1.02 * r, 1e-3)
        there, here = be.mass_properties(*args), PecletMassBackend().mass_properties(*args)
        assert there[0] == here[0] and np.array_equal(there[2], here[2])
        assert there[3] == here[3]
    finally:
        be.close()


def test_check_and_load_name_what_is_missing():
    with pytest.raises(ValueError, match="must declare resolutions"):
        check_backend(type("E", (), {"mass_properties": lambda *a: None,
                                          "resolutions": (1e-3,), "order": 1.0})())
    with pytest.raises(ValueError, match="convergence order"):
        check_backend(type("E", (), {"mass_properties": lambda *a: None,
                                          "resolutions": (1e-3, 1e-4), "order": None})())
    assert isinstance(load_backend("reference"), PecletMassBackend)
    with pytest.raises(ValueError, match="--peclet-mass-backend 'peclet_verify.planted:"
                                         "nondeterministic_dem_backend'.*has none"):
        load_backend("peclet_verify.planted:nondeterministic_dem_backend")


@pytest.mark.heavy
def test_planted_mass_engine_fails_exactly_the_mass_certificate(tmp_path):
    report = tmp_path / "r.json"
    done = subprocess.run([sys.executable, "-m", "pytest", MASS_FILE, "--peclet-certify",
                           "--peclet-profile", "smoke", "--peclet-mass-backend",
                           "peclet_verify.planted:overclaiming_mass_backend",
                           "--peclet-report", str(report), "-p", "no:cacheprovider", "-q"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=600)
    verdicts = {c["name"]: c["status"] for c in load_report(report)["certificates"]}
    assert verdicts == {"mass properties (closed forms)": "failed"}, done.stdout[-2000:]
    assert "CLAIM VIOLATED" in done.stdout and done.returncode == 1
