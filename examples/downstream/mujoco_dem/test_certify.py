"""Certify MuJoCo as a DEM engine: determinism, contact buffers, closed-form mechanics."""
from peclet_verify.dem.suite import *  # noqa: F401,F403
from peclet_verify.mechanics.suite import *  # noqa: F401,F403
