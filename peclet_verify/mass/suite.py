"""The mass-property certificate of any mass-property engine, ready to import into a test
module::

    from peclet_verify.mass.suite import *  # noqa: F401,F403

with a ``pytest_peclet_make_mass_backend(config)`` hook in ``conftest.py`` (or
``--peclet-mass-backend module:factory``; without either, peclet's quadrature is certified).
See :func:`peclet_verify.mass.properties.mass_properties_certificate`.
"""
import pytest

from .. import registry as REG
from ..suites import capped_search
from . import properties as P
from . import strategies as S

__all__ = ["test_mass_properties_closed_forms"]

#: Examples at most (the profile's count if lower): each asks every declared resolution.
CAP = 5


@pytest.mark.peclet_certify
def test_mass_properties_closed_forms(peclet_certificate, peclet_mass_backend):
    """One-leaf solids (moved, turned, scaled) against the leaf table's closed forms: the
    error falls at the stated order as the resolution rises; every claim bounds the error;
    the declared floor is at most MAX_FLOOR (and is reported, passed or failed)."""
    be = peclet_mass_backend
    res = capped_search(be, lambda engine, r: P.mass_properties_certificate(r, engine),
                        S.closed_form_solids(), REG.title("mass_closed_forms"), CAP)
    res.details["declared_floor"] = P.declared_floor(be)
    peclet_certificate(res)
