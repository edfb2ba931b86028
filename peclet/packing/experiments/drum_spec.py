"""The drum's parameters (:class:`DrumSpec`, each field's range declared once) and the
conversions between its speed as rpm and as a Froude number."""
from __future__ import annotations

import math
from dataclasses import dataclass

from peclet.core.spec import Choice, Custom, Float, Int, Spec, Text, field
from peclet.core.validation import PecletArgumentError, check_float

from .regimes import G

#: How the drum's ends are closed: end caps, or a periodic slice of a long drum.
ENDS = ("caps", "periodic")

#: Wall ribs (``ribs`` > 0): boxes along the axis centred on the wall, protruding
#: RIB_HEIGHT D into the drum, 2 RIB_HALF_WIDTH D wide (a rough wall: a bed of spheres
#: otherwise rolls on a smooth wall like a ball bearing instead of turning with it).
RIB_HEIGHT = 0.25
RIB_HALF_WIDTH = 0.1
#: Default rib spacing along the wall (D): ``ribs`` None gives round(2 pi R / RIB_SPACING).
RIB_SPACING = 1.25


def froude_of_rpm(rpm, radius_d, grain_mm):
    """Fr = omega^2 R / g of a drum of ``radius_d`` grain diameters of ``grain_mm`` mm."""
    om = 2.0 * math.pi * rpm / 60.0
    return om * om * radius_d * grain_mm * 1e-3 / G


def rpm_of_froude(fr, radius_d, grain_mm):
    return 60.0 / (2.0 * math.pi) * math.sqrt(fr * G / (radius_d * grain_mm * 1e-3))


def _speed(arg, value, c):
    """``froude`` or ``rpm`` (exactly one), as the Froude number (<= 100)."""
    spec = c.spec
    if (spec.froude is None) == (spec.rpm is None):
        raise PecletArgumentError(c.name("froude"), f"given, or {c.name('rpm')} (exactly one)",
                                  (spec.froude, spec.rpm))
    grain = c.value("grain_mm")
    if spec.froude is not None:
        return check_float(arg, spec.froude, 0.0, 100.0, True)
    rpm = check_float(c.name("rpm"), spec.rpm, 0.0, 1e5, True)
    fr = froude_of_rpm(rpm, c.value("radius"), grain)
    if not 0.0 < fr <= 100.0:          # 0: omega^2 R underflowed (rpm ~ 1e-160 and below)
        raise PecletArgumentError(c.name("rpm"), "a speed with Froude number in (0, 100]", rpm,
                                  f"Fr = {fr:.4g} for R = {c.value('radius'):g} D of "
                                  f"{grain:g} mm")
    return fr


@dataclass(frozen=True)
class DrumSpec(Spec):
    """A drum run (see the module notes). ``froude`` or ``rpm`` (exactly one); ``wall_mu`` and
    ``wall_e`` default to ``mu`` and ``e``; ``dt`` None: 4e-3 (spheres) or 2e-3 (elements),
    at most 0.05 D / (omega R); ``polydispersity`` p (spheres only): radii of 0.5 (1 - p),
    0.5 and 0.5 (1 + p) D in equal shares. :meth:`checked` (from :class:`~peclet.core.spec.
    Spec`) checks every field as declared here (PecletArgumentError naming ``names[field]``,
    e.g. the command line's flag) and resolves the defaults (``rpm`` to ``froude``)."""

    element: str = field("sphere", Text("'sphere' or a library element name"))
    radius: float = field(10.0, Float(3.0, 200.0))
    length: float = field(4.0, Float(1.0, 200.0))
    ends: str = field("caps", Choice(ENDS))
    fill: float = field(0.35, Float(0.0, 0.8, lo_open=True))
    froude: float | None = field(None, Custom(_speed))
    rpm: float | None = field(None, Custom(lambda arg, value, c: None))   # in froude now
    grain_mm: float = field(3.0, Float(0.0, 1e4, lo_open=True))
    mu: float = field(0.5, Float(0.0, 10.0))
    e: float = field(0.3, Float(0.0, 1.0))
    wall_mu: float | None = field(None, Float(0.0, 10.0, if_none=lambda c: c.value("mu")))
    wall_e: float | None = field(None, Float(0.0, 1.0, if_none=lambda c: c.value("e")))
    polydispersity: float = field(0.1, Float(0.0, 0.5, hi_open=True))
    revolutions: float = field(2.0, Float(0.0, 100.0, lo_open=True))
    warmup: float = field(1.0, Float(0.0, 100.0))
    spinup: float = field(0.0, Float(0.0, 3600.0))
    dt: float | None = field(None, Float(0.0, 0.02, lo_open=True, if_none=None))
    seed: int = field(1, Int(0, 2 ** 63 - 1))
    frames: int = field(24, Int(0, 10_000))
    snapshots: int = field(4, Int(1, 12))
    ribs: int | None = field(None, Int(0, 720, if_none=lambda c: int(round(
        2.0 * math.pi * c.value("radius") / RIB_SPACING))))

    @property
    def omega(self):
        """Angular speed (rad/time) of the checked spec."""
        return math.sqrt(self.froude * G / self.radius)
