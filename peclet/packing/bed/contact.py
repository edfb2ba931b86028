"""The contact law of a pack: the impulse engine (the default) or Hertz–Mindlin, and the one
call by which every protocol step advances the simulation (:func:`advance`).

Units of the bed (docs/architecture.md §10): lengths in element diameters D, gravity
9.81 D/T^2, element density 1 (a body's mass is its volume in D^3). Read against a physical
bed of element diameter ``D_m`` (m) and density ``rho`` (kg/m^3) under g = 9.81 m/s^2, one
length unit is ``D_m`` m, one time unit ``T = sqrt(D_m / (1 m/s^2))`` s, one mass unit
``rho D_m^3`` kg, so one pressure unit is ``rho D_m x 1 m/s^2`` Pa (``rho g D_m / 9.81``):

    E_bed = E_Pa / (rho D_m x 1 m/s^2)       (1e7 Pa, 1 mm, 2500 kg/m^3 -> 4e6)

(:meth:`HertzContact.from_si`). A library element has D = 1 world length; an element whose D
is ``d`` world lengths gets ``E_world = E_bed d^2`` (the world's pressure unit is
``rho D_m / d^2 x 1 m/s^2``), so a bed's physics is the same whatever length its tree was
authored in.

Time step: a protocol's step ``dt`` (its schedule: insertion, stop rule, quench, taps all count
these steps) is split into ``K`` Hertz substeps of ``dt / K``, the smallest K for which
``dt / K <= rayleigh_fraction x T_R``, T_R the element's Rayleigh time
``pi R sqrt(rho / G) / (0.1631 nu + 0.8766)`` (R the bounding radius, rho its mass spread
over the bounding sphere, as :mod:`peclet.dem.hertz` checks it). The simulation records the
law and K (``Simulation.set_contact_law("hertz", substeps=K)``), so a checkpoint carries it and
:func:`advance` reads it back from the simulation alone.

Walls stay rigid (``1/E_wall = 0``, the Hertz engine's wall without a material id): a sphere
on the floor sees ``E* = E / (1 - nu^2)``, as in ``benchmarks/_vs_lammps.py``'s reading of
LAMMPS's wall. Restitution and friction come from the pack's materials, as for the impulse
engine; the Walton ``e_t`` is not used by the Hertz law.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from peclet.core.validation import PecletArgumentError, check_float

__all__ = ["HertzContact", "parse_contact", "advance", "CONTACT_FORMS", "MAX_SUBSTEPS_PER_STEP",
           "PRESSURE_UNIT_SI", "DEFAULT_RAYLEIGH_FRACTION"]

#: The default fraction of the Rayleigh time a Hertz substep may take (the engine refuses
#: more than ``peclet.dem.hertz.RAYLEIGH_FRACTION``, 0.3).
DEFAULT_RAYLEIGH_FRACTION = 0.2

#: One bed pressure unit per (kg/m^3 x m): rho D_m x 1 m/s^2 (see the module notes).
PRESSURE_UNIT_SI = 1.0

#: The physical default: E = 1e7 Pa, 1 mm spheres of 2500 kg/m^3 (the LAMMPS column of
#: ``benchmarks/bench_vs_lammps.py``), in bed units.
DEFAULT_SI = dict(youngs=1e7, diameter=1e-3, density=2500.0)

#: Most Hertz substeps one protocol step may need (a stiffer E is refused, naming it).
MAX_SUBSTEPS_PER_STEP = 10_000

CONTACT_FORMS = ("'impulse' (the default), 'hertz', a HertzContact, or a dict "
                 "{'law': 'hertz', 'youngs': E, 'poisson': nu, 'rayleigh_fraction': f}")


def _bed_youngs(youngs, diameter, density):
    return youngs / (density * diameter * PRESSURE_UNIT_SI)


@dataclass(frozen=True)
class HertzContact:
    """The Hertz–Mindlin law of :mod:`peclet.dem.hertz` for a pack.

    ``youngs``: Young's modulus E of the elements in bed pressure units (``rho D_m x 1
    m/s^2``, module notes; > 0, finite; default 4e6, i.e. 1e7 Pa for 1 mm spheres of 2500
    kg/m^3: :meth:`from_si` converts); ``poisson``: Poisson's ratio nu in (-1, 0.5) (default
    0.3); ``rayleigh_fraction``: the largest substep as a fraction of the element's Rayleigh
    time, in (0, 0.3] (default 0.2). Each argument is checked (PecletArgumentError naming it).
    """

    youngs: float = _bed_youngs(**DEFAULT_SI)
    poisson: float = 0.3
    rayleigh_fraction: float = DEFAULT_RAYLEIGH_FRACTION
    law = "hertz"

    def __post_init__(self):
        from peclet.dem.hertz import RAYLEIGH_FRACTION
        object.__setattr__(self, "youngs", check_float("youngs", self.youngs, 0.0,
                                                       lo_open=True))
        object.__setattr__(self, "poisson", check_float("poisson", self.poisson, -1.0, 0.5,
                                                        lo_open=True, hi_open=True))
        object.__setattr__(self, "rayleigh_fraction", check_float(
            "rayleigh_fraction", self.rayleigh_fraction, 0.0, RAYLEIGH_FRACTION,
            lo_open=True))

    @classmethod
    def from_si(cls, youngs, diameter=DEFAULT_SI["diameter"], density=DEFAULT_SI["density"],
                poisson=0.3, rayleigh_fraction=DEFAULT_RAYLEIGH_FRACTION):
        """The law for a physical bed: ``youngs`` E in Pa (> 0), element diameter
        ``diameter`` D_m in m (> 0; default 1e-3), element density ``density`` in kg/m^3
        (> 0; default 2500), under g = 9.81 m/s^2: ``E_bed = E / (density diameter x 1
        m/s^2)``."""
        e = check_float("youngs", youngs, 0.0, lo_open=True)
        d = check_float("diameter", diameter, 0.0, lo_open=True)
        rho = check_float("density", density, 0.0, lo_open=True)
        return cls(_bed_youngs(e, d, rho), poisson, rayleigh_fraction)

    def to_spec(self):
        """``{"law": "hertz", "youngs": E_bed, "poisson": nu, "rayleigh_fraction": f}``."""
        return dict(law=self.law, youngs=self.youngs, poisson=self.poisson,
                    rayleigh_fraction=self.rayleigh_fraction)

    def rayleigh_time(self, model):
        """The element's Rayleigh time (bed time units) for an ElementModel ``model`` (its
        bounding radius and mass, E in world units: ``youngs d^2``)."""
        from peclet.dem.hertz import rayleigh_time

        r = float(model.bounding_radius)
        rho = float(model.mass) / (4.0 / 3.0 * math.pi * r ** 3)
        return float(rayleigh_time(r, rho, self.youngs * model.d ** 2, self.poisson))

    def schedule(self, model, dt):
        """(K substeps per protocol step, the substep dt / K, the Rayleigh time T_R) for the
        protocol step ``dt``: the smallest K with dt / K <= rayleigh_fraction x T_R.
        PecletArgumentError naming ``youngs`` when K would exceed
        :data:`MAX_SUBSTEPS_PER_STEP`."""
        tr = self.rayleigh_time(model)
        limit = self.rayleigh_fraction * tr
        k = max(1, math.ceil(dt / limit))
        while dt / k > limit:              # rounding
            k += 1
        if k > MAX_SUBSTEPS_PER_STEP:
            raise PecletArgumentError(
                "youngs", f"soft enough for at most {MAX_SUBSTEPS_PER_STEP} Hertz substeps "
                f"per protocol step (dt {dt:g} against {self.rayleigh_fraction:g} x the "
                f"Rayleigh time {tr:.4g})", self.youngs, f"it needs {k}")
        return k, dt / k, tr

    def check_material(self, material, name):
        """Refuse a restitution the Hertz damping cannot reproduce (below
        ``peclet.dem.hertz.E_MIN``), naming ``name`` (``material`` or ``wall_material``)."""
        from peclet.dem.hertz import E_MIN
        if material.e_n < E_MIN:
            raise PecletArgumentError(f"{name}.e_n", f"in [{E_MIN}, 1] with the Hertz contact "
                                      "law (its damping cannot stop a contact dead)",
                                      material.e_n)

    def configure(self, sim, model, dt):
        """Give ``sim`` the law: the element's moduli (material id 0, every body's), rigid
        walls, ``Simulation.set_contact_law("hertz", substeps=K)`` for the protocol step
        ``dt``. Returns :meth:`schedule`'s (K, substep, T_R)."""
        k, sub, tr = self.schedule(model, dt)
        sim.set_hertz_material(0, self.youngs * model.d ** 2, self.poisson)
        sim.set_contact_law("hertz", substeps=k)
        return k, sub, tr

    def describe(self, model, dt):
        """One line: E (bed units), nu, the Rayleigh time, K and the substep it chose."""
        k, sub, tr = self.schedule(model, dt)
        return (f"contact hertz: E {self.youngs:.6g} (bed units, rho D x 1 m/s^2), nu "
                f"{self.poisson:g}; Rayleigh time {tr:.4g}; dt {sub:.4g} = step {dt:g} / {k} "
                f"substeps (<= {self.rayleigh_fraction:g} T_R)")


def parse_contact(value):
    """None for the impulse engine (``None`` or ``"impulse"``), else a :class:`HertzContact`
    (from ``"hertz"`` (the defaults), a HertzContact, or its :meth:`~HertzContact.to_spec`
    dict); PecletArgumentError naming ``contact`` otherwise."""
    if value is None or (isinstance(value, str) and value == "impulse"):
        return None
    if isinstance(value, HertzContact):
        return value
    if isinstance(value, str) and value == "hertz":
        return HertzContact()
    if isinstance(value, dict) and value.get("law") == "impulse" and len(value) == 1:
        return None
    if isinstance(value, dict) and value.get("law") == "hertz":
        kw = {k: v for k, v in value.items() if k != "law"}
        unknown = sorted(set(kw) - {"youngs", "poisson", "rayleigh_fraction"})
        if unknown:
            raise PecletArgumentError("contact", CONTACT_FORMS, value,
                                      f"unknown keys {unknown}")
        return HertzContact(**kw)
    raise PecletArgumentError("contact", CONTACT_FORMS, value)


def advance(sim, dt):
    """One protocol step of ``dt`` by the simulation's contact law: the impulse step
    (``Simulation.step``) unless ``Simulation.set_contact_law`` chose an explicit law, whose
    ``substeps`` then split ``dt`` (``Simulation.advance(1, dt / K)``: K substeps of dt / K).
    Reads the law from the simulation only, so a resumed one steps as it did."""
    engine = sim.contact_engine
    if engine.name == "impulse":
        sim.step(dt)
        return
    sim.advance(1, dt / int(engine.parameters["substeps"]))
