"""The impulse engine: the velocity-level step of docs/architecture.md §6 and the overlap relaxer.

One step: predict (gravity, external forces and torques) -> guards -> detection (broad and narrow
phase with speculative margins, a moving wall's surface speed included) -> materials per
contact -> velocity solve (PGS, Coulomb cone, restitution relative to a moving wall's surface,
warm start, speculative contacts) -> integrate (x += v dt; torque-free rotation) -> position
projection (translation AND rotation) -> guards -> :meth:`World.commit`. Its per-contact state
is the warm-start cache (``world.warm``: impulses per contact key), which persistence saves.
"""
from __future__ import annotations

import time

import numpy as np

from peclet.core.geom.transforms import quats_to_matrices
from peclet.core.validation import check_int
from peclet.dem import solver
from peclet.dem.contacts import WarmStart, body_reach, lever_arms, reorder
from peclet.dem.materials import per_contact
from peclet.dem.rigid import advance_all, advance_rotations

#: From this many bodies the step turns them, and finds their world inverse inertias, in
#: parallel (rigid.advance_rotations, solver.world_inv_inertias_parallel: the same bits as the
#: serial loops).
PARALLEL_ROTATION_BODIES = 4000

#: Bounds on work a call can ask for: Gauss-Seidel sweeps per step or relaxation passes.
MAX_SOLVER_ITERATIONS = 10_000


class ImpulseEngine:
    """The impulse (PGS) contact engine (:func:`step`); no parameters. Its history is the
    warm-start cache the world owns, saved by :mod:`peclet.dem.persistence` as always."""

    name = "impulse"
    parameters = {}

    def step(self, world, dt):
        step(world, dt)

    def history(self, world):
        return {}

    def restore(self, world, arrays):
        return None


def _predict(world, dt, inv_mass, inv_inertia, q, v, w):
    # gravity and the external loads into the working velocities
    with np.errstate(over="ignore", invalid="ignore"):   # the guard reports it
        v[inv_mass > 0] += world.gravity * dt
        if world.ext_force is not None:
            v += (inv_mass * dt)[:, None] * world.ext_force
        if world.ext_torque is not None:
            wi = solver.world_inv_inertias(q, inv_inertia)
            w += dt * np.einsum("nij,nj->ni", wi, world.ext_torque)


def step(world, dt):
    """Advance ``world`` by one impulse step of ``dt`` (checked, > 0) and commit it. Raises
    :class:`~peclet.dem.guards.StepError` (state unchanged) on a non-finite or runaway state."""
    materials = world.check_ready()           # whether per-pair materials are in use
    if world.bodies.n == 0:
        world.tick(dt)
        return
    t0 = time.perf_counter()
    inv_mass, inv_inertia, x, q, v, w = world.working_state()
    # what the step asks several times, once: the radii and speed limit of the guards,
    # whether a wall moves
    limits = world.guard_limits()
    radii = limits[0]
    moving = world.wall_motion.moving()
    frozen = world.sleep.frozen(world.bodies.n, world.loaded())
    if frozen is not None:
        # a sleeper is fixed for this step: no gravity, no load, not moved by a solve
        inv_mass = np.where(frozen, 0.0, inv_mass)
        inv_inertia = np.where(frozen[:, None], 0.0, inv_inertia)
        q_frozen = q[frozen]
    _predict(world, dt, inv_mass, inv_inertia, q, v, w)
    world.guard(x, q, v, w, limits, world.load_cause(dt))   # before any kernel sees it
    wall_moving = None if frozen is None else world.wall_motion.moving_walls()
    c = world.detect(x, quats_to_matrices(q), *world.margins(v, w, dt, x, radii, moving),
                     frozen, None if frozen is None else ~wall_moving)
    t1 = time.perf_counter()
    # a large contact set is solved colour by colour, each colour in parallel (solver.py),
    # on the contacts rearranged into that order; below the threshold, in contact order
    colors = solver.colors_for(c.a, c.b, len(x))
    if colors is not None:
        c = reorder(c, colors.order)
    keys = WarmStart.keys_of(c, len(world.walls))
    t1v, t2v = solver.tangent_basis(c.normal)
    if materials:
        e_c, beta_c, mu_c = world.materials.per_contact(c.a, c.b, world.default_material,
                                                        world.geometry())
    else:
        e_c, beta_c, mu_c = per_contact(c.b, world.default_material, world.geometry())
    lam = world.warm.initial(keys, t1v, t2v, mu_c)
    ra, rb = lever_arms(c, x)
    vw = np.zeros((len(c.a), 3))
    if moving:
        isw = c.b < 0
        vw[isw] = world.wall_motion.surface_velocity(-1 - c.b[isw], c.point[isw])
    con = solver.Constraints(c.a, c.b, c.normal, t1v, t2v, ra, rb, c.gap, e_c, beta_c, mu_c,
                             vw)
    invI = (solver.world_inv_inertias_parallel if len(q) >= PARALLEL_ROTATION_BODIES
            else solver.world_inv_inertias)(q, inv_inertia)
    rest = 2.0 * dt * float(np.sqrt((world.gravity ** 2).sum()))
    vn = solver.solve(con, lam, v, w, inv_mass, invI, dt, rest, world.slop(),
                      world.vel_iters, colors)
    world.guard(x, q, v, w, limits)
    x += v * dt
    # rigid.advance_rotations is advance_all's parallel path (the same per-body kernel, the
    # same bits); it pays from a few thousand bodies on (a 22,121-grain column: 2.4 against
    # 3.7 ms serially, at one thread already)
    (advance_rotations if len(q) >= PARALLEL_ROTATION_BODIES else advance_all)(
        q, w, inv_inertia, dt)
    solver.project(con, c.gap + dt * vn, inv_mass, invI, world.slop(), world.pos_iters, x,
                   q, colors)
    world.domain.wrap(x)
    if frozen is not None:
        q[frozen] = q_frozen                # a sleeper's pose keeps its bits
        world.sleep.update(c.a, c.b, body_reach(radii, v, w, 1.0), wall_moving, v, w)
    world.guard(x, q, v, w, limits)
    t2 = time.perf_counter()
    world.warm.store(keys, lam, t1v, t2v)
    world.commit((x, q, v, w), dt, len(c.a), (t2 - t1, t2 - t0))


def relax(world, n):
    """Remove overlaps without dynamics: ``n`` (an integer in [1, 10000]) passes of detection
    at the current state followed by the position projection on the current gaps
    (:meth:`peclet.dem.Simulation.relax`). Velocities, time and the step count are untouched;
    the warm-start cache is cleared."""
    n = check_int("n", n, 1, MAX_SOLVER_ITERATIONS)
    world.check_ready()
    b = world.bodies
    if b.n == 0:
        return
    inv_inertia = world.resolved_inv_inertia()
    for _ in range(n):
        x = world.domain.wrap(b.pos.copy())
        q = b.quat.copy()
        world.guard(x, q, b.vel, b.omega)
        c = world.detect(x, quats_to_matrices(q), world.margins(b.vel, b.omega, None)[0])
        if not len(c.a) or not np.any(c.gap < 0.0):
            break
        t1v, t2v = solver.tangent_basis(c.normal)
        ra, rb = lever_arms(c, x)
        zero = np.zeros(len(c.a))
        con = solver.Constraints(c.a, c.b, c.normal, t1v, t2v, ra, rb, c.gap, zero, zero,
                                 zero, np.zeros((len(c.a), 3)))
        invI = solver.world_inv_inertias(q, inv_inertia)
        # serial in contact order at any size: a sweep along the body order carries a
        # correction through a whole stack, a coloured one a contact or two per colour
        solver.project_positions(con, c.gap, b.inv_mass, invI, world.slop(),
                                 max(world.pos_iters, 1), x, q)
        world.domain.wrap(x)
        world.guard(x, q, b.vel, b.omega)
        b.pos, b.quat = x, q
    world.warm.clear()
