"""A kidney bean as a Python callable phi(points): a tapered swept arc (issue 41's gallery page).

    python examples/bean.py [--spacing 0.02] [--out bean.npz]

writes ``bean.npz`` (a grid saved by :func:`peclet.core.geom.grids.save_grid`, made by
:func:`peclet.core.geom.grids.grid_from_callable` from :func:`bean_phi`) and prints the bean's
exact volume; then ``peclet pack --element bean.npz ...`` packs it.

The bean (lengths in the bean's own unit; the arc in the x-y plane, about the z axis through
the origin; cylindrical coordinates rho, theta (from +x), z):

- ``ARC_RADIUS`` R = 0.45: the radius of the arc the tube is swept along;
- ``HALF_ANGLE`` Theta = 65 degrees: the arc spans theta in [-Theta, Theta];
- ``TUBE_RADIUS`` r_m = 0.20 and ``TAPER`` delta = 0.03: the tube's radius
  r(theta) = r_m + delta sin(pi theta / (2 Theta)) tapers from 0.23 at theta = +Theta to 0.17
  at -Theta, flat (dr/dtheta = 0) at both ends;
- the solid is the union of the meridian discs (rho - R)^2 + z^2 <= r(theta)^2, |theta| <=
  Theta (a "tapered swept arc"), and of the two end balls of radius r(+-Theta) centred on the
  arc's ends (the rounded ends).

phi = min(sqrt((rho - R)^2 + z^2) - r(theta) [|theta| <= Theta], |p - e+| - r(Theta),
|p - e-| - r(-Theta)): the exact zero set, continuous (on the end planes the tube's value is
the ball's), a distance to within |grad phi| <= sqrt(1 + (r' / rho)^2) <= 1.02 near the tube.

Exact volume (Pappus). Each meridian disc of radius r(theta) has its centroid on the arc, at
distance R from the axis, so the tube is V_tube = integral over theta of pi r(theta)^2 R dtheta
(exact while R > r, the discs then never meet). With r = r_m + delta sin(u), u = pi theta /
(2 Theta), the cross term is odd and sin^2 averages 1/2 over the symmetric range:
V_tube = 2 pi R Theta (r_m^2 + delta^2 / 2). Each end ball is cut in halves by its end's
meridian plane (which passes through its centre): the outer half lies beyond the tube, the
inner half inside it (dr/dtheta = 0 at the ends and R (R - r_e) / r_e >= delta (pi / 2
Theta)^2, so the ball's section in a nearby meridian plane stays inside the tube's; checked by
sampling in validation/bean.py). So V = V_tube + 2/3 pi (r(Theta)^3 + r(-Theta)^3)
= 2 pi R Theta (r_m^2 + delta^2 / 2) + 4/3 pi (r_m^3 + 3 r_m delta^2) = 0.165521 (to 6 digits)

The centre of mass and moments (:func:`reference_properties`) come from the same
decomposition: each meridian disc's moments in closed form, theta integrated by Gauss-Legendre
(the integrand is analytic: 48 and 96 nodes agree to round-off), the half balls' moments in
closed form. validation/bean.py checks them, and the decomposition, against Monte Carlo.
"""
from __future__ import annotations

import math
import sys

import numpy as np

ARC_RADIUS = 0.45
HALF_ANGLE = math.radians(65.0)
TUBE_RADIUS = 0.20
TAPER = 0.03


def tube_radius(theta):
    """r(theta), the tube's radius at arc angle ``theta`` (radians, in [-Theta, Theta])."""
    return TUBE_RADIUS + TAPER * np.sin(0.5 * math.pi * np.asarray(theta) / HALF_ANGLE)


def _ends():
    """(centre (3,), radius, outward unit tangent (3,)) of the two end balls (+Theta, -Theta)."""
    out = []
    for s in (1.0, -1.0):
        t = s * HALF_ANGLE
        c = ARC_RADIUS * np.array([math.cos(t), math.sin(t), 0.0])
        n = s * np.array([-math.sin(t), math.cos(t), 0.0])
        out.append((c, float(tube_radius(t)), n))
    return out


def bean_phi(points):
    """phi of the bean (module notes) at ``points`` (N, 3), bean units: < 0 inside."""
    p = np.asarray(points, dtype=np.float64)
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    rho = np.hypot(x, y)
    theta = np.arctan2(y, x)
    tube = np.hypot(rho - ARC_RADIUS, z) - tube_radius(np.clip(theta, -HALF_ANGLE, HALF_ANGLE))
    phi = np.where(np.abs(theta) <= HALF_ANGLE, tube, np.inf)
    for c, r, _ in _ends():
        phi = np.minimum(phi, np.linalg.norm(p - c, axis=1) - r)
    return phi


def bounds():
    """(lo (3,), hi (3,)): a box holding the bean."""
    r = TUBE_RADIUS + TAPER
    R, T = ARC_RADIUS, HALF_ANGLE
    return (np.array([R * math.cos(T) - r, -(R * math.sin(T) + r), -r]),
            np.array([R + r, R * math.sin(T) + r, r]))


def exact_volume():
    """The bean's volume in closed form (module notes), bean units^3."""
    R, T, rm, dl = ARC_RADIUS, HALF_ANGLE, TUBE_RADIUS, TAPER
    return 2.0 * math.pi * R * T * (rm * rm + 0.5 * dl * dl) \
        + 4.0 / 3.0 * math.pi * (rm ** 3 + 3.0 * rm * dl * dl)


def _raw_moments(nodes):
    """(volume, first moments (3,), second moments (3, 3) about the origin) of the bean."""
    R = ARC_RADIUS
    u, w = np.polynomial.legendre.leggauss(nodes)
    th, w = u * HALF_ANGLE, w * HALF_ANGLE
    r = tube_radius(th)
    A = math.pi * r * r
    rho1 = A * R                                   # disc integrals of rho, rho^2, rho^3, rho z^2
    rho2 = A * (R * R + 0.25 * r * r)
    rho3 = A * (R ** 3 + 0.75 * R * r * r)
    rz2 = A * R * 0.25 * r * r
    c, s = np.cos(th), np.sin(th)
    V = float(w @ rho1)
    m1 = np.array([w @ (c * rho2), w @ (s * rho2), 0.0])
    m2 = np.zeros((3, 3))
    m2[0, 0], m2[1, 1], m2[2, 2] = w @ (c * c * rho3), w @ (s * s * rho3), w @ rz2
    m2[0, 1] = m2[1, 0] = w @ (s * c * rho3)
    for e, a, n in _ends():                        # the outer half balls
        v = 2.0 / 3.0 * math.pi * a ** 3
        first = v * 0.375 * a * n                  # about the ball's centre
        V += v
        m1 += v * e + first
        m2 += 2.0 * math.pi / 15.0 * a ** 5 * np.eye(3) + v * np.outer(e, e) \
            + np.outer(e, first) + np.outer(first, e)
    return V, m1, m2


def properties_from_moments(V, m1, m2):
    """dict(volume, com (3,), inertia (3, 3) about the com at unit density, i_over_m (3,)
    ascending principal moments over the mass) from raw moments about the origin."""
    com = m1 / V
    S = m2 - V * np.outer(com, com)
    inertia = np.trace(S) * np.eye(3) - S
    return dict(volume=float(V), com=com, inertia=inertia,
                i_over_m=np.sort(np.linalg.eigvalsh(inertia)) / V)


def reference_properties(nodes=96):
    """The bean's mass properties at unit density (module notes): semi-analytic reference."""
    return properties_from_moments(*_raw_moments(nodes))


def make_grid(builder, spacing):
    """The bean as a grid leaf of ``builder`` at ``spacing`` (bean units); its node index."""
    from peclet.core.geom import grids

    lo, hi = bounds()
    return grids.grid_from_callable(builder, bean_phi, lo, hi, spacing)


def grid_arrays(builder, leaf):
    """(values (nx, ny, nz), spacing, origin (3,)) of a grid leaf, for ``save_grid``."""
    from peclet.core.geom.sampled import grid_values

    ni, nr, _, _ = builder.encode()
    _, _, _, params, t, _, _ = builder.node(leaf)
    values = grid_values(ni[:, 0], nr, params, leaf)
    h = float(params[4])
    return values, h, t - 0.5 * (np.array(values.shape) - 1) * h


def save_bean(path, spacing=0.02):
    """Write the bean's grid at ``spacing`` to ``path`` (grid_from_callable + save_grid)."""
    from peclet.core import geom
    from peclet.core.geom import grids

    b = geom.SceneBuilder()
    values, h, origin = grid_arrays(b, make_grid(b, spacing))
    return grids.save_grid(path, values, h, origin)


def main(argv=None):
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spacing", type=float, default=0.02, help="grid spacing (default 0.02)")
    ap.add_argument("--out", default="bean.npz", help="output .npz (default bean.npz)")
    a = ap.parse_args(argv)
    ref = reference_properties()
    print(f"bean: exact volume {exact_volume():.6f}, com {np.round(ref['com'], 6).tolist()}, "
          f"I/m {np.round(ref['i_over_m'], 6).tolist()}")
    print("wrote", save_bean(a.out, a.spacing))
    return 0


if __name__ == "__main__":
    sys.exit(main())
