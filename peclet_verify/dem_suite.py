"""The DEM certificates of any DEM engine, ready to import into a test module.

A downstream project certifies its DEM engine with a test module holding one line::

    from peclet_verify.dem_suite import *  # noqa: F401,F403

and a ``pytest_peclet_make_dem_backend(config)`` hook in its ``conftest.py`` returning the
engine (a :class:`~peclet_verify.dem_backends.DemBackend`; or ``--peclet-dem-backend
module:factory``); then ``pytest --peclet-certify``. Without either, peclet.dem is certified.
Each certificate searches the active profile's examples (capped: every example is a run of
the engine) and prints a shrunk counterexample as a runnable page-API snippet. Names are in
:data:`peclet_verify.report.DEM_CERTIFICATES`.
"""
import pytest

from . import mechanics as M
from . import properties as P

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


_IMPORT = "from peclet_verify.mechanics import Collision, Incline, Pour, Roll, Rotor\n"


def describe_pour(p):
    return f"{_IMPORT}{p!r}\n# the run, in the page's API:\n{M.pour_scenario(p).snippet()}"


def describe_hints(a):
    p, hints = a
    cap, ccap = hints[0]
    return (f"{_IMPORT}pour = {p!r}\nhints = {hints!r}\n# the first hinted run, in the page's API:\n"
            f"{M.pour_scenario(p, capacity=cap, contact_capacity=ccap).snippet()}")


def describe_case(x):
    return f"{_IMPORT}{x!r}\n# in the page's API:\n{x.scenario().snippet()}"


@pytest.mark.peclet_certify
def test_dem_determinism_one_thread(peclet_certificate, peclet_dem_backend):
    """Two runs of a pour at one thread: the same bytes."""
    be = peclet_dem_backend
    peclet_certificate(_tagged(P.search(
        lambda p: M.determinism_one_thread(be, p), M.pours(),
        name="determinism at one thread (DEM backend)", settings=_few("determinism"),
        describe=describe_pour), be))


@pytest.mark.peclet_certify
def test_dem_determinism_across_threads(peclet_certificate, peclet_dem_backend):
    """A pour at every thread count the engine runs: the bytes of the one-thread run.
    "not claimed" (skipped, listed) for an engine declaring ``thread_determinism = False``."""
    be = peclet_dem_backend
    name = "determinism across threads (DEM backend)"
    if not getattr(be, "thread_determinism", True):
        res = P.PropertyResult(name, False, 0, float("nan"), "distinct state hashes",
                               f"{getattr(be, 'name', be)!r} declares thread_determinism = "
                               "False", M.NOT_CLAIMED)
    else:
        res = P.search(lambda p: M.determinism_across_threads(be, p), M.pours(), name=name,
                       settings=_few("determinism"), describe=describe_pour)
        res.name = name   # also when "unavailable" (a property's own result)
    peclet_certificate(_tagged(res, be))
    if res.status == M.NOT_CLAIMED:
        pytest.skip(f"{name}: not claimed by the engine ({res.counterexample})")


@pytest.mark.peclet_certify
def test_dem_buffer_growth(peclet_certificate, peclet_dem_backend):
    """A pour under capacity hints that force growth: the trajectory of ample hints, no
    contact lost, no crash."""
    from hypothesis import strategies as st
    be = peclet_dem_backend
    peclet_certificate(_tagged(P.search(
        lambda a: M.buffer_growth(be, a[0], a[1]), st.tuples(M.pours(), M.capacity_hints()),
        name="buffer growth (DEM backend)", settings=_few("buffer"),
        describe=describe_hints), be))


@pytest.mark.peclet_certify
def test_dem_binary_restitution(peclet_certificate, peclet_dem_backend):
    """Two spheres head-on: separation / approach speed = e; momentum conserved."""
    be = peclet_dem_backend
    peclet_certificate(_tagged(P.search(
        lambda c: M.binary_restitution(be, c), M.collisions(), name="binary restitution",
        settings=_few("mechanics"), describe=describe_case), be))


@pytest.mark.peclet_certify
def test_dem_slide_to_roll(peclet_certificate, peclet_dem_backend):
    """A solid sphere launched sliding: rolls at v = 5/7 v0."""
    be = peclet_dem_backend
    peclet_certificate(_tagged(P.search(
        lambda r: M.slide_to_roll(be, r), M.rolls(), name="slide to roll",
        settings=_few("mechanics"), describe=describe_case), be))


@pytest.mark.peclet_certify
def test_dem_incline_stick_slip(peclet_certificate, peclet_dem_backend):
    """A cube on an incline: sticks for tan(theta) < mu, slides at g (sin - mu cos) above."""
    be = peclet_dem_backend
    peclet_certificate(_tagged(P.search(
        lambda i: M.incline(be, i), M.inclines(), name="incline stick/slip",
        settings=_few("mechanics"), describe=describe_case), be))


@pytest.mark.peclet_certify
def test_dem_free_rigid_body(peclet_certificate, peclet_dem_backend):
    """A torque-free asymmetric body: energy and angular momentum conserved, the
    intermediate-axis flip period of Euler's equations."""
    be = peclet_dem_backend
    peclet_certificate(_tagged(P.search(
        lambda r: M.free_rigid_body(be, r), M.rotors(), name="free rigid body",
        settings=_few("rotor"), describe=describe_case), be))
