"""The Chung & Ooi certificates of any impact engine, ready to import into a test module::

    from peclet_verify.impact.suite import *  # noqa: F401,F403

with the family's backend (a ``pytest_peclet_make_impact_backend(config)`` hook in
``conftest.py``, or ``--peclet-impact-backend module:factory``; without either, peclet.dem's
Hertz law is certified). Each certificate searches its benchmark's parameter range
(:mod:`peclet_verify.impact.strategies`), at most :data:`CAP` examples (each is an impact run
to separation), and prints a shrunk counterexample as the :class:`Impact` that rebuilds it.
A test the engine does not claim (a capability it does not declare) is reported "not
claimed".
"""
from .. import registry as REG
from ..suites import certificate_test
from .properties import judge
from .strategies import TESTS

#: Examples per certificate at most (the profile's count if lower): each is an impact run.
CAP = 6

_IMPORT = "from peclet_verify.impact.cases import Ball, Impact\n"

__all__ = [f"test_chung_ooi_{n}" for n in TESTS]


def describe_case(case):
    """An impact case as the code that makes it."""
    return f"{_IMPORT}{case!r}"


for _n, _strategy in TESTS.items():
    globals()[f"test_chung_ooi_{_n}"] = certificate_test(
        f"test_chung_ooi_{_n}", REG.title(f"chung_ooi_{_n}"), "peclet_impact_backend", judge,
        lambda s=_strategy: s, f"chung_ooi_{_n}", CAP, describe_case)
