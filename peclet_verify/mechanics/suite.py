"""The closed-form mechanics certificates of any DEM engine, ready to import into a test
module::

    from peclet_verify.mechanics.suite import *  # noqa: F401,F403

with the DEM family's backend (a ``pytest_peclet_make_dem_backend(config)`` hook in
``conftest.py``, or ``--peclet-dem-backend module:factory``; without either, peclet.dem is
certified). Each certificate searches the active profile's examples (capped: every example is
a run of the engine) and prints a shrunk counterexample as a runnable page-API snippet. Names
are in the registry's ``mechanics`` family (:mod:`peclet_verify.registry`).
"""
from ..suites import certificate_test
from . import properties as P
from . import strategies as S

__all__ = ["test_dem_binary_restitution", "test_dem_slide_to_roll",
           "test_dem_incline_stick_slip", "test_dem_free_rigid_body"]

#: Examples per certificate at most (the profile's count if lower): each is a run.
CAPS = {"mechanics": 10, "rotor": 6}

_IMPORT = "from peclet_verify.mechanics.strategies import Collision, Incline, Roll, Rotor\n"


def describe_case(x):
    """A mechanics case as the code that makes it, and its run in the page's API."""
    return f"{_IMPORT}{x!r}\n# in the page's API:\n{x.scenario().snippet()}"


def _mechanics_test(test_name, doc, prop, strategy, key, cap):
    return certificate_test(test_name, doc, "peclet_dem_backend", prop, strategy, key, cap,
                            describe_case)


test_dem_binary_restitution = _mechanics_test(
    "test_dem_binary_restitution",
    "Two spheres head-on: separation / approach speed = e; momentum conserved.",
    P.binary_restitution, S.collisions, "binary_restitution", CAPS["mechanics"])


test_dem_slide_to_roll = _mechanics_test(
    "test_dem_slide_to_roll", "A solid sphere launched sliding: rolls at v = 5/7 v0.",
    P.slide_to_roll, S.rolls, "slide_to_roll", CAPS["mechanics"])


test_dem_incline_stick_slip = _mechanics_test(
    "test_dem_incline_stick_slip",
    "A cube on an incline: sticks for tan(theta) < mu, slides at g (sin - mu cos) above.",
    P.incline, S.inclines, "incline", CAPS["mechanics"])


test_dem_free_rigid_body = _mechanics_test(
    "test_dem_free_rigid_body",
    "A torque-free asymmetric body: energy and angular momentum conserved, the "
    "intermediate-axis flip period of Euler's equations.",
    P.free_rigid_body, S.rotors, "free_rigid_body", CAPS["rotor"])
