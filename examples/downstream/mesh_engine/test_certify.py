"""Certify the mesh engine: every certificate peclet ships for an engine."""
from peclet_verify.geometry.suite import *  # noqa: F401,F403
