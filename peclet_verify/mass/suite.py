"""The mass-property certificate of any mass-property engine, ready to import into a test
module::

    from peclet_verify.mass.suite import *  # noqa: F401,F403

with a ``pytest_peclet_make_mass_backend(config)`` hook in ``conftest.py`` (or
``--peclet-mass-backend module:factory``; without either, peclet's quadrature is certified).
See :func:`peclet_verify.mass.properties.mass_properties_certificate`.
"""
from ..suites import certificate_test
from . import properties as P
from . import strategies as S

__all__ = ["test_mass_properties_closed_forms"]

#: Examples at most (the profile's count if lower): each asks every declared resolution.
CAP = 5

test_mass_properties_closed_forms = certificate_test(
    "test_mass_properties_closed_forms",
    "One-leaf solids (moved, turned, scaled) against the leaf table's closed forms: the error "
    "falls at the stated order as the resolution rises; every claim bounds the error; the "
    "declared floor is at most MAX_FLOOR.",
    "peclet_mass_backend", lambda be, r: P.mass_properties_certificate(r, be),
    S.closed_form_solids, "mass_closed_forms", CAP)
