"""Certify MuJoCo as a DEM engine: determinism, contact buffers, closed-form mechanics."""
from peclet_verify.dem_suite import *  # noqa: F401,F403
