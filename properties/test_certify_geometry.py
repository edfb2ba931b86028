"""Certification of the geometry engine: Equation 1, sign and distance agreement.

Run with ``pytest --peclet-certify`` (optionally ``--peclet-backend module:factory`` to
certify another engine against the reference). The certificates of the engine under
certification are the shipped suite (:mod:`peclet_verify.geometry.suite`, what a downstream project
imports); the tree-walk one certifies peclet's flat program itself.
"""
import pytest

from peclet_verify import registry as REG
from peclet_verify import search as S
from peclet_verify.geometry import properties as GP
from peclet_verify.geometry import strategies as GS
from peclet_verify.geometry.suite import *  # noqa: F401,F403  (the backend certificates)
from peclet_verify.geometry.suite import TREES
from peclet_verify.planted import TreeWalkBackend


@pytest.mark.peclet_certify
def test_distance_agreement_tree_walk(peclet_certificate):
    """The flat program equals a node-by-node numpy walk of the same encoding."""
    peclet_certificate(S.search(
        lambda r: GP.distance_agreement(r, None, TreeWalkBackend()),
        GS.trees(**TREES), name=REG.title("distance_tree_walk")))
