"""The certificates of an engine under certification, ready to import into a test module.

A downstream project certifies its engine with a test module holding one line::

    from peclet_verify.geometry.suite import *  # noqa: F401,F403

and a ``pytest_peclet_make_backend(config)`` hook in its ``conftest.py`` returning the engine
(or ``--peclet-backend module:factory``); then ``pytest --peclet-certify``. Each certificate
searches the active profile's examples (``--peclet-profile``) and compares the engine with the
peclet reference. Names: the registry's ``suite`` scope (:mod:`peclet_verify.registry`).
"""
import pytest

from .. import registry as REG
from ..search import search
from . import properties as P
from . import strategies as pst

__all__ = ["test_equation1_reference_rule", "test_equation1_backend_claims",
           "test_sign_agreement_all_paths", "test_sign_agreement_same_solid",
           "test_distance_agreement_backend"]

TREES = dict(max_leaves=6)


@pytest.mark.peclet_certify
def test_equation1_reference_rule(peclet_certificate, peclet_backend):
    """Equation 1 on every tree the reference rule certifies, with the backend's phi."""
    peclet_certificate(search(
        lambda r: P.equation1(r, peclet_backend, claimed_by="reference"),
        pst.trees(certified_only=True, **TREES), name=REG.title("equation1_reference")))


@pytest.mark.peclet_certify
def test_equation1_backend_claims(peclet_certificate, peclet_backend):
    """Equation 1 on every tree the backend itself claims certified (its own bound())."""
    peclet_certificate(search(
        lambda r: P.equation1(r, peclet_backend, claimed_by="backend"),
        pst.trees(kinds=pst.LIPSCHITZ_KINDS, **TREES), name=REG.title("equation1_backend")))


@pytest.mark.peclet_certify
def test_sign_agreement_all_paths(peclet_certificate, peclet_backend):
    """eval_root vs eval_root_grad vs bake vs scene query vs decode(encode()) vs backend."""
    peclet_certificate(search(
        lambda r: P.sign_agreement(r, backend=peclet_backend),
        pst.trees(**TREES), name=REG.title("sign_paths")))


@pytest.mark.peclet_certify
def test_sign_agreement_same_solid(peclet_certificate, peclet_backend):
    """Two recipes of one solid: reframed there and back; difference vs intersection with the
    complement half-space."""
    peclet_certificate(search(
        lambda pair: P.sign_agreement(pair[0], other=pair[1], backend=peclet_backend),
        pst.same_solid_pairs(max_leaves=4), name=REG.title("sign_same_solid"),
        describe=lambda pair: f"{pair[0]!r}\n# ---- other recipe ----\n{pair[1]!r}"))


@pytest.mark.peclet_certify
def test_distance_agreement_backend(peclet_certificate, peclet_backend):
    """The backend's phi equals the reference's (rtol 1e-9)."""
    peclet_certificate(search(
        lambda r: P.distance_agreement(r, None, peclet_backend),
        pst.trees(**TREES), name=REG.title("distance_backend")))
