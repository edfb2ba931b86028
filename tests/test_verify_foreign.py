"""A foreign engine certified out of process: the upstream ``peclet-geom`` wheel, installed
into its own virtual environment (it ships a ``peclet`` namespace that must not meet ours)."""

import pytest
from hypothesis import HealthCheck, settings

from peclet_verify import search as S
from peclet_verify.geometry import properties as GP
from peclet_verify.geometry import strategies as GS
from peclet_verify.geometry.backend import SubprocessBackend, wheel_child_command

FOREIGN = settings(max_examples=15, derandomize=True, database=None, deadline=None,
             suppress_health_check=list(HealthCheck))
AGREEING = tuple(k for k in GS.BOUNDED_KINDS if k != "superquadric")


@pytest.fixture(scope="module")
def upstream(peclet_geom_python):
    with SubprocessBackend(wheel_child_command(peclet_geom_python),
                           name="peclet-geom") as backend:
        yield backend


def test_distance_agreement_except_superquadric(upstream):
    res = S.search(lambda r: GP.distance_agreement(r, None, upstream, n=64),
                   GS.trees(kinds=AGREEING, max_leaves=4), settings=FOREIGN)
    assert res.status == "passed", res.counterexample


def test_sign_agreement_except_superquadric(upstream):
    res = S.search(lambda r: GP.sign_agreement(r, backend=upstream, n=64),
                   GS.trees(kinds=AGREEING, max_leaves=4), settings=FOREIGN)
    assert res.status == "passed", res.counterexample


def test_equation1_on_trees_our_rule_certifies(upstream):
    res = S.search(lambda r: GP.equation1(r, upstream, n=128),
                   GS.trees(certified_only=True, max_leaves=4), settings=FOREIGN)
    assert res.status == "passed" and res.details["applicable"] > 0, res.counterexample


def test_superquadric_disagreement_is_found_and_shrinks_to_one_leaf(upstream):
    res = S.search(lambda r: GP.sign_agreement(r, backend=upstream, n=64),
                   GS.leaves(kinds=("superquadric",)), settings=FOREIGN)
    assert res.status == "failed", "upstream and reference now agree on superquadrics"
    assert "'superquadric'" in res.counterexample
