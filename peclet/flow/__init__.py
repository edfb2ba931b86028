"""``peclet.flow``: steady flow through a pack by a D3Q19 lattice-Boltzmann solver.

Geometry comes straight from the exact trees (fluid nodes where phi > 0, wall crossings on
every link by a root find of phi along it), so contact points and walls thinner than a cell
need no special meshing. Modules: ``lattice`` (D3Q19, TRT rates), ``geometry`` (fluid nodes,
cut links), ``solver`` (TRT, body force, mass correction, convergence), ``wall_rule``
(interpolated bounce-back with a parabolic correction), ``permeability`` (packs: k, Kozeny,
Ergun, drag, Richardson), ``output`` (VTI/VTU, slice figure).

    from peclet.flow import permeability
    r = permeability("pall_ring_pack.npz", resolution=16)
    print(r.k_D2, r.ergun_ratio_sauter)
"""
from .geometry import Grid, LatticeGeometry, build_geometry
from .lattice import MAGIC_DEFAULT
from .permeability import PackFlow, ThinWallWarning, pack_domain, permeability, richardson
from .solver import FlowResult, solve

__all__ = ["permeability", "richardson", "pack_domain", "PackFlow", "ThinWallWarning", "Grid",
           "LatticeGeometry", "build_geometry", "solve", "FlowResult", "MAGIC_DEFAULT"]
