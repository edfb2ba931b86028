"""The DEM certificates of any DEM engine, ready to import into a test module.

A downstream project certifies its DEM engine with a test module holding::

    from peclet_verify.dem.suite import *  # noqa: F401,F403
    from peclet_verify.mechanics.suite import *  # noqa: F401,F403  (closed-form mechanics)

and a ``pytest_peclet_make_dem_backend(config)`` hook in its ``conftest.py`` returning the
engine (a :class:`~peclet_verify.dem.backend.DemBackend`; or ``--peclet-dem-backend
module:factory``); then ``pytest --peclet-certify``. Without either, peclet.dem is certified.
Each certificate searches the active profile's examples (capped: every example is a run of
the engine) and prints a shrunk counterexample as a runnable page-API snippet. Names are in
the registry's ``dem`` family (:mod:`peclet_verify.registry`).
"""
import pytest

from .. import registry as REG
from ..search import NOT_CLAIMED, PropertyResult
from ..suites import capped_search, tagged
from . import properties as P
from . import strategies as S

__all__ = ["test_dem_determinism_one_thread", "test_dem_determinism_across_threads",
           "test_dem_buffer_growth"]

#: Examples per certificate at most (the profile's count if lower): each is a run or more.
CAPS = {"determinism": 4, "buffer": 4}

_IMPORT = "from peclet_verify.dem.strategies import Pour\n"


def describe_pour(p):
    """A pour as the code that makes it, and its run in the page's API."""
    return f"{_IMPORT}{p!r}\n# the run, in the page's API:\n{S.pour_scenario(p).snippet()}"


def describe_hints(a):
    """A pour with capacity hints as code, and its first hinted run in the page's API."""
    p, hints = a
    cap, ccap = hints[0]
    return (f"{_IMPORT}pour = {p!r}\nhints = {hints!r}\n# the first hinted run, in the page's API:\n"
            f"{S.pour_scenario(p, capacity=cap, contact_capacity=ccap).snippet()}")


@pytest.mark.peclet_certify
def test_dem_determinism_one_thread(peclet_certificate, peclet_dem_backend):
    """Two runs of a pour at one thread, and one in each of two fresh processes: the same
    bytes. The report says whether the fresh processes ran (``cross_process``)."""
    be = peclet_dem_backend
    res = capped_search(be, P.determinism_one_thread, S.pours(),
                        REG.title("dem_determinism_one_thread"), CAPS["determinism"],
                        describe_pour)
    res.details["cross_process"] = P.cross_process(be)
    peclet_certificate(res)


@pytest.mark.peclet_certify
def test_dem_determinism_across_threads(peclet_certificate, peclet_dem_backend):
    """A pour at every thread count the engine runs: the bytes of the one-thread run.
    "not claimed" (skipped, listed) for an engine declaring ``thread_determinism = False``."""
    be = peclet_dem_backend
    name = REG.title("dem_determinism_across_threads")
    if not getattr(be, "thread_determinism", True):
        res = tagged(PropertyResult(name, False, 0, float("nan"), REG.certificate(
            "dem_determinism_across_threads").figure, f"{getattr(be, 'name', be)!r} declares "
            "thread_determinism = False", NOT_CLAIMED), be)
    else:
        res = capped_search(be, P.determinism_across_threads, S.pours(), name,
                            CAPS["determinism"], describe_pour)
        res.name = name   # also when "unavailable" (a property's own result)
    peclet_certificate(res)
    if res.status == NOT_CLAIMED:
        pytest.skip(f"{name}: not claimed by the engine ({res.counterexample})")


@pytest.mark.peclet_certify
def test_dem_buffer_growth(peclet_certificate, peclet_dem_backend):
    """A pour under capacity hints that force growth: the trajectory of ample hints, no
    contact lost, no crash."""
    from hypothesis import strategies as st
    peclet_certificate(capped_search(
        peclet_dem_backend, lambda be, a: P.dem_buffer_growth(be, *a),
        st.tuples(S.pours(), S.capacity_hints()), REG.title("dem_buffer_growth"),
        CAPS["buffer"], describe_hints))
