"""Certification of peclet's contact laws on the Chung & Ooi benchmarks (the Hertz law unless
``--peclet-impact-backend`` names another engine, e.g.
``peclet_verify.impact.backend:linear_backend``): the suite a downstream project imports."""
from peclet_verify.impact.suite import *  # noqa: F401,F403
