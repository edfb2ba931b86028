"""Certification of a mass-property engine against the leaf table's closed forms (peclet's
quadrature unless ``--peclet-mass-backend`` names another): :mod:`peclet_verify.mass.suite`."""
from peclet_verify.mass.suite import *  # noqa: F401,F403
