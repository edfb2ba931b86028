"""peclet.packing: packing elements, containers, deposition protocols (the page's and rain),
:func:`pack` (any element into any container), checkpoint/resume, pack analysis,
freeze/load, figures and the ``peclet pall-ring`` pipeline (the reference page, Steps 1-7)."""
from .api import PackResult, pack, resume
from .containers import Container
from .elements import (ELEMENTS, Element, berl_saddle, intalox_saddle, pall_ring,
                       pall_ring_of_thickness, raschig_ring, solid_cylinder, sphere)
from .material import Material
from .protocols import PageProtocol, RainProtocol

__all__ = ["ELEMENTS", "Element", "berl_saddle", "intalox_saddle", "pall_ring",
           "pall_ring_of_thickness", "raschig_ring", "solid_cylinder", "sphere", "pack",
           "resume", "PackResult", "Material", "Container", "PageProtocol", "RainProtocol"]
