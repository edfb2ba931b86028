"""The linear spring-dashpot law (peclet.dem.linear) against its closed forms.

    python -m validation.linear_law

Protocol (Chung & Ooi 2011, tests 1 and 2, for the linear law instead of Hertz's): a sphere of
radius 0.5 m and mass 1 kg meets a rigid flat wall (test 1) or an identical sphere (test 2)
head-on at 1 m/s relative speed, no gravity, no friction, k_n = 1e5 N/m; restitution e over
[0, 1]. Measured: the coefficient of restitution (separation over approach speed), the contact
time (the overlap's zero crossings, interpolated linearly between steps) and the largest
overlap, each beside the closed form of the damped oscillator ``m* delta'' + c_n delta' + k_n
delta = 0`` (the notes of :mod:`peclet.dem.linear`), at ``steps`` steps per undamped contact
time. Prints our figure beside the reference; the tests (tests/test_dem_linear.py) assert them.
"""
from __future__ import annotations

import math

import numpy as np

RADIUS, MASS, KN, SPEED = 0.5, 1.0, 1e5, 1.0


def _floor(sim):
    from peclet.core import geom
    b = geom.SceneBuilder()
    root = b.add_leaf("box", [5.0, 5.0, 5.0], translation=[0.0, -5.0, 0.0])
    ni, nr, _, _ = b.encode()
    sim.add_analytic_wall(ni, nr, root, False, 0.5, 0.0)


def impact(e, wall, steps=400, threads=1):
    """One normal impact (module notes): returns a dict of the measured ``e``, ``t_contact``
    (s) and ``max_overlap`` (m) and their closed forms ``*_ref``."""
    import numba

    from peclet.dem import Simulation
    from peclet.dem.linear import contact_time, max_overlap
    before = numba.get_num_threads()
    numba.set_num_threads(threads)
    try:
        sim = Simulation(2)
        sim.add_sphere_shape(RADIUS)
        gap0 = 0.0          # touching at t = 0, as in Chung & Ooi: the contact starts on a step
        if wall:
            _floor(sim)
            sim.set_wall_material_id(0, 1)
            sim.set_positions([[0.0, RADIUS + gap0, 0.0]])
            sim.set_velocities([[0.0, -SPEED, 0.0]])
            sim.set_inv_mass([1.0 / MASS])
            mstar = MASS
        else:
            sim.set_positions([[0.0, 0.0, 0.0], [2 * RADIUS + gap0, 0.0, 0.0]])
            sim.set_velocities([[0.5 * SPEED, 0.0, 0.0], [-0.5 * SPEED, 0.0, 0.0]])
            sim.set_inv_mass([1.0 / MASS] * 2)
            mstar = MASS / 2
        sim.set_shape_ids([0] * sim.num_particles())
        sim.set_material_ids([1] * sim.num_particles())
        sim.set_pair_material(1, 1, e, 0.0, 0.0)
        sim.set_contact_law("linear", kn=KN)
        t0 = math.pi * math.sqrt(mstar / KN)
        dt = t0 / steps

        def overlap_speed():
            x, v = sim.get_positions(), sim.get_velocities()
            if wall:
                return RADIUS - x[0, 1], -v[0, 1]
            return 2 * RADIUS - (x[1, 0] - x[0, 0]), v[0, 0] - v[1, 0]

        t, d_prev = 0.0, overlap_speed()[0]
        start = end = None
        dmax = 0.0
        limit = 12 * steps
        for _ in range(limit):
            sim.advance(1, dt)
            t += dt
            d, _ = overlap_speed()
            if start is None and d > 0.0:
                start = t - dt * d / (d - d_prev)
            if start is not None and d <= 0.0 < d_prev:
                end = t - dt * d / (d - d_prev)
                break
            dmax = max(dmax, d)
            d_prev = d
        e_meas = -overlap_speed()[1] / SPEED if end is not None else max(0.0, -overlap_speed()[1])
        return {"e": e_meas, "e_ref": e, "t_contact": (end - start) if end else math.inf,
                "t_contact_ref": contact_time(KN, mstar, e), "max_overlap": dmax,
                "max_overlap_ref": max_overlap(SPEED, KN, mstar, e), "dt": dt}
    finally:
        numba.set_num_threads(before)


def main():
    print(__doc__.split("\n\n")[2])
    print(f"{'test':<14}{'e':>6}{'e ours':>12}{'t_c ours (s)':>15}{'t_c closed':>14}"
          f"{'d_max ours (m)':>16}{'d_max closed':>15}")
    for wall in (True, False):
        for e in (0.0, 0.1, 0.3, 0.5, 0.7, 0.9, 1.0):
            r = impact(e, wall)
            print(f"{'1 sphere-wall' if wall else '2 sphere-sphere':<14}{e:>6.2f}"
                  f"{r['e']:>12.5f}{r['t_contact']:>15.6g}{r['t_contact_ref']:>14.6g}"
                  f"{r['max_overlap']:>16.6g}{r['max_overlap_ref']:>15.6g}")


if __name__ == "__main__":
    np.set_printoptions(precision=6)
    main()
