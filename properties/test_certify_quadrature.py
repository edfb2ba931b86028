"""Certification of the implicit quadrature against closed forms, with observed order."""
import pytest

from peclet_verify import properties as P
from peclet_verify import strategies as pst

pytestmark = pytest.mark.peclet_certify

CLOSED_FORM_KINDS = ("sphere", "box", "ellipsoid", "hollow_cylinder", "torus", "capsule")


def test_quadrature_convergence(peclet_certificate):
    peclet_certificate(P.search(
        lambda r: P.quadrature_convergence(r),
        pst.leaves(kinds=CLOSED_FORM_KINDS), name="quadrature convergence"))
