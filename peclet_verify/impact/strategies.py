"""The eight Chung & Ooi benchmarks as Hypothesis strategies over their parameter ranges.

Each ``caseN(...)`` builds one :class:`~peclet_verify.impact.cases.Impact` from the benchmark's
parameters; each strategy (``TESTS[n]``) draws those parameters on a grid (a failure shrinks to
the grid's first point in a few steps). The ranges are the benchmark's, except where stated:

1. two identical spheres, elastic, glass or limestone, R 0.01 m, each at v (the benchmark: 10
   m/s; here v in 2.5-20 m/s): delta_max, f_max, t_c of the normal model;
2. a sphere on a rigid plane, elastic, aluminium alloy or magnesium alloy, R 0.1 m, v (0.2
   m/s; here 0.05-0.8): the same figures;
3. a sphere on a plane over e in [0.2, 1] (the benchmark: 3.9 m/s; here also 0.39-39 m/s, so
   that a damping whose restitution depends on speed is seen): rebound / approach = e;
4. oblique impact at 3.9 m/s, incident angle 5-85 deg (only the angles where the contact slides
   throughout are drawn: the closed form holds there, Chung & Ooi compare with FEM below);
5. oblique impact at v_n 5 m/s, v_t / (mu v_n) up to 14 (sliding part), steel or polyethylene;
6. a spinning sphere dropped on a plane at v_n 0.2 m/s, R w / v_n up to 7 (sliding part);
7. two identical spheres at 0.2 m/s each, both spinning at w (sliding part, up to 21 rad/s);
8. unequal spheres (R 0.1 and 0.2 m), the smaller at 0.2 m/s and spinning (sliding part).

Steps: dt = t_c / 500 of the elastic Hertz impact (the benchmark's resolution; validation/
chung_ooi.py runs 2000 for its figures).
"""
from __future__ import annotations

import math

from hypothesis import strategies as st

from .cases import Ball, Impact, effective, hertz_elastic, secant_stiffness, slides

__all__ = ["STEPS", "impact_case", "case1", "case2", "case3", "case4", "case5", "case6",
           "case7", "case8", "TESTS"]

#: steps per elastic Hertz contact time
STEPS = 500


def impact_case(test, balls, wall, e, mu, needs, label, steps=STEPS):
    """The :class:`Impact` of ``balls`` (sphere 0 first, moving +x), its dt from the elastic
    Hertz contact time over ``steps`` and its linear stiffness the Hertz secant one."""
    m, r, es = effective(balls[:1] if wall else balls)
    v = balls[0].v[0] - (0.0 if wall else balls[1].v[0])
    dt = hertz_elastic(m, r, es, v)["contact_time"] / steps
    return Impact(test, tuple(balls), wall, float(e), float(mu), dt,
                  secant_stiffness(m, r, es, v), frozenset(needs), label)


def _pair(material, r1, r2, v1, v2, w1=0.0, w2=0.0):
    """Two balls touching at x = 0 (sphere 0 at -x)."""
    return (Ball.of(material, r1, (-r1, 0.0, 0.0), (v1, 0.0, 0.0), (0.0, 0.0, w1)),
            Ball.of(material, r2, (r2, 0.0, 0.0), (v2, 0.0, 0.0), (0.0, 0.0, w2)))


def _on_plane(material, r, vn, vt=0.0, w=0.0):
    """A ball touching the plane x = 0 from -x."""
    return (Ball.of(material, r, (-r, 0.0, 0.0), (vn, vt, 0.0), (0.0, 0.0, w)),)


def case1(material, v):
    return impact_case(1, _pair(material, 0.01, 0.01, v, -v), False, 1.0, 0.0,
                       {"sphere_sphere"}, f"elastic normal impact of two spheres of {material}")


def case2(material, v):
    return impact_case(2, _on_plane(material, 0.1, v), True, 1.0, 0.0, {"sphere_wall"},
                       f"elastic normal impact of a sphere of {material} on a rigid plane")


def case3(material, e, v):
    return impact_case(3, _on_plane(material, 0.0025, v), True, e, 0.0,
                       {"sphere_wall", "restitution"},
                       f"normal impact of a sphere of {material} on a plane, e = {e!r}, v = {v:.4g} m/s")


def case4(material, angle_deg):
    a = math.radians(angle_deg)
    return impact_case(4, _on_plane(material, 0.0025, 3.9 * math.cos(a), 3.9 * math.sin(a)),
                       True, 0.98, 0.092, {"sphere_wall", "restitution", "friction"},
                       f"oblique impact of a sphere of {material} at {angle_deg} deg")


def case5(material, psi):
    return impact_case(5, _on_plane(material, 0.010, 5.0, psi * 0.3 * 5.0), True, 1.0, 0.3,
                       {"sphere_wall", "friction"},
                       f"oblique impact of a sphere of {material}, v_t / (mu v_n) = {psi!r}")


def case6(material, tan_in):
    return impact_case(6, _on_plane(material, 0.1, 0.2, 0.0, tan_in * 0.2 / 0.1), True, 0.5,
                       0.4, {"sphere_wall", "restitution", "friction", "spin"},
                       f"a sphere of {material} spinning at R w / v_n = {tan_in!r} on a plane")


def case7(material, w):
    return impact_case(7, _pair(material, 0.1, 0.1, 0.2, -0.2, w, w), False, 0.5, 0.4,
                       {"sphere_sphere", "restitution", "friction", "spin"},
                       f"two spheres of {material}, both spinning at {w!r} rad/s")


def case8(material, w):
    return impact_case(8, _pair(material, 0.1, 0.2, 0.2, 0.0, w, 0.0), False, 0.5, 0.4,
                       {"sphere_sphere", "unequal_spheres", "restitution", "friction", "spin"},
                       f"unequal spheres of {material}, the smaller spinning at {w!r} rad/s")


def _sliding_grid(build, material, grid):
    """The points of ``grid`` where ``build(material, x)`` slides throughout."""
    return [x for x in grid if slides(build(material, x))]


def _oblique(build, materials, grid):
    pairs = [(m, x) for m in materials for x in _sliding_grid(build, m, grid)]
    return st.sampled_from(pairs).map(lambda p: build(*p))


def _speeds(nominal, lo, hi):
    """Speeds nominal x 2^(k/4) within [lo, hi] x nominal, the nominal first."""
    ks = [k for k in range(-12, 13) if lo <= 2 ** (k / 4) <= hi]
    return st.sampled_from(sorted(ks, key=abs)).map(lambda k: nominal * 2 ** (k / 4))


#: test number -> strategy of its cases
TESTS = {
    1: st.builds(case1, st.sampled_from(("glass", "limestone")), _speeds(10.0, 0.25, 2.0)),
    2: st.builds(case2, st.sampled_from(("aluminium_alloy_t2", "magnesium_alloy")),
                 _speeds(0.2, 0.25, 4.0)),
    3: st.builds(case3, st.sampled_from(("aluminium_oxide", "cast_iron")),
                 st.integers(2, 10).map(lambda k: k / 10), _speeds(3.9, 0.1, 10.0)),
    4: _oblique(case4, ("aluminium_oxide", "aluminium_alloy"), range(5, 86)),
    5: _oblique(case5, ("steel", "polyethylene"), [k / 2 for k in range(1, 29)]),
    6: _oblique(case6, ("aluminium_alloy", "nylon"), [k / 4 for k in range(1, 29)]),
    7: _oblique(case7, ("aluminium_alloy", "nylon"), [k / 2 for k in range(1, 43)]),
    8: _oblique(case8, ("aluminium_alloy", "nylon"), [k / 2 for k in range(1, 43)]),
}
