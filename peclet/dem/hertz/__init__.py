"""Hertz–Mindlin soft contacts: the force law, its restitution calibration and the explicit step.

An alternative to the impulse step of docs/architecture.md §6 for engineers who calibrate bulk
flow with real elastic moduli. Candidate contacts are found by the same detection (broad and
narrow phase, :mod:`peclet.dem.contacts`) within a skin and kept as a Verlet list while no
pair can have closed the skin (:func:`~peclet.dem.hertz.candidates.candidates`); at every substep each candidate's
contact is recomputed exactly (:func:`contact_geometry`), every touching one (gap < 0, overlap
``delta = -gap``) exerts a force, and the bodies are advanced by an explicit integrator.

Normal force (Hertz)::

    F_n = 4/3 E* sqrt(R*) delta^(3/2) + F_d,   F_d = gamma sqrt(S_n m*) (-v_n),
    S_n = 2 E* sqrt(R* delta),                 total clamped at F_n >= 0 (no attraction)

with ``1/E* = (1 - nu_a^2)/E_a + (1 - nu_b^2)/E_b``, ``1/R* = 1/R_a + 1/R_b`` (a wall counts
as flat, R* = R of the sphere, also where it is curved) and ``1/m* = 1/m_a + 1/m_b`` (a wall or
a body of inverse mass 0 adds nothing). ``v_n`` is the normal relative velocity, positive when
separating.

Tangential force (Mindlin, no-slip)::

    S_t = 8 G* sqrt(R* delta),   1/G* = (2 - nu_a)/G_a + (2 - nu_b)/G_b,   G = E / (2 (1 + nu))
    xi <- (xi rotated into the current tangent plane) + v_t dt
    F_t = -S_t xi - gamma sqrt(S_t m*) v_t,   |F_t| <= mu F_n (else scaled onto the cone and
    xi reset to -F_t / S_t, so that the spring holds the sliding force)

``xi`` is the tangential displacement history of the contact, kept per contact key (the body
pair and the feature, :meth:`peclet.dem.contacts.WarmStart.keys_of`; a wall is body -1 - w)
while the bodies overlap, and dropped when they separate. It is stored in the world frame and
rotated into each new tangent plane keeping its length.

Damping law and why: the Tsuji et al. (1992) form (a dashpot proportional to
``sqrt(m* S_n)``, i.e. ``delta^(1/4)``), because with it the coefficient of restitution does
not depend on the impact speed. The dimensionless coefficient ``gamma`` is not taken from the
linear-spring formula used by EDEM/LIGGGHTS (``gamma = -2 sqrt(5/6) ln e / sqrt(ln^2 e +
pi^2)``), which for the Hertz law with the no-attraction clamp rebounds too fast (0.55 for
e = 0.5, 0.40 for e = 0.3, 0.25 for e = 0.1: :func:`edem_gamma`, :func:`restitution_of`): it is
computed by
:func:`damping_gamma`, which solves the dimensionless impact
``x'' = -max(0, x^(3/2) + sqrt(3/2) gamma x^(1/4) x')``, ``x(0) = 0``, ``x'(0) = 1`` (a
fixed-step RK4, h = 2e-5 against a contact of ~3.2; the rebound speed is good to ~1e-7,
measured against h / 4), independent of the engine, and finds the gamma whose rebound speed
is ``e`` (Brent's method). The same gamma damps the tangential spring (as EDEM does).
Restitution ``e_n`` and friction ``mu`` come from the contact's pair material (the impulse
engine's :class:`~peclet.dem.materials.MaterialTable`, or the wall's own values); the Walton
``e_t`` is not used by this engine. Rolling resistance: optional, off by default
(:mod:`peclet.dem.hertz.rolling`).

Moduli: :meth:`HertzState.set_material` per material id (the same ids as the pair table). A
wall without a material id is rigid (``1/E_wall = 0``); a wall with an id takes that id's
moduli.

Lever arms: the contact point is the narrow phase's, midway between the two surfaces, so a
sphere's torque arm is R - delta/2 (R - delta against a rigid plane would be the other common
choice; rigid-body formulas with R differ from either by O(delta / R)).

Integrator: symplectic Euler in kick-drift order (the leapfrog: the stored velocities are those
of the half step), per substep: detect, forces at the current positions, ``v += dt (F/m + g +
F_ext/m)``, ``omega += dt I_w^-1 (T + T_ext)``, ``x += dt v``, then the torque-free rotation of
:func:`peclet.dem.rigid.advance_all` (unchanged). Second order in the positions for the elastic
force; the damping sees the half-step velocity.

Step-size check: the Rayleigh time of body i, ``T_R = pi R sqrt(rho / G) / (0.1631 nu +
0.8766)`` with ``rho = m / (4/3 pi R^3)``, must satisfy ``dt <= RAYLEIGH_FRACTION * min_i T_R``
(a stability guard: an accurate impact needs tens of steps per contact time, see
``validation/chung_ooi.py``).

Determinism: the force and rolling kernels write only their own contact's slots; forces and
torques are summed into bodies serially in contact order (the rolling torques after the
forces'); the history is sorted by key. Bitwise identical
at any thread count.

The package, one module per job (:mod:`~peclet.dem.hertz.rolling`,
:mod:`~peclet.dem.hertz.patch` and :mod:`~peclet.dem.hertz.distributed` hold their laws'
notes):

- ``calibration``: the dashpot's gamma per e_n (Hertz and linear laws), the elliptical Hertz
  table, the Rayleigh time;
- ``law``: the force per contact, its sums into the bodies, kick-drift, the spheres' contacts;
- ``rolling``: rolling resistance (Ai et al. type C);
- ``fields``: a composed contact's two sides and their exact fields and curvatures;
- ``patch``: the Hertz patch solve and its statuses; ``seeds``: the patches of a pair at a
  rebuild;
- ``distributed``: the distributed contact of a pair; ``overlap``: its region along a normal
  (grid, zooms, integral, law);
- ``state``: :class:`HertzState`; ``candidates``: the Verlet list, what every law asks of a
  pair, a composed pair's patches and carried histories; ``substep``: the substep and listing;
- ``engine``: :class:`ExplicitEngine`, the contact engine of every force law
  (:class:`peclet.dem.engine.ForceLaw`), and :class:`HertzLaw`, this law;
- ``dispatch``: the one serial-or-parallel choice of the per-row kernels (thresholds below).

Kernels take bundled arrays (NamedTuples: :class:`~peclet.dem.hertz.law.ContactRows`,
:class:`~peclet.dem.hertz.law.PairLaw`, :class:`~peclet.dem.hertz.fields.Shapes`,
:class:`~peclet.dem.hertz.fields.Pair`, ...).
"""
from __future__ import annotations

#: Below this many contacts (bodies) the force, rolling (kick) loops run serially: a parallel
#: launch was measured at ~0.6 ms on a loaded 2-core machine. Both paths run the same per-row
#: function, so the choice never changes a bit. Read at each call (:mod:`.dispatch`).
PARALLEL_MIN = 20000
#: Below this many patches the patch solves run serially (same bits either way).
PATCH_PARALLEL_MIN = 256
#: Below this many distributed contacts they are computed serially (same bits either way).
DIST_PARALLEL_MIN = 4

from .calibration import (E_MIN, RATIO_LIMIT, RAYLEIGH_FRACTION, damping_gamma,  # noqa: E402,F401
                          damping_gamma_linear, edem_gamma, elliptic_table, rayleigh_time,
                          rebound_speed, restitution_of)
from .law import (ContactRows, ForceOut, Motion, PairLaw, Walls, accumulate,  # noqa: E402,F401
                  contact_forces, contact_geometry, forces_loops,
                  kick_drift, walls_of)
from .rolling import (MU_R_MAX, ROLLING_DAMPING, RollLaw, RollOut, Spin,  # noqa: E402,F401
                      accumulate_torques, rolling_loops, rolling_torques)
from .fields import Pair, Shapes, Side, shapes_of  # noqa: E402,F401
from .patch import (DELTA_LIMIT, FAILED_FEATURE, FD_STEP, MAX_PATCHES, PATCH_DEEP,  # noqa: E402,F401
                    PATCH_LINE, PATCH_MAX_ITER, PATCH_NO_CONVERGENCE, PATCH_NOT_CONVEX,
                    PATCH_OK, PATCH_PROBE_INSIDE, PATCH_REASONS, PATCH_TOL, PATCH_TOO_MANY,
                    SAME_PATCH, HertzPatchError, patch_geometry, raise_patch_error)
from .seeds import seed_patches  # noqa: E402,F401
from .overlap import (DIST_BISECT, DIST_DEEP_LIMIT, DIST_FEATURE, DIST_GRID,  # noqa: E402,F401
                      DIST_UNRESOLVED, DIST_ZOOMS, MODE_DISTRIBUTED, PATCH_DIST_DEEP)
from .distributed import DIST_DISTINCT, DIST_FALLBACK, distributed_geometry  # noqa: E402,F401
from .state import HertzState  # noqa: E402,F401
from .candidates import Candidates, Pairs  # noqa: E402,F401
from .substep import DEFAULT_SKIN_FRACTION, last_listing, substep  # noqa: E402,F401
from .engine import ExplicitEngine, HertzLaw, HertzParams  # noqa: E402,F401
