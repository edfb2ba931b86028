"""Certification of the DEM engine: determinism of a pour, contact-buffer growth."""
import pytest
from hypothesis import strategies as st

from peclet_verify import properties as P
from peclet_verify import registry as REG
from peclet_verify import strategies as pst

pytestmark = pytest.mark.peclet_certify


def few():
    """Each example is a pour or a subprocess: a handful is what fits a CI budget."""
    return P.profile_settings(max_examples=min(P.active_settings().max_examples, 5))


def test_determinism_across_threads(peclet_certificate):
    peclet_certificate(P.search(
        lambda s: P.determinism(s), pst.rigid_states((2, 12), box=((0, 0.3, 0), (3, 3, 3))),
        name=REG.title("determinism"), settings=few(),
        describe=lambda s: s.snippet()))


def test_buffer_growth(peclet_certificate):
    peclet_certificate(P.search(
        lambda a: P.buffer_growth(a[0], a[1], a[2]),
        st.tuples(pst.trees(max_leaves=2, certified_only=True, transforms=False),
                  pst.capacity_sequences(max_size=4),
                  pst.rigid_states((2, 5), box=((0, 0, 0), (1.5, 1.5, 1.5)))),
        name=REG.title("buffer_growth"), settings=few(),
        describe=lambda a: f"{a[0]!r}\ncapacities = {a[1]!r}\n{a[2].snippet()}"))
