"""The certification properties catch planted known-bad engines, with a small shrunk
counterexample, and pass their correct twins."""
import numba
import numpy as np
import pytest
from hypothesis import HealthCheck, settings

from peclet_verify import planted
from peclet_verify import search as S
from peclet_verify.dem import buffers as DB
from peclet_verify.dem import properties as DP
from peclet_verify.dem import strategies as DS
from peclet_verify.geometry import backend as GB
from peclet_verify.geometry import properties as GP
from peclet_verify.geometry import strategies as GS
from peclet_verify.mass import properties as MP

FAST = settings(max_examples=30, derandomize=True, database=None, deadline=None,
                suppress_health_check=list(HealthCheck))
SHELL_AND_EXACT = GS.EXACT_KINDS + ("hollow_cylinder_shell",)


def _nodes_in(text):
    return sum(1 for line in text.splitlines() if line.startswith("n") and " = b.add_" in line)


def test_overclaimed_shell_bound_is_caught():
    res = S.search(lambda r: GP.equation1(r, planted.OverclaimingBoundBackend()),
                   GS.trees(kinds=SHELL_AND_EXACT, max_leaves=4), settings=FAST)
    assert res.status == "failed" and res.worst < 0
    assert "hollow_cylinder_shell" in res.counterexample
    assert _nodes_in(res.counterexample) <= 3, res.counterexample


def test_reference_bounds_hold_on_the_same_trees():
    res = S.search(lambda r: GP.equation1(r, GB.ReferenceBackend()),
                   GS.trees(kinds=SHELL_AND_EXACT, max_leaves=4), settings=FAST)
    assert res.status == "passed" and res.details["applicable"] > 0


def test_sign_flip_in_one_leaf_is_caught():
    res = S.search(lambda r: GP.sign_agreement(r, backend=planted.TreeWalkBackend(flip="torus"),
                                              n=32),
                   GS.trees(max_leaves=3), settings=FAST)
    assert res.status == "failed" and res.worst > 0
    assert "'torus'" in res.counterexample
    assert _nodes_in(res.counterexample) <= 3, res.counterexample


def test_tree_walk_without_flip_agrees():
    res = S.search(lambda r: GP.sign_agreement(r, backend=planted.TreeWalkBackend(), n=64),
                   GS.trees(max_leaves=3), settings=settings(FAST, max_examples=10))
    assert res.status == "passed"


KINDS = ("sphere", "box", "ellipsoid", "hollow_cylinder", "torus", "capsule")


def test_biased_cell_quadrature_is_caught():
    res = S.search(lambda r: MP.quadrature_convergence(r, planted.biased_cell_quadrature,
                                                      tols=(1e-3, 1e-4)),
                   GS.leaves(kinds=KINDS), settings=settings(FAST, max_examples=10))
    assert res.status == "failed" and res.worst > 1e-2
    assert _nodes_in(res.counterexample) == 1, res.counterexample


@pytest.mark.parametrize("kind, params", [("torus", (0.8, 0.3)), ("capsule", (0.3, 0.5)),
                                          ("cone", (0.5, 0.2, 0.4))])
def test_closed_forms_match_a_fine_cell_rule(kind, params):
    # the closed forms, moved by a rotation, translation and scale (the cone's com is off its
    # origin), are checked against brute force (2 % at n=48, first order)
    recipe = GS.TreeRecipe(GS.LeafCall(kind, params, GS.Transform(
        (0.1, 0.2, -0.3), (0.0, 0.3826834323650898, 0.0, 0.9238795325112867), 1.3)))
    v0, com0, mom0 = MP.closed_form(recipe)
    b, root = recipe.build()
    c, r, _ = b.node_bound(root)
    v, com, mom = planted.cell_quadrature(b, root, c - r, c + r, 48)
    assert abs(v - v0) / v0 < 0.02
    assert np.linalg.norm(com - com0) < 0.02
    assert np.max(np.abs(mom - mom0)) / mom0.max() < 0.03


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs >= 2 numba threads")
def test_thread_order_dependent_sum_is_caught():
    """Caught, shrunk (the shrink phase on) to a state of at most 3 bodies, printed as a
    runnable snippet that rebuilds the state and fails again."""
    res = S.search(lambda s: DP.determinism(s, planted.thread_order_pour),
                   DS.rigid_states((2, 8)), settings=settings(FAST, max_examples=15),
                   describe=lambda s: s.snippet())
    assert res.status == "failed" and res.worst >= 2
    assert res.details["runs_after_failure"] > 0  # Hypothesis did shrink
    snippet = res.counterexample.split("shrunk input:\n", 1)[1].split("\n\n", 1)[0]
    assert "RigidState(" in snippet and "state = " in snippet
    scope = {}
    exec(snippet, scope)
    state = scope["state"]
    assert isinstance(state, DS.RigidState) and 2 <= state.n <= 3, snippet
    again = DP.determinism(state, planted.thread_order_pour)
    assert again.status == "failed", snippet


def test_rigid_state_snippet_is_exact():
    """repr / snippet of a state rebuild the same bits (so a printed counterexample replays)."""
    q = np.array([[0.1, -0.2, 0.3, 0.9]])
    state = DS.RigidState(np.array([[1 / 3, 0.1 + 0.2, -1e-300]]), q / np.linalg.norm(q),
                           np.array([[np.pi, -0.0, 5e-324]]), np.array([[1e300, 2.0, 3.0]]))
    scope = {}
    exec(state.snippet(), scope)
    for name in ("positions", "quaternions", "velocities", "angular_velocities"):
        assert getattr(scope["state"], name).tobytes() == getattr(state, name).tobytes(), name


def test_deterministic_pour_passes():
    def serial_pour(state):
        pos = np.array(state.positions)
        return [pos + 1e-3 * np.cumsum(state.velocities, axis=0)]
    res = S.search(lambda s: DP.determinism(s, serial_pour), DS.rigid_states(3),
                   settings=settings(FAST, max_examples=5))
    assert res.status == "passed" and res.worst == 1


def test_buffer_never_grown_is_caught_and_grown_one_passes():
    recipe = GS.TreeRecipe(GS.LeafCall("box", (0.5, 0.3, 0.4)))
    q = np.array([[0, 0, 0, 1], [0, 0, 0.38, 0.92], [0.1, 0, 0, 1]], float)
    state = DS.RigidState(np.array([[0, 0, 0], [0.7, 0.1, 0], [0.2, 0.5, 0.1]], float),
                           q / np.linalg.norm(q, axis=1)[:, None], np.zeros((3, 3)),
                           np.zeros((3, 3)))
    bad = DB.buffer_growth(recipe, [1, 2], state, engine="peclet_verify.planted:fixed_buffer_engine")
    assert bad.status == "failed" and "out-of-bounds write" in bad.counterexample
    good = DB.buffer_growth(recipe, [1, 2], state,
                           engine="peclet_verify.planted:growing_buffer_engine")
    assert good.status == "passed" and good.details["reference_pairs"] == 3


# ------------------------------------------------- engines answering what is not a finite phi
# the certificates that ask the engine under certification (properties/test_certify_geometry.py)
BACKEND_CERTIFICATES = {
    "equation1 (reference rule)": lambda r, be: GP.equation1(r, be, claimed_by="reference", n=32),
    "equation1 (backend claims)": lambda r, be: GP.equation1(r, be, claimed_by="backend", n=32),
    "sign agreement": lambda r, be: GP.sign_agreement(r, backend=be, n=32),
    "sign agreement (same solid)": lambda r, be: GP.sign_agreement(
        r, other=r.reframed(GS.Transform()).reframed(GS.Transform()), backend=be, n=32),
    "distance agreement": lambda r, be: GP.distance_agreement(r, None, be, n=32),
}
CERTIFIED_TREE = GS.TreeRecipe(GS.LeafCall("torus", (0.8, 0.3), GS.Transform(
    (0.1, 0.2, -0.3), (0.0, 0.3826834323650898, 0.0, 0.9238795325112867), 1.3)))
SHOWN = {"nan": "non-finite", "inf": "non-finite", "none": "returned None",
         "empty": "shape (0,)", "short": "shape (31,)", "zero": "=0.0",
         "raise": "raised RuntimeError"}


@pytest.mark.parametrize("bad", sorted(planted.BAD_ANSWERS))
def test_every_bad_answer_fails_every_backend_certificate(bad):
    """Each planted unusable answer FAILS each certificate, and the answer is in the text."""
    backend = planted.BadAnswerBackend(bad)
    assert CERTIFIED_TREE.build()[0].node_bound(CERTIFIED_TREE.build()[1])[2]  # Eq. 1 applies
    for label, certify in BACKEND_CERTIFICATES.items():
        res = certify(CERTIFIED_TREE, backend)
        assert res.status == "failed" and not res.passed, (bad, label, res)
        shown = SHOWN[bad] if bad != "zero" or "distance" not in label else "vs 0.0;"
        assert shown in res.counterexample and backend.name in res.counterexample, \
            (label, res.counterexample)
    assert GP.equation1(CERTIFIED_TREE, GB.ReferenceBackend(), n=32).status == "passed"


def test_bad_answers_fail_through_search_with_the_answer_shown():
    res = S.search(lambda r: GP.distance_agreement(r, None, planted.BadAnswerBackend("nan"), n=16),
                   GS.trees(max_leaves=2), settings=settings(FAST, max_examples=3))
    assert res.status == "failed" and res.worst == float("inf")
    assert "nan, nan" in res.counterexample and "shrunk input" in res.counterexample


def test_a_bound_answering_nan_fails_equation1():
    class NanBound(GB.ReferenceBackend):
        name = "nan-bound"

        def bound(self, ni, nr, root):
            return np.zeros(3), float("nan"), True
    res = GP.equation1(CERTIFIED_TREE, NanBound(), n=16)
    assert res.status == "failed" and "radius nan" in res.counterexample


# the NaN engine through the real `pytest --peclet-certify --peclet-backend -n 2` route:
# tests/test_verify_options.py::test_xdist_report_holds_every_certificate
