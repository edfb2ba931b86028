"""Certify the upstream wheels on every family that applies: geometry (peclet-geom), mass
properties (peclet-geom's body_properties) and DEM with the closed-form mechanics (peclet-dem)."""
from peclet_verify.dem.suite import *  # noqa: F401,F403
from peclet_verify.geometry.suite import *  # noqa: F401,F403
from peclet_verify.mass.suite import *  # noqa: F401,F403
from peclet_verify.mechanics.suite import *  # noqa: F401,F403
