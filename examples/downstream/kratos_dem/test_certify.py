"""Certify Kratos DEM on the Chung & Ooi benchmarks (the impact family)."""
from peclet_verify.impact.suite import *  # noqa: F401,F403
