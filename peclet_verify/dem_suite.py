"""The DEM certificates of any DEM engine, ready to import into a test module.

A downstream project certifies its DEM engine with a test module holding one line::

    from peclet_verify.dem_suite import *  # noqa: F401,F403

and a ``pytest_peclet_make_dem_backend(config)`` hook in its ``conftest.py`` returning the
engine (a :class:`~peclet_verify.dem_backends.DemBackend`; or ``--peclet-dem-backend
module:factory``); then ``pytest --peclet-certify``. Without either, peclet.dem is certified.
Each certificate searches the active profile's examples (capped: every example is a run of
the engine) and prints a shrunk counterexample as a runnable page-API snippet. Names are in
the registry's ``dem`` scope (:mod:`peclet_verify.registry`).
"""

import pytest

from . import properties as P
from . import registry as REG
from . import strategies as pst

__all__ = ["test_dem_determinism_one_thread", "test_dem_determinism_across_threads",
           "test_dem_buffer_growth", "test_dem_binary_restitution", "test_dem_slide_to_roll",
           "test_dem_incline_stick_slip", "test_dem_free_rigid_body"]

#: Examples per certificate at most (the profile's count if lower): each is a run or more.
CAPS = {"determinism": 4, "buffer": 4, "mechanics": 10, "rotor": 6}


def _few(kind):
    return P.profile_settings(max_examples=min(P.active_settings().max_examples, CAPS[kind]))


def _tagged(result, backend):
    result.details["backend"] = getattr(backend, "name", type(backend).__name__)
    return result


_IMPORT = "from peclet_verify.strategies import Collision, Incline, Pour, Roll, Rotor\n"


def describe_pour(p):
    return f"{_IMPORT}{p!r}\n# the run, in the page's API:\n{pst.pour_scenario(p).snippet()}"


def describe_hints(a):
    p, hints = a
    cap, ccap = hints[0]
    return (f"{_IMPORT}pour = {p!r}\nhints = {hints!r}\n# the first hinted run, in the page's API:\n"
            f"{pst.pour_scenario(p, capacity=cap, contact_capacity=ccap).snippet()}")


def describe_case(x):
    return f"{_IMPORT}{x!r}\n# in the page's API:\n{x.scenario().snippet()}"


def _search(be, prop, strategy, name, kind, describe=describe_case):
    """:func:`peclet_verify.properties.search` of ``prop(be, example)`` over ``strategy``, at
    most ``CAPS[kind]`` examples."""
    return P.search(lambda x: prop(be, x), strategy, name=name, settings=_few(kind),
                    describe=describe)


def _certify(peclet_certificate, be, prop, strategy, name, kind, describe=describe_case):
    """Record the certificate of :func:`_search`, tagged with the backend's name."""
    peclet_certificate(_tagged(_search(be, prop, strategy, name, kind, describe), be))


def _dem_certificate(test_name, doc, prop, strategy, key, kind, describe=describe_case):
    """A certificate test named ``test_name`` (docstring ``doc``) that records the
    certificate ``key`` of the registry: ``prop(backend, example)`` over ``strategy()`` (one
    test function serves every certificate that is a plain property search)."""
    @pytest.mark.peclet_certify
    def test(peclet_certificate, peclet_dem_backend):
        _certify(peclet_certificate, peclet_dem_backend, prop, strategy(), REG.title(key), kind,
                 describe)
    test.__name__ = test.__qualname__ = test_name
    test.__doc__ = doc
    return test


test_dem_determinism_one_thread = _dem_certificate(
    "test_dem_determinism_one_thread", "Two runs of a pour at one thread: the same bytes.",
    P.determinism_one_thread, pst.pours, "dem_determinism_one_thread", "determinism",
    describe_pour)


@pytest.mark.peclet_certify
def test_dem_determinism_across_threads(peclet_certificate, peclet_dem_backend):
    """A pour at every thread count the engine runs: the bytes of the one-thread run.
    "not claimed" (skipped, listed) for an engine declaring ``thread_determinism = False``."""
    be = peclet_dem_backend
    name = REG.title("dem_determinism_across_threads")
    if not getattr(be, "thread_determinism", True):
        res = P.PropertyResult(name, False, 0, float("nan"), REG.certificate(
            "dem_determinism_across_threads").figure, f"{getattr(be, 'name', be)!r} declares "
            "thread_determinism = False", P.NOT_CLAIMED)
    else:
        res = _search(be, P.determinism_across_threads, pst.pours(), name, "determinism",
                      describe_pour)
        res.name = name   # also when "unavailable" (a property's own result)
    peclet_certificate(_tagged(res, be))
    if res.status == P.NOT_CLAIMED:
        pytest.skip(f"{name}: not claimed by the engine ({res.counterexample})")


@pytest.mark.peclet_certify
def test_dem_buffer_growth(peclet_certificate, peclet_dem_backend):
    """A pour under capacity hints that force growth: the trajectory of ample hints, no
    contact lost, no crash."""
    from hypothesis import strategies as st
    _certify(peclet_certificate, peclet_dem_backend, lambda be, a: P.dem_buffer_growth(be, *a),
             st.tuples(pst.pours(), pst.capacity_hints()), REG.title("dem_buffer_growth"),
             "buffer", describe_hints)


test_dem_binary_restitution = _dem_certificate(
    "test_dem_binary_restitution",
    "Two spheres head-on: separation / approach speed = e; momentum conserved.",
    P.binary_restitution, pst.collisions, "binary_restitution", "mechanics")


test_dem_slide_to_roll = _dem_certificate(
    "test_dem_slide_to_roll", "A solid sphere launched sliding: rolls at v = 5/7 v0.",
    P.slide_to_roll, pst.rolls, "slide_to_roll", "mechanics")


test_dem_incline_stick_slip = _dem_certificate(
    "test_dem_incline_stick_slip",
    "A cube on an incline: sticks for tan(theta) < mu, slides at g (sin - mu cos) above.",
    P.incline, pst.inclines, "incline", "mechanics")


test_dem_free_rigid_body = _dem_certificate(
    "test_dem_free_rigid_body",
    "A torque-free asymmetric body: energy and angular momentum conserved, the "
    "intermediate-axis flip period of Euler's equations.",
    P.free_rigid_body, pst.rotors, "free_rigid_body", "rotor")
