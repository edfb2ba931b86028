"""A foreign engine certified out of process: the upstream ``peclet-geom`` wheel, installed
into its own virtual environment (it ships a ``peclet`` namespace that must not meet ours)."""

import pytest
from hypothesis import HealthCheck, settings

from peclet_verify import properties as P
from peclet_verify import strategies as pst
from peclet_verify.backends import SubprocessBackend, peclet_geom_child_command

S = settings(max_examples=15, derandomize=True, database=None, deadline=None,
             suppress_health_check=list(HealthCheck))
AGREEING = tuple(k for k in pst.BOUNDED_KINDS if k != "superquadric")


@pytest.fixture(scope="module")
def upstream(peclet_geom_python):
    with SubprocessBackend(peclet_geom_child_command(peclet_geom_python),
                           name="peclet-geom") as backend:
        yield backend


def test_distance_agreement_except_superquadric(upstream):
    res = P.search(lambda r: P.distance_agreement(r, None, upstream, n=64),
                   pst.trees(kinds=AGREEING, max_leaves=4), settings=S)
    assert res.status == "passed", res.counterexample


def test_sign_agreement_except_superquadric(upstream):
    res = P.search(lambda r: P.sign_agreement(r, backend=upstream, n=64),
                   pst.trees(kinds=AGREEING, max_leaves=4), settings=S)
    assert res.status == "passed", res.counterexample


def test_equation1_on_trees_our_rule_certifies(upstream):
    res = P.search(lambda r: P.equation1(r, upstream, n=128),
                   pst.trees(certified_only=True, max_leaves=4), settings=S)
    assert res.status == "passed" and res.details["applicable"] > 0, res.counterexample


def test_superquadric_disagreement_is_found_and_shrinks_to_one_leaf(upstream):
    res = P.search(lambda r: P.sign_agreement(r, backend=upstream, n=64),
                   pst.leaves(kinds=("superquadric",)), settings=S)
    assert res.status == "failed", "upstream and reference now agree on superquadrics"
    assert "'superquadric'" in res.counterexample
