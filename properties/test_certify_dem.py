"""Certification of the DEM engine: determinism of a pour, contact-buffer growth."""
import pytest
from hypothesis import strategies as st

from peclet_verify import registry as REG
from peclet_verify import search as S
from peclet_verify.dem import buffers as DB
from peclet_verify.dem import properties as DP
from peclet_verify.dem import strategies as DS
from peclet_verify.geometry import strategies as GS

pytestmark = pytest.mark.peclet_certify


def few():
    """Each example is a pour or a subprocess: a handful is what fits a CI budget."""
    return S.profile_settings(max_examples=min(S.active_settings().max_examples, 5))


def test_determinism_across_threads(peclet_certificate):
    peclet_certificate(S.search(
        lambda s: DP.determinism(s), DS.rigid_states((2, 12), box=((0, 0.3, 0), (3, 3, 3))),
        name=REG.title("determinism"), settings=few(),
        describe=lambda s: s.snippet()))


def test_buffer_growth(peclet_certificate):
    peclet_certificate(S.search(
        lambda a: DB.buffer_growth(a[0], a[1], a[2]),
        st.tuples(GS.trees(max_leaves=2, certified_only=True, transforms=False),
                  DS.capacity_sequences(max_size=4),
                  DS.rigid_states((2, 5), box=((0, 0, 0), (1.5, 1.5, 1.5)))),
        name=REG.title("buffer_growth"), settings=few(),
        describe=lambda a: f"{a[0]!r}\ncapacities = {a[1]!r}\n{a[2].snippet()}"))
