"""Certification of the implicit quadrature against closed forms, with observed order.

Split into :data:`~peclet_verify.profiles.SHARDS` shards, each searching its share of the
profile's examples under its own name (so its own seed under a derandomised profile), so that
``pytest -n`` spreads the slowest certificate over the workers. The levels of one example
share their integrated cells (``quadrature_convergence(..., fast=True)``);
tests/test_quadrature_certificate_cache.py holds that path to the straightforward one.
"""
import math

import pytest

from peclet_verify import properties as P
from peclet_verify import registry as REG
from peclet_verify import strategies as pst
from peclet_verify.profiles import SHARDS

pytestmark = pytest.mark.peclet_certify


@pytest.mark.parametrize("shard", range(1, SHARDS + 1))
def test_quadrature_convergence(peclet_certificate, shard):
    share = math.ceil(P.active_settings().max_examples / SHARDS)
    peclet_certificate(P.search(
        lambda r: P.quadrature_convergence(r),
        pst.closed_form_solids(pst.CLOSED_FORM_KINDS),
        name=f"{REG.title('quadrature')} [shard {shard}/{SHARDS}]",
        settings=P.profile_settings(max_examples=share)))

