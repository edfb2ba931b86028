"""peclet.packing: packing elements, the pour protocol, pack analysis, freeze/load, figures and
the ``peclet pall-ring`` pipeline (the reference page, Steps 1-7)."""
from .elements import (ELEMENTS, Element, berl_saddle, intalox_saddle, pall_ring,
                       pall_ring_of_thickness, raschig_ring, solid_cylinder, sphere)

__all__ = ["ELEMENTS", "Element", "berl_saddle", "intalox_saddle", "pall_ring",
           "pall_ring_of_thickness", "raschig_ring", "solid_cylinder", "sphere"]
