"""Certification of grid leaves (issue 41): random CSG trees sampled onto grids keep their
source's sign beyond a cell diagonal and Equation 1 for their measured ball; grids of random
meshes (primitives, and meshes of random trees) measure within the band bound of the mesh's
exact mass properties (:mod:`peclet_verify.mass.meshes`)."""
import pytest

from peclet_verify import registry as REG
from peclet_verify import search as S
from peclet_verify.geometry import sampled as GS
from peclet_verify.mass import meshes as MM

pytestmark = pytest.mark.peclet_certify

#: Examples at most of the mass certificate (a quadrature of a grid each, 2-20 s)
MASS_CAP = 8


def test_grid_sign_agreement(peclet_certificate):
    peclet_certificate(S.search(GS.grid_sign, GS.sampled_trees(), name=REG.title("grid_sign")))


def test_grid_equation1(peclet_certificate):
    peclet_certificate(S.search(GS.grid_equation1, GS.sampled_trees(),
                                name=REG.title("grid_equation1")))


def test_grid_mass_against_the_mesh(peclet_certificate):
    cap = min(S.active_settings().max_examples, MASS_CAP)
    peclet_certificate(S.search(MM.grid_mass_certificate, MM.mesh_solids(),
                                name=REG.title("grid_mass"),
                                settings=S.profile_settings(max_examples=cap)))
