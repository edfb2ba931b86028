"""Hypothesis strategies of the mass-property family: one-leaf solids (moved, turned, scaled)
whose mass properties the leaf table knows in closed form.
"""
from __future__ import annotations

from ..geometry.strategies import leaves

__all__ = ["CLOSED_FORM_KINDS", "MASS_KINDS", "closed_form_solids"]

#: Leaves with a closed form in the leaf table that peclet's quadrature certifies.
CLOSED_FORM_KINDS = ("sphere", "box", "ellipsoid", "hollow_cylinder", "torus", "capsule")
#: Leaves a mass-property engine is certified on: the closed-form leaves whose distance is
#: exact, less the cone: peclet's quadrature overflows its 128 breakpoint slots on some
#: turned cones in their ball's box ("a line crossed the surface more than 128 times", a
#: known limitation, see tests/test_leaf_closed_forms.py). Pass ``kinds`` to include it.
MASS_KINDS = ("sphere", "box", "hollow_cylinder", "torus", "capsule")


def closed_form_solids(kinds=MASS_KINDS):
    """One-leaf :class:`~peclet_verify.geometry.recipes.TreeRecipe` s of ``kinds`` with random
    transforms (see :func:`~peclet_verify.geometry.strategies.leaves`)."""
    return leaves(kinds=kinds)
