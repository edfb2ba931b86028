"""peclet.packing: packed beds, in five subpackages (docs/architecture.md section 10):

- :mod:`~peclet.packing.bed`: elements, containers, materials, protocols, :func:`pack` /
  :func:`resume`, the pour, the frozen pack, progress, run checkpoints;
- :mod:`~peclet.packing.analysis`: pack analysis on the exact trees, coordination, profiles;
- :mod:`~peclet.packing.output`: exports, figures, the bed report;
- :mod:`~peclet.packing.experiments`: the drum, the stirred column, growth to jamming;
- :mod:`~peclet.packing.page`: the ``peclet pall-ring`` pipeline (the reference page, Steps 1-7).
"""
from .analysis import profiles
from .bed.api import PackResult, pack, resume
from .bed.containers import Container
from .bed.elements import (ELEMENTS, Element, berl_saddle, intalox_saddle, pall_ring,
                           pall_ring_of_thickness, raschig_ring, solid_cylinder, sphere)
from .bed.material import Material
from .bed.protocols import PageProtocol, RainProtocol

__all__ = ["ELEMENTS", "Element", "berl_saddle", "intalox_saddle", "pall_ring",
           "pall_ring_of_thickness", "raschig_ring", "solid_cylinder", "sphere", "pack",
           "resume", "PackResult", "Material", "Container", "PageProtocol", "RainProtocol",
           "profiles"]
