"""Contact solvers: projected Gauss-Seidel on velocities, and a non-penetration projection.

Conventions: a contact i joins body ``a[i]`` and body ``b[i]`` (``b < 0`` = a static wall);
``normal`` points from b to a; ``ra``/``rb`` are the contact point relative to each body's
centre of mass (b's image, for periodic pairs). Impulses act on a along +n, on b along -n.

Velocity solve (per contact, accumulated impulses, serial and in a fixed order, with the
sweep direction alternating between iterations -- symmetric Gauss-Seidel propagates through
deep stacks in both directions):

- normal: ``lambda_n >= 0`` and the relative normal velocity ``v_n >= vmin``, where
  ``vmin = -gap/dt`` for a speculative contact (gap > 0, it may close but not cross),
  ``0`` for a touching one, and ``-e v_n^-`` for a colliding one (approach faster than the
  resting threshold and reached within this step, to within the slop) when e > 0;
- friction: the tangential relative velocity is driven to ``-beta v_t^-`` (Walton's
  tangential restitution) for a colliding contact and to 0 otherwise, inside the Coulomb cone
  ``|lambda_t| <= mu lambda_n`` (a disc in the tangent plane, not a pyramid).

Position projection: non-linear Gauss-Seidel on the predicted end-of-step gaps
``gap + dt v_n`` with accumulated, non-negative corrections; each correction moves AND rotates
both bodies with the same effective mass as the velocity constraint (not translation only), and
never touches the velocities.

Large contact sets (at least :data:`COLORED_MIN_CONTACTS`, a fixed count) are swept colour by
colour instead (:func:`color_contacts`: greedy in contact order, no two contacts of a colour
share a body; walls are no bodies), the contacts of one colour in parallel, the colours in
alternating order: each update then touches rows no other update of its colour touches, so the
result is that of a serial sweep in colour order, bit for bit at any thread count
(docs/architecture.md §7). Below the threshold the serial sweep in contact order is unchanged.
The colour order converges more slowly along a stack than the contact order does (contacts
sorted by body, bodies numbered up a stack, carry a correction through the whole stack in one
sweep; alternate colours carry it a contact or two per sweep): on the stirred column the
largest grain-grain overlap over 400 steps was 0.0030 against 0.0021 serially (radius 0.4),
the mean overlap and the kinetic energy the same to a few percent. The position projection of
:meth:`Simulation.relax`, which works on one state and has no later step to catch up, stays
serial at any size.

Layout: this module keeps the names the callers use and the choice of path (:func:`colors_for`,
:func:`solve`, :func:`project`); the kernels are in :mod:`peclet.dem.solver_rows` (the
bundles and per-contact terms), :mod:`peclet.dem.solver_velocity`,
:mod:`peclet.dem.solver_position` and :mod:`peclet.dem.solver_colored` (the colouring and the
coloured sweeps).
"""
from __future__ import annotations

import numpy as np

from peclet.dem.solver_colored import (Colored, color_contacts, project_positions_colored,
                                       solve_velocities_colored)
from peclet.dem.solver_position import project_positions
from peclet.dem.solver_rows import (COLOR_CHUNK, PARALLEL_COLOR_MIN, Constraints, tangent_basis,
                                    world_inv_inertias, world_inv_inertias_parallel)
from peclet.dem.solver_velocity import solve_velocities

__all__ = ["COLORED_MIN_CONTACTS", "PARALLEL_COLOR_MIN", "COLOR_CHUNK", "Constraints", "Colored",
           "tangent_basis", "world_inv_inertias", "world_inv_inertias_parallel",
           "solve_velocities", "solve_velocities_colored", "project_positions",
           "project_positions_colored", "color_contacts", "colors_for", "solve", "project"]

#: From this many contacts a step's velocity solve and position projection sweep the contacts
#: colour by colour, each colour in parallel (:func:`solve_velocities_colored`); below it they
#: sweep serially in contact order. A count of contacts, never of threads: which path runs, and
#: so the bits, never depends on the thread count. On the stirred column (58,000 contacts, 11
#: colours) the coloured sweeps cost 1.15x the serial ones' CPU time at one thread, plus 2.6 ms
#: to colour and reorder, and run about 150 parallel regions a step: worth it where each colour
#: holds thousands of contacts per thread. The page's pour (a few thousand contacts) and the
#: 1000-ring column (at most 12,870) stay below it, with their bits. A module setting, read at
#: each call of :func:`colors_for` (a test or :mod:`peclet.dem.warm` may set it here).
COLORED_MIN_CONTACTS = 20000


def colors_for(a, b, n_bodies, threshold=None):
    """The :class:`Colored` colouring of the contacts (``a``, ``b``) (b < 0: a wall) when
    there are at least ``threshold`` (default :data:`COLORED_MIN_CONTACTS`) of them, else None
    (the serial path). The choice depends on the contact count alone, never on the thread
    count."""
    lim = COLORED_MIN_CONTACTS if threshold is None else threshold
    if len(a) < lim:
        return None
    return Colored(*color_contacts(a, b, np.int64(n_bodies)))


def solve(con, lam, v, w, inv_mass, invI, dt, rest_threshold, slop, iterations, colors=None):
    """The velocity solve: :func:`solve_velocities` (serial, in contact order) when
    ``colors`` is None, else :func:`solve_velocities_colored`, ``con`` and ``lam`` then in
    the colour order of ``colors`` (:func:`colors_for`)."""
    if colors is None:
        return solve_velocities(con, lam, v, w, inv_mass, invI, dt, rest_threshold, slop,
                                iterations)
    return solve_velocities_colored(con, lam, v, w, inv_mass, invI, dt, rest_threshold, slop,
                                    iterations, colors)


def project(con, gap_end, inv_mass, invI, slop, iterations, pos, quats, colors=None):
    """The position projection: :func:`project_positions` when ``colors`` is None, else
    :func:`project_positions_colored` (``con`` and ``gap_end`` in colour order, see
    :func:`solve`)."""
    if colors is None:
        project_positions(con, gap_end, inv_mass, invI, slop, iterations, pos, quats)
    else:
        project_positions_colored(con, gap_end, inv_mass, invI, slop, iterations, pos, quats,
                                  colors)
