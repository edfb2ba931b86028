"""Certification of the geometry engine: Equation 1, sign and distance agreement.

Run with ``pytest --peclet-certify`` (optionally ``--peclet-backend module:factory`` to
certify another engine against the reference).
"""
import pytest

from peclet_verify import properties as P
from peclet_verify import strategies as pst
from peclet_verify.planted import TreeWalkBackend

pytestmark = pytest.mark.peclet_certify

TREES = dict(max_leaves=6)


def test_equation1_reference_rule(peclet_certificate, peclet_backend):
    """Equation 1 on every tree the reference rule certifies, with the backend's phi."""
    peclet_certificate(P.search(
        lambda r: P.equation1(r, peclet_backend, claimed_by="reference"),
        pst.trees(certified_only=True, **TREES), name="equation1 (reference rule)"))


def test_equation1_backend_claims(peclet_certificate, peclet_backend):
    """Equation 1 on every tree the backend itself claims certified (its own bound())."""
    peclet_certificate(P.search(
        lambda r: P.equation1(r, peclet_backend, claimed_by="backend"),
        pst.trees(kinds=pst.LIPSCHITZ_KINDS, **TREES), name="equation1 (backend claims)"))


def test_sign_agreement_all_paths(peclet_certificate, peclet_backend):
    """eval_root vs eval_root_grad vs bake vs scene query vs decode(encode()) vs backend."""
    peclet_certificate(P.search(
        lambda r: P.sign_agreement(r, backend=peclet_backend),
        pst.trees(**TREES), name="sign agreement (evaluation paths)"))


def test_sign_agreement_same_solid(peclet_certificate, peclet_backend):
    """Two recipes of one solid: reframed there and back; difference vs intersection with the
    complement half-space."""
    peclet_certificate(P.search(
        lambda pair: P.sign_agreement(pair[0], other=pair[1], backend=peclet_backend),
        pst.same_solid_pairs(max_leaves=4), name="sign agreement (same solid)",
        describe=lambda pair: f"{pair[0]!r}\n# ---- other recipe ----\n{pair[1]!r}"))


def test_distance_agreement_backend(peclet_certificate, peclet_backend):
    """The backend's phi equals the reference's (rtol 1e-9)."""
    peclet_certificate(P.search(
        lambda r: P.distance_agreement(r, None, peclet_backend),
        pst.trees(**TREES), name="distance agreement (backend vs reference)"))


def test_distance_agreement_tree_walk(peclet_certificate):
    """The flat program equals a node-by-node numpy walk of the same encoding."""
    peclet_certificate(P.search(
        lambda r: P.distance_agreement(r, None, TreeWalkBackend()),
        pst.trees(**TREES), name="distance agreement (program vs tree walk)"))
