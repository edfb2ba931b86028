"""What the families' suite modules share (pytest at import): a certificate test that searches a
property of the engine a family fixture provides, at most a few examples (each is a run of the
engine), and records the result tagged with the engine's name."""
from __future__ import annotations

import pytest

from . import registry as REG
from .loading import backend_name
from .search import capped_settings, search

__all__ = ["tagged", "capped_search", "certificate_test"]


def tagged(result, backend):
    """``result`` with ``details["backend"]`` set to the engine's name; returned."""
    result.details["backend"] = backend_name(backend)
    return result


def capped_search(backend, prop, strategy, name, cap, describe=repr):
    """:func:`peclet_verify.search.search` of ``prop(backend, example)`` over ``strategy``, at
    most ``cap`` examples (the profile's count if lower), tagged with the engine's name."""
    return tagged(search(lambda x: prop(backend, x), strategy, name=name,
                         settings=capped_settings(cap), describe=describe), backend)


def certificate_test(test_name, doc, fixture, prop, strategy, key, cap, describe=repr):
    """A certificate test named ``test_name`` (docstring ``doc``, marked ``peclet_certify``)
    that records the registry's certificate ``key``: ``prop(engine, example)`` over
    ``strategy()``, the engine being the session fixture named ``fixture``, at most ``cap``
    examples. One function serves every certificate that is a plain property search."""
    @pytest.mark.peclet_certify
    def test(peclet_certificate, request):
        engine = request.getfixturevalue(fixture)
        peclet_certificate(capped_search(engine, prop, strategy(), REG.title(key), cap,
                                         describe))
    test.__name__ = test.__qualname__ = test_name
    test.__doc__ = doc
    return test
