"""The mass-property certificate of any mass-property engine, ready to import into a test
module::

    from peclet_verify.mass_suite import *  # noqa: F401,F403

with a ``pytest_peclet_make_mass_backend(config)`` hook in ``conftest.py`` (or
``--peclet-mass-backend module:factory``; without either, peclet's quadrature is certified).
See :func:`peclet_verify.properties.mass.mass_properties_certificate`.
"""
import pytest

from . import properties as P
from . import registry as REG
from . import strategies as pst

__all__ = ["test_mass_properties_closed_forms"]

#: Examples at most (the profile's count if lower): each asks every declared resolution.
CAP = 5


@pytest.mark.peclet_certify
def test_mass_properties_closed_forms(peclet_certificate, peclet_mass_backend):
    """One-leaf solids (moved, turned, scaled) against the leaf table's closed forms: the
    error falls at the stated order as the resolution rises; every claim bounds the error."""
    be = peclet_mass_backend
    res = P.search(lambda r: P.mass_properties_certificate(r, be), pst.closed_form_solids(),
                   name=REG.title("mass_closed_forms"),
                   settings=P.profile_settings(max_examples=min(
                       P.active_settings().max_examples, CAP)))
    res.details["backend"] = getattr(be, "name", type(be).__name__)
    peclet_certificate(res)
