"""Certification of the implicit quadrature against closed forms, with observed order.

Split into :data:`~peclet_verify.profiles.SHARDS` shards, each searching its share of the
profile's examples under its own name (so its own seed under a derandomised profile), so that
``pytest -n`` spreads the slowest certificate over the workers. The levels of one example
share their integrated cells (``quadrature_convergence(..., fast=True)``);
tests/test_quadrature_certificate_cache.py holds that path to the straightforward one.
"""
import math

import pytest

from peclet_verify import registry as REG
from peclet_verify import search as S
from peclet_verify.mass import properties as MP
from peclet_verify.mass import strategies as MS
from peclet_verify.profiles import SHARDS

pytestmark = pytest.mark.peclet_certify


@pytest.mark.parametrize("shard", range(1, SHARDS + 1))
def test_quadrature_convergence(peclet_certificate, shard):
    share = math.ceil(S.active_settings().max_examples / SHARDS)
    peclet_certificate(S.search(
        lambda r: MP.quadrature_convergence(r),
        MS.closed_form_solids(MS.CLOSED_FORM_KINDS),
        name=f"{REG.title('quadrature')} [shard {shard}/{SHARDS}]",
        settings=S.profile_settings(max_examples=share)))

