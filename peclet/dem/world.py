"""``World``: the state a DEM step reads and writes, and the one internal API between its parts.

:class:`~peclet.dem.Simulation` is the user's facade over one ``World``; the contact engines
(:mod:`peclet.dem.engine`: the impulse engine, the Hertz–Mindlin engine and every law
registered there), :mod:`~peclet.dem.persistence` and :mod:`~peclet.dem.warm` talk to the
world, never to the facade's private state (docs/architecture.md §6, "The World").

What it owns (public attributes; units and frames of :mod:`peclet.dem.bodies`):

- ``bodies`` (:class:`~peclet.dem.bodies.Bodies`), ``scales``, ``shapes`` (registered shapes
  in id order) and ``walls`` (registered walls), ``wall_motion`` (poses and velocities);
- ``domain`` (box and periodic axes), ``gravity`` (3,), ``ext_force`` / ``ext_torque``
  ((N, 3) or None);
- ``default_material`` (the body-body material of ``set_material_params``), ``materials``
  (ids and the pair table), ``hertz`` (the Hertz engine's moduli and history),
  ``histories`` (each explicit law's contact history by name, the Hertz law's ``hertz``);
- ``detector`` and ``warm`` (the impulse engine's warm-start cache), ``sleep``;
- ``pos_iters`` / ``vel_iters`` (Gauss-Seidel sweeps), ``margin_fraction``;
- the clock: ``dt`` (the default step, or None), ``step_count``, ``time``; ``num_contacts``
  of the last step and ``timings`` (wall-clock seconds per phase).

Derived quantities (the shape table under scales, the packed geometry, radii, margins) are
methods, cached where they are costly; an engine commits a step with :meth:`World.commit`,
which is the one place the state, the walls, the clock and the timings advance.
"""
from __future__ import annotations

import numpy as np

from peclet.core.geom.transforms import quats_to_matrices
from peclet.core.validation import PecletArgumentError, check_float
from peclet.dem import narrowphase
from peclet.dem.bodies import Bodies
from peclet.dem.contacts import Detector, WarmStart, body_reach
from peclet.dem.domain import Domain
from peclet.dem.guards import check_state, speed_bound
from peclet.dem.hertz import HertzState
from peclet.dem.limits import MAX_DT, MIN_DT
from peclet.dem.materials import SIMULATION_DEFAULT, MaterialTable
from peclet.dem.scales import Scales
from peclet.dem.shapes import build_geometry
from peclet.dem.sleep import Sleep
from peclet.dem.wallmotion import WallMotion

#: Default base speculative margin, as a fraction of the smallest bounding radius in use; each
#: pair adds what its two members can travel in the step (``(s_a + s_b) dt``, s = |v| + |omega| r)
#: so that no approach within one step goes unseen.
DEFAULT_MARGIN_FRACTION = 0.05

#: Gaps below this fraction of the smallest bounding radius count as touching (see slop).
SLOP_FRACTION = 5e-4


class World:
    """The state of one simulation (see the module notes for what it owns). ``capacity`` is
    the hint of the initial particle count, already checked by the facade."""

    def __init__(self, capacity):
        self.capacity_hint = capacity
        self.bodies = Bodies()
        self.shapes = []
        self.walls = []
        self.scales = Scales()
        self.default_material = SIMULATION_DEFAULT
        self.pos_iters, self.vel_iters = 10, 8
        self.gravity = np.zeros(3)
        self.domain = Domain()
        self.dt = None
        self.step_count = 0
        self.time = 0.0
        self.margin_fraction = DEFAULT_MARGIN_FRACTION
        self.warm = WarmStart()
        self.detector = Detector(max(1, capacity) * narrowphase.MAX_PER_TASK)
        self.num_contacts = 0
        self.wall_motion = WallMotion()
        self.materials = MaterialTable()
        self.ext_force = None
        self.ext_torque = None
        self.hertz = HertzState()          # the Hertz engine's moduli and contact history
        #: Each explicit law's contact history by law name (peclet.dem.hertz.engine).
        self.histories = {"hertz": self.hertz}
        self.sleep = Sleep()               # sleeping of bodies at rest (off by default)
        #: Accumulated wall-clock seconds per phase (broad, narrow, solver = the engine's
        #: force or velocity solve + integration, total), for the benchmarks.
        self.timings = {"broad": 0.0, "narrow": 0.0, "solver": 0.0, "total": 0.0}
        self._geo, self._geo_shapes = None, ()
        self._table, self._table_key = None, None

    # ------------------------------------------------------------------ registration
    def register(self, table, item):
        """Append ``item`` to ``table`` (``shapes`` or ``walls``); returns its index. The
        packed geometry is rebuilt at its next use."""
        table.append(item)
        self._geo = None
        return len(table) - 1

    def sync_material_ids(self):
        """Resize the material ids to N (the first min(N_old, N) kept, new bodies 0)."""
        ids, n = self.materials.body_ids, self.bodies.n
        if ids is not None and len(ids) != n:
            out = np.zeros(n, np.int64)
            k = min(n, len(ids))
            out[:k] = ids[:k]
            self.materials.body_ids = out

    # ------------------------------------------------------------------ derived quantities
    def shape_table(self):
        """(internal shapes, internal shape id per body): the registered shapes and ids
        themselves unless some body is scaled (:mod:`peclet.dem.scales`)."""
        b = self.bodies
        self.scales.resize(b.n)
        if not self.scales.active():
            return self.shapes, b.shape
        key = (b.shape, self.scales.values, len(self.shapes))
        old = self._table_key
        if old is None or old[0] is not key[0] or old[1] is not key[1] or old[2] != key[2]:
            self._table = self.scales.table(self.shapes, b.shape)
            self._table_key = key
        return self._table

    def geometry(self):
        """The packed :class:`~peclet.dem.shapes.Geometry` of the internal shapes and walls
        (rebuilt when a shape, wall or scale changed)."""
        shapes, _ = self.shape_table()
        same = (len(shapes) == len(self._geo_shapes)
                and all(a is b for a, b in zip(shapes, self._geo_shapes)))
        if self._geo is None or not same:
            self._geo = build_geometry(shapes, self.walls)
            self._geo_shapes = tuple(shapes)
        return self._geo

    def radii(self):
        """(N,) bounding radius of each body (its scale applied)."""
        shapes, ids = self.shape_table()
        r = np.array([s.radius for s in shapes], dtype=np.float64)
        return r[ids]

    def radii_in_use(self):
        """(k,) bounding radii of the shapes the step's tables hold: every registered shape,
        and each scaled body's (scale times its shape's), without building scaled shapes."""
        r = np.array([s.radius for s in self.shapes], dtype=np.float64)
        b = self.bodies
        self.scales.resize(b.n)
        v = self.scales.values
        if v is None or not len(r) or not b.n:
            return r
        ids = np.minimum(b.shape, len(r) - 1)
        return np.concatenate([r, v * r[ids]])

    def need_shapes(self):
        """Raise PecletArgumentError when no shape is registered."""
        if not self.shapes:
            raise PecletArgumentError("shapes", "registered first (add a shape)", "none")

    def resolved_inv_inertia(self):
        """(N, 3) principal inverse moments, the defaults of unset rows resolved."""
        b = self.bodies
        if np.isnan(b.inv_inertia).any():
            self.need_shapes()
        ii = b.resolved_inv_inertia(self.radii() if self.shapes else None)
        if not np.all(np.isfinite(ii)):      # a default moment 2.5 inv_mass / r^2 overflowed
            i = int(np.flatnonzero(~np.isfinite(ii).all(axis=1))[0])
            raise PecletArgumentError("inv_mass", "an inverse mass whose default inverse moment "
                                      "2.5 inv_mass / r^2 is finite (or set_inv_inertia)",
                                      float(b.inv_mass[i]), f"body {i}, bounding radius "
                                      f"{float(self.radii()[i]):g}")
        return ii

    def loaded(self):
        """(N,) bool: bodies with a non-zero external force or torque (None: no loads)."""
        rows = [f for f in (self.ext_force, self.ext_torque) if f is not None]
        if not rows:
            return None
        return np.any(np.concatenate(rows, axis=1) != 0.0, axis=1)

    def slop(self):
        """Gaps below this count as touching in the velocity solve: no speculative approach
        velocity is granted for them, so the sub-slop gaps the position projection leaves
        behind do not feed velocity noise back into resting stacks."""
        return SLOP_FRACTION * float(self.geometry().shape_rad.min())

    # ------------------------------------------------------------------ checks
    def check_loads(self):
        """Raise when the external loads no longer have one row per body."""
        for name, arr in (("forces", self.ext_force), ("torques", self.ext_torque)):
            if arr is not None and len(arr) != self.bodies.n:
                raise PecletArgumentError(f"external {name}", f"{self.bodies.n} rows (one per "
                                          "body: set them again after changing N)", len(arr))

    def check_ready(self):
        """Raise when the world cannot step; returns whether per-pair materials are in use."""
        b = self.bodies
        if b.n:
            self.need_shapes()
        if b.n and b.shape.max() >= len(self.shapes):
            raise PecletArgumentError("shape ids", f"registered shapes in [0, "
                                      f"{len(self.shapes)})", int(b.shape.max()))
        self.domain.check_ready()
        self.sync_material_ids()
        self.check_loads()
        active = self.materials.active()
        if active:
            self.materials.check_declared(b.n, self.default_material)
        return active

    def resolve_dt(self, dt):
        """The step's dt: the argument, else the world's default; in [1e-100, 1e100]."""
        if dt is None:
            if self.dt is None:
                raise PecletArgumentError("dt", "given, or set with set_dt(dt) before",
                                          None, "no time step")
            dt = self.dt
        return self.checked_dt(dt)

    @staticmethod
    def checked_dt(dt):
        """``dt`` checked: a finite time step in [MIN_DT, MAX_DT] = [1e-100, 1e100]."""
        v = check_float("dt", dt, 0.0, lo_open=True)
        if not MIN_DT <= v <= MAX_DT:
            raise PecletArgumentError("dt", f"a finite number in [{MIN_DT:g}, {MAX_DT:g}] (a "
                                      "time step: gaps over dt and speeds times dt must stay "
                                      "float64 numbers)", dt)
        return v

    def guard_limits(self):
        """(radii, speed bound) of the guards: fixed within a step (the committed positions).
        A moving wall whose surface speed at a body exceeds the bound is refused here, before
        the step's work (:meth:`peclet.dem.wallmotion.WallMotion.check_speeds`)."""
        radii = self.radii()
        bound = speed_bound(self.domain, self.bodies.pos, radii)
        if self.wall_motion.moving():
            self.wall_motion.check_speeds(self.bodies.pos, radii, bound)
        return radii, bound

    def guard(self, x, q, v, w, limits=None, cause=""):
        """Raise StepError when a working state is non-finite or runs away (``limits``:
        :meth:`guard_limits` when the caller has them; they do not change in a step;
        ``cause``: the user's inputs the stage applied, named in the message)."""
        check_state(x, q, v, w, *(self.guard_limits() if limits is None else limits),
                    self.step_count + 1, cause)

    def load_cause(self, dt):
        """The user's inputs the prediction applies (gravity and loads times ``dt``), as text
        for a StepError raised right after it."""
        text = f"after the gravity {self.gravity.tolist()} (set_gravity) times dt = {dt:g}"
        if self.ext_force is not None or self.ext_torque is not None:
            text += " and the external forces / torques (set_external_forces / _torques)"
        return text + " were applied"

    # ------------------------------------------------------------------ detection
    def margins(self, vel, omega, dt, pos=None, radii=None, moving=None):
        """(base, reach (N,) or None, wall_reach (N, W) or None) for :meth:`detect`: each
        pair's margin is the base plus what its two members can close in ``dt``
        (:func:`peclet.dem.broadphase.task_list`); a moving wall's surface speed near a body
        enters that body's wall pairs like a body's own speed. ``radii`` (:meth:`radii`) and
        ``moving`` (whether a wall moves) when the caller has them already."""
        base = self.margin_fraction * float(np.min([s.radius for s in
                                                    self.shape_table()[0]]))
        if dt is None:
            return base, None, None
        radii = self.radii() if radii is None else radii
        reach = body_reach(radii, vel, omega, dt)
        wall_reach = None
        if self.wall_motion.moving() if moving is None else moving:
            p = self.bodies.pos if pos is None else pos
            wall_reach = self.wall_motion.surface_speeds(p, radii) * dt
        return base, reach, wall_reach

    def detect(self, pos, rot, margin, reach=None, wall_reach=None, frozen=None,
               wall_static=None):
        """Contacts (:class:`~peclet.dem.contacts.Contacts`) of bodies at ``pos`` (N, 3) and
        rotations ``rot`` (N, 3, 3) within the margins, walls at their current poses."""
        geo = self.geometry()
        if self.wall_motion.n:
            geo.wall_pos[:] = self.wall_motion.pos
            geo.wall_rot[:] = self.wall_motion.rotations()
        return self.detector.detect(geo, self.shape_table()[1], pos, rot, margin,
                                    self.margin_fraction, self.domain, self.timings,
                                    reach, wall_reach, frozen, wall_static)

    def current_contacts(self):
        """Contacts of the committed state (nothing advances), with the margins of a step of
        the default dt; None without bodies or shapes."""
        self.check_ready()
        b = self.bodies
        if b.n == 0 or not self.shapes:
            return None
        pos = self.domain.wrap(b.pos.copy())
        return self.detect(pos, quats_to_matrices(b.quat),
                           *self.margins(b.vel, b.omega, self.dt, pos))

    # ------------------------------------------------------------------ a step's state
    def working_state(self):
        """(inverse masses, resolved inverse moments, and copies of the positions (wrapped),
        quaternions, velocities and angular velocities) that a step advances and commits."""
        b = self.bodies
        return (b.inv_mass, self.resolved_inv_inertia(), self.domain.wrap(b.pos.copy()),
                b.quat.copy(), b.vel.copy(), b.omega.copy())

    def tick(self, dt):
        """Advance the clock by one step of ``dt`` (a step with no bodies does only this)."""
        self.step_count += 1
        self.time += dt

    def commit(self, state, dt, num_contacts, seconds):
        """Commit a step: ``state`` = (x, q, v, w) the new positions, quaternions, velocities
        and angular velocities; the walls advance by their velocities over ``dt``; the clock
        ticks; ``num_contacts`` is recorded; ``seconds`` = (solver, total) wall-clock seconds
        are added to the timings. Every engine ends its step here."""
        b = self.bodies
        b.pos, b.quat, b.vel, b.omega = state
        self.wall_motion.advance(dt)
        self.num_contacts = int(num_contacts)
        self.tick(dt)
        self.timings["solver"] += seconds[0]
        self.timings["total"] += seconds[1]
