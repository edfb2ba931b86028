"""The start of a run: the simulation with its container's walls, the start cloud of a pour and
the bodies inserted into it (the protocols of :mod:`peclet.packing.bed.protocols` call them)."""
from __future__ import annotations

import math

import numpy as np

from peclet.core.validation import PecletArgumentError

from .landing import check_gravity

def start_cloud(n, container, rng, y0=1.2, gap=1.55, dy=0.15, lookback=14, clearance=0.0,
                y_max=math.inf):
    """The page's loose non-overlapping start cloud and random orientations.

    Bodies are placed one by one at an (x, z) drawn by ``container.sample_xz`` (uniform in
    [0, L)^2 for the page's box) and the current height y (starting at ``y0``); a candidate
    is accepted if, against each of the last ``lookback`` accepted, it is more than ``gap``
    away horizontally OR vertically; otherwise y grows by ``dy``. Orientations are normalised
    4-D Gaussians (uniform on SO(3)). Returns (positions (n, 3), quaternions (n, 4)), drawn
    from ``rng`` in the page's order.

    The cloud stops at ``y_max`` (a closed container's ceiling for the clearance): a cloud
    that would rise above it is refused (PecletArgumentError naming "count") instead of
    climbing forever. In an open container the loop is bounded: each rejection raises y by
    ``dy``, and after ``gap / dy`` of them in a row y is ``gap`` above every earlier body, so
    the cloud is at most ``n (gap + dy)`` tall."""
    pos, y = [], float(y0)
    while len(pos) < int(n):
        if y > y_max:
            raise PecletArgumentError(
                "count", f"at most what the container holds: the start cloud reached its "
                f"ceiling y = {y_max:.3f} after {len(pos)} elements", int(n))
        xz = container.sample_xz(rng, clearance, y)
        if xz is None:
            y += dy
            continue
        c = np.array([xz[0], y, xz[1]])
        if all(np.linalg.norm((c - q)[[0, 2]]) > gap or abs(c[1] - q[1]) > gap
               for q in pos[-lookback:]):
            pos.append(c)
        else:
            y += dy
    quat = rng.normal(size=(int(n), 4))
    quat /= np.linalg.norm(quat, axis=1)[:, None]
    return np.asarray(pos, dtype=np.float64), quat


def insert_bodies(sim, body, pos, quat, vel):
    """Append bodies (positions, quaternions, velocities) to ``sim`` (N grows; the bodies
    already in keep their state and, under an explicit law such as Hertz, their contact
    histories (``Simulation.keep_contact_histories``); the impulse engine's warm-start cache
    is cleared, as any change of N does)."""
    n0 = sim.num_particles()
    if n0:
        P = np.vstack([sim.get_positions(), pos])
        Q = np.vstack([sim.get_quaternions(), quat])
        V = np.vstack([sim.get_velocities(), vel])
        W = np.vstack([sim.get_angular_velocities(), np.zeros((len(pos), 3))])
    else:
        P, Q, V, W = pos, quat, vel, np.zeros((len(pos), 3))
    n = len(P)
    sim.set_positions(P)
    sim.set_shape_ids(np.full(n, body.shape_id, np.int32))
    sim.set_quaternions(Q)
    sim.set_inv_mass(np.full(n, 1.0 / body.mass))
    sim.set_inv_inertia(np.tile(np.asarray(body.inv_inertia, float), (n, 1)))
    if n0 or np.any(vel):
        sim.set_velocities(V)
        sim.set_angular_velocities(W)
    if n0:
        sim.keep_contact_histories()


def new_simulation(register, container, material, wall_material, iterations, gravity, dt,
                   y_top, count):
    """A Simulation set up as the page does (domain, periodicity, gravity, materials, solver
    sweeps, the shape via ``register(sim)``, the container's walls, dt). ``gravity`` is the
    magnitude of g (length/time^2, > 0: :func:`check_gravity`), acting along -y towards the
    floor. Returns (sim, sid)."""
    from peclet.dem import Simulation

    gravity = check_gravity(gravity)

    sim = Simulation(count + 8)
    lo, hi = container.domain(y_top)
    sim.set_domain(lo, hi)
    px, pz = container.periodic
    sim.enable_periodicity(px, False, pz)
    sim.set_gravity(0.0, -float(gravity), 0.0)
    sim.set_material_params(*material.as_tuple())
    sim.set_solver_iterations(*iterations)
    sid = register(sim)
    container.add_walls(sim, wall_material, y_top)
    sim.set_dt(dt)
    return sim, sid
