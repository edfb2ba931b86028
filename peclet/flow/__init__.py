"""``peclet.flow``: steady flow through a pack by a D3Q19 lattice-Boltzmann solver.

Geometry comes straight from the exact trees (fluid nodes where phi > 0, wall crossings on
every link by a root find of phi along it), so contact points and walls thinner than a cell
need no special meshing. Modules: ``lattice`` (D3Q19, TRT rates), ``geometry`` (fluid nodes,
cut links), ``solver`` (TRT, body force, mass correction, convergence), ``wall_rule``
(interpolated bounce-back with a parabolic correction), ``domain`` (the lattice over a pack),
``packs`` (every pack file, grown beds included), ``setup`` (a pack's flow problem and what a
solve measures), ``permeability`` (packs: k, Kozeny, Ergun, drag, Richardson), ``curve``
(dP/L against Re, the Forchheimer fit), ``correlations`` (Ergun, Eisfeld & Schnitzlein,
Carman-Kozeny, Happel), ``output`` (VTI/VTU, slice and curve figures).

    from peclet.flow import permeability
    r = permeability("pall_ring_pack.npz", resolution=16)
    print(r.k_D2, r.ergun_ratio_sauter)
    c = pressure_drop_curve("pack.npz", "0.01:100:8", resolution=8)
    print(c.fit["k_D2"], c.fit["beta_D"])
"""
from .curve import forchheimer_fit, pressure_drop_curve
from .domain import PeriodicCell
from .geometry import Grid, LatticeGeometry, build_geometry
from .lattice import MAGIC_DEFAULT
from .permeability import PackFlow, ThinWallWarning, pack_domain, permeability, richardson
from .packs import load_flow_pack
from .solver import FlowResult, solve

__all__ = ["permeability", "richardson", "pack_domain", "PackFlow", "ThinWallWarning", "Grid",
           "LatticeGeometry", "build_geometry", "solve", "FlowResult", "MAGIC_DEFAULT", "pressure_drop_curve",
           "forchheimer_fit", "PeriodicCell", "load_flow_pack"]
