"""Certify LAMMPS's GRANULAR package: the Chung & Ooi benchmarks (the impact family), and
determinism, contact buffers and closed-form mechanics through the page's API (the DEM and
mechanics families)."""
from peclet_verify.impact.suite import *  # noqa: F401,F403
from peclet_verify.dem.suite import *  # noqa: F401,F403
from peclet_verify.mechanics.suite import *  # noqa: F401,F403
