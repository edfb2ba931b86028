"""The Chung & Ooi (2011) single-contact benchmarks as data, and their closed forms.

Reference: Y.C. Chung and J.Y. Ooi, "Benchmark tests for verifying discrete element modelling
codes at particle impact level", Granular Matter 13:643-656 (2011). The materials and speeds
are those of the public implementations of the benchmark (Yade's check scripts for tests 1-4,
Kratos DEM's nightly benchmark class for tests 5-8; validation/chung_ooi.py lists where each
value was read and which were our choice).

Frame and sign conventions (SI: m, s, kg, N, rad/s): the contact normal is +x. Sphere 0
starts at -x moving +x; sphere 1 (if any) starts at +x; a rigid plane (``wall``) fills x > 0.
Tangential motion is along y and spins are about z, so the contact-point slip of sphere 0 on
the plane is ``v_y + w_z R``. Stdlib and numpy only (no engine import).

Closed forms. Elastic Hertz impact at approach speed v (m*, R*, E* effective; 1/E* = sum
(1 - nu^2)/E; a rigid plane adds nothing)::

    delta_max = (15 m* v^2 / (16 E* sqrt(R*)))^(2/5),  f_max = 4/3 E* sqrt(R*) delta_max^(3/2)
    t_c = 2 (delta_max / v) int_0^1 dx / sqrt(1 - x^(5/2))

Elastic linear (Hooke) impact of stiffness k_n: delta_max = v sqrt(m*/k_n), f_max = k_n
delta_max, t_c = pi sqrt(m*/k_n). Oblique and spinning impacts (tests 4-8): the rigid-body
impulse theory, exact for ANY normal force history while the contact slides throughout
(tangential impulse = mu x normal impulse = mu m* (1 + e) v_n), see :func:`sliding`.
"""
from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field

__all__ = ["MATERIALS", "TC_CONSTANT", "SLIDE_MARGIN", "Ball", "Impact", "effective",
           "hertz_elastic", "hooke_elastic", "sliding", "secant_stiffness",
           "compressive_restitution", "slip", "slides"]


def _tc_integral(n=20000):
    """2 int_0^1 (1 - x^2.5)^-1/2 dx, by the substitution x = 1 - s^2 (which removes the
    endpoint singularity) and the midpoint rule in s: 1e-9 relative at n = 20000."""
    total = 0.0
    for i in range(n):
        s = (i + 0.5) / n
        x = 1.0 - s * s
        total += 2.0 * s / math.sqrt(1.0 - x ** 2.5)
    return 2.0 * total / n


#: t_c = TC_CONSTANT (m*^2 / (R* E*^2 v))^(1/5) of an elastic Hertz impact (2.8683...)
TC_CONSTANT = _tc_integral() * (15.0 / 16.0) ** 0.4
#: an oblique row is scored only where the incoming slip is this many times the rigid theory's
#: sliding threshold (the Mindlin spring's compliance makes a near-threshold contact stick
#: for a while, where no closed form exists; Chung & Ooi compare with FEM there)
SLIDE_MARGIN = 1.3

#: name -> (Young's modulus Pa, Poisson ratio, density kg/m^3)
MATERIALS = {
    "glass": (4.8e10, 0.20, 2800.0), "limestone": (2.0e10, 0.25, 2500.0),
    "aluminium_alloy_t2": (7.0e10, 0.30, 2699.0), "magnesium_alloy": (4.0e10, 0.35, 1800.0),
    "aluminium_oxide": (3.8e11, 0.23, 4000.0), "cast_iron": (1.0e11, 0.25, 7000.0),
    "aluminium_alloy": (7.0e10, 0.33, 2700.0), "steel": (2.08e11, 0.30, 7850.0),
    "polyethylene": (1.0e9, 0.40, 1400.0), "nylon": (2.5e9, 0.40, 1000.0),
}


@dataclass(frozen=True)
class Ball:
    """One solid sphere: radius (m), Young's modulus (Pa), Poisson ratio, density (kg/m^3),
    and its initial centre (m), velocity (m/s) and angular velocity (rad/s), world frame."""

    radius: float
    youngs: float
    poisson: float
    density: float
    x: tuple
    v: tuple
    w: tuple = (0.0, 0.0, 0.0)

    @property
    def mass(self):
        return self.density * 4.0 / 3.0 * math.pi * self.radius ** 3

    @property
    def inertia(self):
        return 0.4 * self.mass * self.radius ** 2

    @classmethod
    def of(cls, material, radius, x, v, w=(0.0, 0.0, 0.0)):
        ym, nu, rho = MATERIALS[material]
        return cls(radius, ym, nu, rho, tuple(x), tuple(v), tuple(w))


@dataclass(frozen=True)
class Impact:
    """One benchmark impact, run to separation by the engine under certification.

    ``balls``: one sphere against the rigid plane x > 0 (``wall``) or two spheres; ``e`` the
    normal restitution asked for, ``mu`` the sliding friction; ``dt`` (s) the step, a fraction
    of the elastic Hertz contact time (the benchmark's practice); ``kn`` (N/m) the normal
    stiffness an engine with a linear (Hooke) law uses: the secant stiffness f_max/delta_max
    of the Hertz impact, so both laws see comparable overlaps. ``test`` is the benchmark's
    number (1-8), ``label`` says what it is; ``needs`` the capabilities it asks of an engine
    (:data:`peclet_verify.impact.backend.CAPABILITIES`)."""

    test: int
    balls: tuple
    wall: bool
    e: float
    mu: float
    dt: float
    kn: float
    needs: frozenset = field(default_factory=frozenset)
    label: str = ""

    @property
    def approach(self):
        """The normal approach speed (m/s, > 0 towards contact)."""
        v0 = self.balls[0].v[0]
        return v0 if self.wall else v0 - self.balls[1].v[0]

    def effective(self):
        """(m*, R*, E*) of the contact (kg, m, Pa)."""
        return effective(self.balls[:1] if self.wall else self.balls[:2])

    def to_json(self) -> str:
        """The case as JSON (floats round-trip exactly), for an engine in another process."""
        d = asdict(self)
        d["needs"] = sorted(self.needs)
        return json.dumps(d)

    @classmethod
    def from_json(cls, text: str) -> "Impact":
        """The inverse of :meth:`to_json`."""
        d = json.loads(text)
        d["balls"] = tuple(Ball(**{k: tuple(v) if isinstance(v, list) else v
                                   for k, v in b.items()}) for b in d["balls"])
        d["needs"] = frozenset(d["needs"])
        return cls(**d)

    def __repr__(self):
        balls = ", ".join(f"Ball({b.radius!r}, {b.youngs!r}, {b.poisson!r}, {b.density!r}, "
                          f"{b.x!r}, {b.v!r}, {b.w!r})" for b in self.balls)
        return (f"Impact(test={self.test}, balls=({balls},), wall={self.wall}, e={self.e!r}, "
                f"mu={self.mu!r}, dt={self.dt!r}, kn={self.kn!r}, "
                f"needs=frozenset({sorted(self.needs)!r}), label={self.label!r})")


def effective(balls):
    """(m*, R*, E*) of two balls or one ball and a rigid plane (kg, m, Pa)."""
    inv_m = inv_r = ce = 0.0
    for b in balls:
        inv_m += 1.0 / b.mass
        inv_r += 1.0 / b.radius
        ce += (1.0 - b.poisson ** 2) / b.youngs
    return 1.0 / inv_m, 1.0 / inv_r, 1.0 / ce


def hertz_elastic(m, r, e, v):
    """delta_max (m), f_max (N) and contact_time (s) of an elastic Hertz impact of effective
    mass ``m``, radius ``r`` and modulus ``e`` at approach speed ``v``."""
    dmax = (15.0 * m * v * v / (16.0 * e * math.sqrt(r))) ** 0.4
    return {"delta_max": dmax, "f_max": 4.0 / 3.0 * e * math.sqrt(r) * dmax ** 1.5,
            "contact_time": TC_CONSTANT * (m * m / (r * e * e * v)) ** 0.2}


def hooke_elastic(m, kn, v):
    """delta_max (m), f_max (N) and contact_time (s) of an elastic linear impact of effective
    mass ``m`` and stiffness ``kn`` at approach speed ``v``."""
    omega = math.sqrt(kn / m)
    return {"delta_max": v / omega, "f_max": kn * v / omega, "contact_time": math.pi / omega}


def secant_stiffness(m, r, e, v):
    """f_max / delta_max (N/m) of the elastic Hertz impact: the linear law's stiffness."""
    h = hertz_elastic(m, r, e, v)
    return h["f_max"] / h["delta_max"]


def sliding(b1, b2, vn, slip, mu, e):
    """The rigid theory of a contact that slides throughout: ball ``b1`` hits ball ``b2`` (or
    the plane, ``b2`` None) at normal speed ``vn``, contact-point slip ``slip`` along +y.
    Returns (dv1_y, dw1_z, dv2_y, dw2_z, dslip, threshold): the changes of velocity and spin,
    of the slip, and the incoming |slip| at or above which the contact slides throughout."""
    m1, i1, r1 = b1.mass, b1.inertia, b1.radius
    inv = 1.0 / m1 + (0.0 if b2 is None else 1.0 / b2.mass)
    pn = (1.0 + e) * vn / inv
    pt = -mu * pn * math.copysign(1.0, slip)      # impulse on ball 1 along y
    dv1, dw1 = pt / m1, r1 * pt / i1              # torque (R, 0, 0) x (0, Pt, 0) along z
    k = 1.0 / m1 + r1 * r1 / i1
    dv2 = dw2 = 0.0
    if b2 is not None:
        dv2, dw2 = -pt / b2.mass, b2.radius * pt / b2.inertia
        k += 1.0 / b2.mass + b2.radius ** 2 / b2.inertia
    return dv1, dw1, dv2, dw2, pt * k, mu * pn * k


def compressive_restitution(e):
    """For a linear spring-dashpot whose dashpot may pull (no clamp of the normal force at 0):
    the compressive normal impulse over m* v, minus 1. The force k delta + c delta' = -m*
    delta'' changes sign where delta'' = 0, at omega_d t* = atan2(2 zeta s, 2 zeta^2 - 1) (s =
    sqrt(1 - zeta^2), zeta = -ln e / sqrt(pi^2 + ln^2 e)); the impulse up to then is m* (v -
    delta'(t*)), so this is -delta'(t*) / v = -exp(-zeta theta / s) (cos theta - zeta / s
    sin theta), >= e (equal at e = 1; e^-2 at e = 0, critical damping). A Coulomb friction
    limited by the compressive force gives a sliding contact this tangential impulse. The same
    function holds for a Hertz spring with the Tsuji-form dashpot (coefficient ~ delta^(1/4)),
    checked by integrating that impact (tests/test_verify_impact.py, 1e-8 at e = 0.5)."""
    if e >= 1.0:
        return 1.0
    if e <= 0.0:
        return math.exp(-2.0)
    le = math.log(e)
    zeta = -le / math.sqrt(math.pi ** 2 + le * le)
    s = math.sqrt(1.0 - zeta * zeta)
    theta = math.atan2(2.0 * zeta * s, 2.0 * zeta * zeta - 1.0)
    return -math.exp(-zeta * theta / s) * (math.cos(theta) - zeta / s * math.sin(theta))


def slip(case):
    """The incoming contact-point slip along +y of ball 0 relative to ball 1 or the plane (m/s):
    v0_y + w0_z R0 - (v1_y - w1_z R1)."""
    b = case.balls
    s = b[0].v[1] + b[0].w[2] * b[0].radius
    return s if case.wall else s - (b[1].v[1] - b[1].w[2] * b[1].radius)


def slides(case, e=None):
    """True where the incoming slip is at least SLIDE_MARGIN x the rigid theory's sliding
    threshold, for a normal impulse m* v (1 + e) (default the case's e; an engine whose
    friction is limited by a larger, compressive impulse needs a larger slip)."""
    s = slip(case)
    b = case.balls
    thr = sliding(b[0], None if case.wall else b[1], case.approach, s or 1.0, case.mu,
                  case.e if e is None else e)[5]
    return abs(s) >= SLIDE_MARGIN * thr

