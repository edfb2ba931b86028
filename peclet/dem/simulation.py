"""``peclet.dem.Simulation``: rigid-body DEM of spheres and composed analytic (CSG) particles.

Units are whatever the caller uses consistently (the page: lengths in ring diameters, seconds).
Frames and conventions are those of :mod:`peclet.dem.bodies` (centres of mass, quaternions
(x, y, z, w) active home -> world, world-frame velocities, principal inverse moments) and of
the geometry core (phi < 0 inside; a scene shape's tree and probes in the body's home frame).

The step (docs/architecture.md §6)::

    predict (gravity, external forces and torques) -> periodic wrap / minimum images -> broad
    phase (cell list over bounding spheres + margin, a moving wall's surface speed included)
    -> narrow phase (both ways, exact paths for spheres, walls at their poses) -> manifold
    reduction -> materials per contact (per pair of material ids, or the defaults) ->
    velocity solve (PGS, Coulomb cone, restitution relative to a moving wall's surface, warm
    start, speculative contacts) -> integrate (x += v dt; torque-free rotation,
    rigid.advance_rotations) -> position projection (translation AND rotation) -> guards ->
    commit, wrap, walls advance by their velocities (:mod:`peclet.dem.wallmotion`).

Determinism: every parallel kernel writes only its own slots and every reduction is serial in a
fixed order, so the state is bitwise identical at any thread count, and ``save``/``load``
(which stores the warm-start cache too) resumes a run bitwise.
"""
from __future__ import annotations

import hashlib
import time

import numpy as np

from peclet.core.geom.transforms import quats_to_matrices
from peclet.core.validation import PecletArgumentError, check_array, check_float, check_int
from peclet.dem import broadphase, narrowphase, persistence, solver
from peclet.dem.bodies import Bodies
from peclet.dem.contacts import (Detector, WarmStart, body_reach, lever_arms, listing,
                                 overlap_pairs, reorder)
from peclet.dem.domain import Domain
from peclet.dem.materials import (MAX_MATERIAL_ID, SIMULATION_DEFAULT, MaterialTable,
                                  material, per_contact)
from peclet.dem.wallmotion import WallMotion
from peclet.dem.hertz import HertzState
from peclet.dem.sleep import Sleep
from peclet.dem.guards import StepError, check_state, speed_bound  # noqa: F401 (API)
from peclet.dem.rigid import advance_all, advance_rotations
from peclet.dem.scales import Scales
from peclet.dem.shapes import analytic_wall, build_geometry, scene_shape, sphere_shape

#: Default base speculative margin, as a fraction of the smallest bounding radius in use; each
#: pair adds what its two members can travel in the step (``(s_a + s_b) dt``, s = |v| + |omega| r)
#: so that no approach within one step goes unseen.
DEFAULT_MARGIN_FRACTION = 0.05

#: Gaps below this fraction of the smallest bounding radius count as touching (see _slop).
SLOP_FRACTION = 5e-4

#: From this many bodies the step turns them, and finds their world inverse inertias, in
#: parallel (rigid.advance_rotations, solver.world_inv_inertias_parallel: the same bits as the
#: serial loops).
PARALLEL_ROTATION_BODIES = 4000

#: Bounds on work a call can ask for: Gauss-Seidel sweeps per step, the capacity hints.
MAX_SOLVER_ITERATIONS = 10_000
MAX_CONTACT_CAPACITY = 10 ** 7


def step_kernels_cached():
    """Whether the step's main kernels (broad phase, narrow phase, velocity and position
    solves) are in Numba's on-disk cache: False means the first step compiles them (about two
    minutes on 2 cores), None that it cannot be told."""
    from peclet.core.jitcache import all_cached

    return all_cached([broadphase.find_pairs, narrowphase.narrow_workers,
                       solver.solve_velocities, solver.project_positions])


class Simulation:
    """A rigid-body DEM simulation: a facade over bodies (:mod:`~peclet.dem.bodies`), shapes
    and walls (:mod:`~peclet.dem.shapes`), the domain, contact detection and the warm-start
    cache (:mod:`~peclet.dem.contacts`), the solvers and persistence.

    ``capacity`` is only a hint for the initial particle count (an integer in
    [0, ``MAX_CAPACITY``]): every buffer grows as needed, and results never depend on it.

    Particle count: :meth:`set_positions` defines N. While N is unchanged every other
    per-particle attribute (shape id, quaternion, velocities, masses, inertia) is KEPT, so
    ``set_positions`` and ``set_shape_ids`` may be called in either order. When N changes, the
    first min(N_old, N) particles keep their attributes, new particles get the defaults
    (shape 0, identity quaternion, zero velocities, inverse mass 1, inverse inertia of a
    uniform solid sphere of the shape's bounding radius) and the warm-start cache is cleared.
    Any per-particle setter called while N == 0 defines N the same way.

    Every setter validates its input (types, shapes, finiteness, ranges) and raises
    :class:`~peclet.core.validation.PecletArgumentError` naming the argument.
    """

    MAX_CAPACITY = 10 ** 6

    def __init__(self, capacity=1):
        cap = check_int("capacity", capacity, 0, self.MAX_CAPACITY)
        self._capacity_hint = cap
        self._bodies = Bodies()
        self._shapes = []
        self._walls = []
        self._geo = None
        self._geo_shapes = ()
        self._scales = Scales()
        self._table, self._table_key = None, None
        self._material = SIMULATION_DEFAULT
        self._pos_iters, self._vel_iters = 10, 8
        self._gravity = np.zeros(3)
        self._domain = Domain()
        self._dt = None
        self._step_count = 0
        self._time = 0.0
        self._margin_fraction = DEFAULT_MARGIN_FRACTION
        self._warm = WarmStart()
        self._detector = Detector(max(1, cap) * narrowphase.MAX_PER_TASK)
        self._num_contacts = 0
        self._wallmo = WallMotion()
        self._materials = MaterialTable()
        self._ext_force = None
        self._ext_torque = None
        self._hertz = HertzState()         # the Hertz engine's moduli and contact history
        self._sleep = Sleep()              # sleeping of bodies at rest (off by default)
        #: Accumulated wall-clock seconds per phase (broad, narrow, solver = velocity solve +
        #: integration + projection, total), for the benchmark.
        self.timings = {"broad": 0.0, "narrow": 0.0, "solver": 0.0, "total": 0.0}

    # ------------------------------------------------------------------ configuration
    def set_domain(self, lo, hi):
        """Axis-aligned domain [lo, hi) (3 finite numbers each, hi > lo on every axis). Used
        by periodic axes and the speed guard."""
        self._domain.set_box(lo, hi)

    def enable_periodicity(self, px, py, pz):
        """Periodic axes (each a bool; the string "False" is an error). A periodic axis needs
        :meth:`set_domain` before stepping."""
        self._domain.set_periodic(px, py, pz)

    def set_gravity(self, gx, gy, gz):
        """Gravitational acceleration (world frame, length / time^2), three finite numbers."""
        self._gravity = np.array([check_float("gx", gx), check_float("gy", gy),
                                  check_float("gz", gz)])

    def set_material_params(self, e_n, e_t, mu):
        """Body-body contact material: normal restitution ``e_n`` in [0, 1], tangential
        (Walton) restitution ``e_t`` in [-1, 1] (applied to colliding contacts only: the
        tangential velocity is driven to -e_t times its incoming value, within the Coulomb
        cone), Coulomb friction ``mu`` >= 0, all finite. Defaults (0.5, 0.0, 0.5)."""
        self._material = material(e_n, e_t, mu)

    def set_solver_iterations(self, position, velocity):
        """Gauss-Seidel sweeps of the position projection and of the velocity solve
        (integers in [0, 10000]; defaults 10 and 8)."""
        self._pos_iters, self._vel_iters = (
            check_int("position", position, 0, MAX_SOLVER_ITERATIONS),
            check_int("velocity", velocity, 0, MAX_SOLVER_ITERATIONS))

    def set_sleeping(self, speed, steps):
        """Let bodies at rest sleep (:mod:`peclet.dem.sleep`): a body whose surface speed
        ``|v| + |omega| r`` stays below ``speed`` (> 0, length/time) for ``steps`` (an integer
        in [1, 1000000]) consecutive steps, with every contact partner as still or asleep,
        is held fixed and skipped by the narrow phase until a moving partner, a moving wall,
        a load or an API call wakes it. Off by default; every body starts awake. Applies to
        :meth:`step` (the Hertz engine ignores it)."""
        self._sleep.configure(speed, steps)

    def disable_sleeping(self):
        """Sleeping off (the default): every body awake, the step exactly as without it."""
        self._sleep.disable()

    def get_sleeping(self):
        """(N,) bool: the bodies asleep now (all False with sleeping off)."""
        if not self._sleep.on:
            return np.zeros(self._bodies.n, bool)
        return self._sleep.sized(self._bodies.n)[0].copy()

    def set_contact_margin_fraction(self, fraction):
        """Speculative margin as a fraction of the smallest bounding radius, in (0, 10]
        (default 0.05)."""
        self._margin_fraction = check_float("fraction", fraction, 0.0, 10.0, lo_open=True)

    def set_dt(self, dt):
        """Default time step for :meth:`step` (finite, > 0)."""
        self._dt = check_float("dt", dt, 0.0, lo_open=True)

    def set_contact_capacity(self, n):
        """Initial size hint (contacts, an integer in [1, 10**7]) of the narrow phase's
        buffers; any n gives the same contacts: the buffers are grown from the measured task
        count before they are filled."""
        self._detector.slot_capacity = check_int("n", n, 1, MAX_CONTACT_CAPACITY)

    @property
    def contact_capacity(self):
        """Current size (contacts) of the narrow phase's slot buffer (read-only)."""
        return self._detector.slot_capacity

    # ------------------------------------------------------------------ shapes and walls
    def add_sphere_shape(self, radius):
        """Register a sphere of ``radius`` (finite, > 0); returns its shape id."""
        return self._register(self._shapes, sphere_shape(radius))

    def add_scene_shape(self, node_ints, node_reals, root, shell_points, bounding_radius):
        """Register a composed CSG particle; returns its shape id.

        ``node_ints`` (n, 3) / ``node_reals`` (n, 16) is the flat encoding, ``root`` the node
        whose value (in its parent frame = the body's home frame, centred on the centre of
        mass, principal axes) is the particle; ``shell_points`` (M >= 1, 3) are surface probes
        in the same frame; ``bounding_radius`` (> 0) a radius about the origin containing the
        solid (it is raised to the farthest probe if a probe lies outside it).
        """
        return self._register(self._shapes, scene_shape(node_ints, node_reals, root,
                                                        shell_points, bounding_radius))

    def add_analytic_wall(self, node_ints, node_reals, root, invert, e_n, mu):
        """A solid wall given by a CSG tree in the world frame (e.g. a box below the floor),
        static unless moved (:meth:`set_wall_transform`, :meth:`set_wall_velocity`).
        ``invert`` (a bool) True makes the complement the solid (a container). ``e_n`` in
        [0, 1] and ``mu`` >= 0 are the wall's restitution and friction (its tangential
        restitution is the body material's ``e_t``), unless it is given a material id
        (:meth:`set_wall_material_id`). Returns the wall index; in contact listings a wall
        appears as body ``-1 - index``."""
        w = self._register(self._walls, analytic_wall(node_ints, node_reals, root, invert,
                                                      e_n, mu))
        self._wallmo.add()
        self._materials.wall_ids = np.append(self._materials.wall_ids, -1)
        return w

    # ------------------------------------------------------------------ moving walls
    def set_wall_transform(self, wall, translation=(0.0, 0.0, 0.0),
                           quaternion=(0.0, 0.0, 0.0, 1.0)):
        """Pose of ``wall`` (an index from :meth:`add_analytic_wall`): the wall's tree, authored
        in the world frame, is placed at ``p = R(quaternion) p_tree + translation``.
        ``translation``: 3 finite numbers; ``quaternion`` (x, y, z, w): unit to within 1e-6.
        Contacts at the next step see the wall there (see :mod:`peclet.dem.wallmotion`)."""
        self._wallmo.set_transform(wall, translation, quaternion)

    def set_wall_velocity(self, wall, linear=(0.0, 0.0, 0.0), angular=(0.0, 0.0, 0.0),
                          center=(0.0, 0.0, 0.0)):
        """Rigid velocity of ``wall``: ``linear`` (length/time) and ``angular`` (rad/time,
        world frame) about the world point ``center``, each 3 finite numbers. The surface
        velocity at p is ``linear + angular x (p - center)``: contacts take it as the wall's
        velocity (friction drags, restitution is relative to the moving surface), and each step
        advances the wall's pose by it (a later :meth:`set_wall_transform` overrides that)."""
        self._wallmo.set_velocity(wall, linear, angular, center)

    def get_wall_transform(self, wall):
        """(translation (3,), quaternion (4,) x y z w) of ``wall``, copies."""
        i = self._wallmo.index(wall)
        return self._wallmo.pos[i].copy(), self._wallmo.quat[i].copy()

    def get_wall_velocity(self, wall):
        """(linear (3,), angular (3,), center (3,)) of ``wall``, copies."""
        i = self._wallmo.index(wall)
        m = self._wallmo
        return m.vel[i].copy(), m.omega[i].copy(), m.center[i].copy()

    # ------------------------------------------------------------------ materials per pair
    def set_material_ids(self, ids):
        """Material id per body (N,), integers in [0, 1023] (default 0 for every body). A
        contact of bodies with ids (i, j) uses the pair declared by :meth:`set_pair_material`;
        (0, 0) defaults to :meth:`set_material_params`. When N changes later, the first
        min(N_old, N) bodies keep their ids and new ones get 0."""
        n = self._bodies.n
        raw = check_array("ids", ids, (n,))            # numbers, finite, one per body
        if not np.all(raw == np.floor(raw)):
            raise PecletArgumentError("ids", f"integers in [0, {MAX_MATERIAL_ID}]", ids,
                                      "a non-integer entry")
        ids = raw.astype(np.int64)
        if n and (ids.min() < 0 or ids.max() > MAX_MATERIAL_ID):
            raise PecletArgumentError("ids", f"integers in [0, {MAX_MATERIAL_ID}]",
                                      (int(ids.min()), int(ids.max())))
        self._materials.body_ids = ids.copy()

    def get_material_ids(self):
        """(N,) material id per body."""
        self._sync_material_ids()
        ids = self._materials.body_ids
        return np.zeros(self._bodies.n, np.int64) if ids is None else ids.copy()

    def set_pair_material(self, a, b, e_n, e_t, mu):
        """Material of contacts between material ids ``a`` and ``b`` (either order; ids in
        [0, 1023]): normal restitution ``e_n`` in [0, 1], tangential restitution ``e_t`` in
        [-1, 1], friction ``mu`` >= 0. A wall with a material id (:meth:`set_wall_material_id`)
        takes the pair (body id, wall id)."""
        self._materials.set_pair(a, b, e_n, e_t, mu)

    def set_wall_material_id(self, wall, material_id):
        """Give ``wall`` the material id ``material_id`` in [0, 1023] (-1: back to the wall's own
        restitution and friction from :meth:`add_analytic_wall`)."""
        i = self._wallmo.index(wall)
        self._materials.wall_ids[i] = check_int("material_id", material_id, -1,
                                                MAX_MATERIAL_ID)

    def _sync_material_ids(self):
        ids, n = self._materials.body_ids, self._bodies.n
        if ids is not None and len(ids) != n:
            out = np.zeros(n, np.int64)
            k = min(n, len(ids))
            out[:k] = ids[:k]
            self._materials.body_ids = out

    # ------------------------------------------------------------------ external loads
    def set_external_forces(self, forces):
        """Force (N, 3) on each body's centre of mass (world frame, mass length / time^2),
        applied at every step until changed or cleared; finite numbers."""
        self._ext_force = check_array("forces", forces, (self._bodies.n, 3)).copy()

    def set_external_torques(self, torques):
        """Torque (N, 3) on each body (world frame), applied at every step until changed or
        cleared; finite numbers."""
        self._ext_torque = check_array("torques", torques, (self._bodies.n, 3)).copy()

    def clear_external_forces(self):
        self._ext_force = None

    def clear_external_torques(self):
        self._ext_torque = None

    def get_external_forces(self):
        """(N, 3) external forces (zeros when none are set)."""
        f = self._ext_force
        return np.zeros((self._bodies.n, 3)) if f is None else f.copy()

    def get_external_torques(self):
        """(N, 3) external torques (zeros when none are set)."""
        t = self._ext_torque
        return np.zeros((self._bodies.n, 3)) if t is None else t.copy()

    def _check_loads(self):
        for name, arr in (("forces", self._ext_force), ("torques", self._ext_torque)):
            if arr is not None and len(arr) != self._bodies.n:
                raise PecletArgumentError(f"external {name}", f"{self._bodies.n} rows (one per "
                                          "body: set them again after changing N)", len(arr))

    def _register(self, table, item):
        table.append(item)
        self._geo = None
        return len(table) - 1

    def num_shapes(self):
        return len(self._shapes)

    def num_walls(self):
        return len(self._walls)

    # ------------------------------------------------------------------ particles
    def num_particles(self):
        """Number of particles N."""
        return self._bodies.n

    def _per_particle(self, setter, *args):
        n = self._bodies.n
        self._sleep.wake_all()
        setter(*args)
        if self._bodies.n != n:
            self._warm.clear()

    def set_positions(self, positions):
        """Centres of mass (N, 3), world frame. Defines N (see the class docstring)."""
        self._per_particle(self._bodies.set_positions, positions)

    def get_positions(self):
        """(N, 3) float64 copy of the centres of mass."""
        return self._bodies.pos.copy()

    def set_shape_ids(self, ids):
        """Shape id per particle (N,), each a registered shape."""
        self._per_particle(self._bodies.set_shape_ids, ids, len(self._shapes))

    def get_shape_ids(self):
        return self._bodies.shape.copy()

    def set_quaternions(self, quats):
        """Orientations (N, 4) as (x, y, z, w), body -> world; normalised on input (any finite
        magnitude). A zero row raises PecletArgumentError."""
        self._per_particle(self._bodies.set_quaternions, quats)

    def get_quaternions(self):
        """(N, 4) float64 copy of the unit quaternions (x, y, z, w)."""
        return self._bodies.quat.copy()

    def set_scales(self, scales):
        """Scale factor per body (N,), each in (0, 1000]: a body of shape k and scale s is
        shape k enlarged by s about its centre of mass (sphere radius, tree, probes, bounding
        radius; :mod:`peclet.dem.scales`). Mass and inertia follow: changing a body's scale
        from s to s' divides its inverse mass by (s'/s)^3 and its inverse moments by
        (s'/s)^5, so set masses for the CURRENT scales, or scales first. Positions are
        centres and stay where they are (a grown body may overlap: :meth:`relax`)."""
        b = self._bodies
        new = self._scales.checked(scales, b.n)
        self._sleep.wake_all()
        self._scales.resize(b.n)
        old = self._scales.values if self._scales.values is not None else np.ones(b.n)
        k = new / old
        b.inv_mass = b.inv_mass / k ** 3
        b.inv_inertia = b.inv_inertia / (k ** 5)[:, None]
        self._scales.values = new

    def set_scales_uniform(self, scale):
        """Every body's scale set to ``scale`` in (0, 1000] (see :meth:`set_scales`)."""
        self.set_scales(np.full(self._bodies.n, Scales.checked_uniform(scale)))

    def get_scales(self):
        """(N,) scale per body (1 for a body never scaled)."""
        self._scales.resize(self._bodies.n)
        v = self._scales.values
        return np.ones(self._bodies.n) if v is None else v.copy()

    def set_inv_mass(self, inv_mass):
        """Inverse masses (N,), each finite and >= 0 (0 = not moved by contacts or gravity)."""
        self._per_particle(self._bodies.set_inv_mass, inv_mass)

    def get_inv_mass(self):
        return self._bodies.inv_mass.copy()

    def set_inv_inertia(self, inv_inertia):
        """Principal inverse moments of inertia (N, 3), each finite and >= 0 (0 = locked
        axis)."""
        self._per_particle(self._bodies.set_inv_inertia, inv_inertia)

    def get_inv_inertia(self):
        """(N, 3) principal inverse moments actually used (defaults resolved)."""
        return self._resolved_inv_inertia()

    def set_velocities(self, v):
        """Linear velocities (N, 3), world frame."""
        self._per_particle(self._bodies.set_velocities, v)

    def get_velocities(self):
        return self._bodies.vel.copy()

    def set_angular_velocities(self, w):
        """Angular velocities (N, 3), world frame, rad / time."""
        self._per_particle(self._bodies.set_angular_velocities, w)

    def get_angular_velocities(self):
        return self._bodies.omega.copy()

    @property
    def step_count(self):
        return self._step_count

    @property
    def time(self):
        return self._time

    # ------------------------------------------------------------------ derived quantities
    def _shape_table(self):
        # (internal shapes, internal shape id per body): the registered shapes and ids
        # themselves unless some body is scaled (peclet.dem.scales)
        b = self._bodies
        self._scales.resize(b.n)
        if not self._scales.active():
            return self._shapes, b.shape
        key = (b.shape, self._scales.values, len(self._shapes))
        old = self._table_key
        if old is None or old[0] is not key[0] or old[1] is not key[1] or old[2] != key[2]:
            self._table = self._scales.table(self._shapes, b.shape)
            self._table_key = key
        return self._table

    def _geometry(self):
        shapes, _ = self._shape_table()
        same = (len(shapes) == len(self._geo_shapes)
                and all(a is b for a, b in zip(shapes, self._geo_shapes)))
        if self._geo is None or not same:
            self._geo = build_geometry(shapes, self._walls)
            self._geo_shapes = tuple(shapes)
        return self._geo

    def _radii(self):
        shapes, ids = self._shape_table()
        r = np.array([s.radius for s in shapes], dtype=np.float64)
        return r[ids]

    def _need_shapes(self):
        if not self._shapes:
            raise PecletArgumentError("shapes", "registered first (add a shape)", "none")

    def _resolved_inv_inertia(self):
        b = self._bodies
        if np.isnan(b.inv_inertia).any():
            self._need_shapes()
        return b.resolved_inv_inertia(self._radii() if self._shapes else None)

    def state_hash(self):
        """SHA-256 (hex) of the state's float64 bytes: positions, quaternions (x, y, z, w),
        velocities and angular velocities, in that order. Equal hashes: the same state bit for
        bit (e.g. the same run at another thread count, or with another buffer capacity)."""
        h = hashlib.sha256()
        b = self._bodies
        for a in (b.pos, b.quat, b.vel, b.omega):
            h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
        return h.hexdigest()

    def kinetic_energy(self):
        """Translational plus rotational kinetic energy; bodies with inverse mass 0 contribute
        no translational part, locked axes no rotational part."""
        b = self._bodies
        return b.kinetic_energy(self._resolved_inv_inertia() if b.n else None)

    def num_contacts(self):
        """Contacts (manifold points) used by the last step."""
        return self._num_contacts

    # ------------------------------------------------------------------ contacts
    def _check_ready(self):
        # raises when the simulation cannot step; returns whether per-pair materials are in use
        b = self._bodies
        if b.n:
            self._need_shapes()
        if b.n and b.shape.max() >= len(self._shapes):
            raise PecletArgumentError("shape ids", f"registered shapes in [0, "
                                      f"{len(self._shapes)})", int(b.shape.max()))
        self._domain.check_ready()
        self._sync_material_ids()
        self._check_loads()
        active = self._materials.active()
        if active:
            self._materials.check_declared(b.n, self._material)
        return active

    def _margins(self, vel, omega, dt, pos=None, radii=None, moving=None):
        """(base, reach (N,) or None, wall_reach (N, W) or None) for :meth:`_detect`: each
        pair's margin is the base plus what its two members can close in ``dt``
        (:func:`peclet.dem.broadphase.task_list`); a moving wall's surface speed near a body
        enters that body's wall pairs like a body's own speed. ``radii`` (:meth:`_radii`) and
        ``moving`` (whether a wall moves) when the caller has them already."""
        base = self._margin_fraction * float(np.min([s.radius for s in
                                                     self._shape_table()[0]]))
        if dt is None:
            return base, None, None
        radii = self._radii() if radii is None else radii
        reach = body_reach(radii, vel, omega, dt)
        wall_reach = None
        if self._wallmo.moving() if moving is None else moving:
            p = self._bodies.pos if pos is None else pos
            wall_reach = self._wallmo.surface_speeds(p, radii) * dt
        return base, reach, wall_reach

    def _detect(self, pos, rot, margin, reach=None, wall_reach=None, frozen=None,
                wall_static=None):
        geo = self._geometry()
        if self._wallmo.n:
            geo.wall_pos[:] = self._wallmo.pos
            geo.wall_rot[:] = self._wallmo.rotations()
        return self._detector.detect(geo, self._shape_table()[1], pos, rot, margin,
                                     self._margin_fraction, self._domain, self.timings,
                                     reach, wall_reach, frozen, wall_static)

    def _loaded(self):
        # (N,) bool: bodies with a non-zero external force or torque (None: no loads)
        rows = [f for f in (self._ext_force, self._ext_torque) if f is not None]
        if not rows:
            return None
        return np.any(np.concatenate(rows, axis=1) != 0.0, axis=1)

    def _slop(self):
        # a gap below the slop counts as touching in the velocity solve: no speculative
        # approach velocity is granted for it, so the sub-slop gaps the position projection
        # leaves behind do not feed velocity noise back into resting stacks
        return SLOP_FRACTION * float(self._geometry().shape_rad.min())

    def _current_contacts(self):
        self._check_ready()
        b = self._bodies
        if b.n == 0 or not self._shapes:
            return None
        pos = self._domain.wrap(b.pos.copy())
        return self._detect(pos, quats_to_matrices(b.quat),
                            *self._margins(b.vel, b.omega, self._dt, pos))

    def detect_contacts(self):
        """Contacts of the CURRENT state (nothing advances), sorted by (body_a, body_b,
        feature). Returns a dict of arrays: ``body_a``, ``body_b`` (a wall is -1 - index),
        ``point`` (n, 3) world, ``normal`` (n, 3) unit, from b towards a, ``depth`` (n,)
        penetration depth (negative = a speculative contact that is still apart),
        ``feature`` (n,) the probe id (offset by 2**24 for b's probes in a's tree)."""
        return listing(self._current_contacts())

    def compute_overlaps(self):
        """Maximum penetration depth (length, >= 0) over the current contacts."""
        c = self._current_contacts()
        if c is None or len(c.gap) == 0:
            return 0.0
        return float(max(0.0, -c.gap.min()))

    def overlap_pairs(self):
        """Per pair (body_a, body_b, max depth) of the current contacts that overlap."""
        return overlap_pairs(self.detect_contacts())

    # ------------------------------------------------------------------ the step
    def step(self, dt=None):
        """Advance by ``dt`` (else the :meth:`set_dt` value; with neither, an error).

        Raises :class:`StepError` (state unchanged) when a particle's state becomes
        non-finite or its speed exceeds ``1e3`` domain sizes per unit time (the domain size is
        the largest side of :meth:`set_domain`, else of the particles' bounding box plus two
        bounding radii)."""
        dt = self._resolve_dt(dt)
        materials = self._check_ready()         # whether per-pair materials are in use
        if self._bodies.n == 0:
            self._step_count += 1
            self._time += dt
            return
        t0 = time.perf_counter()
        inv_mass, inv_inertia, x, q, v, w = self._working_state()
        # what the step asks several times, once: the radii and speed limit of the guards,
        # whether a wall moves
        limits = self._guard_limits()
        radii = limits[0]
        moving = self._wallmo.moving()
        frozen = self._sleep.frozen(self._bodies.n, self._loaded())
        if frozen is not None:
            # a sleeper is fixed for this step: no gravity, no load, not moved by a solve
            inv_mass = np.where(frozen, 0.0, inv_mass)
            inv_inertia = np.where(frozen[:, None], 0.0, inv_inertia)
            q_frozen = q[frozen]
        with np.errstate(over="ignore", invalid="ignore"):   # the guard reports it
            v[inv_mass > 0] += self._gravity * dt
            if self._ext_force is not None:
                v += (inv_mass * dt)[:, None] * self._ext_force
            if self._ext_torque is not None:
                wi = solver.world_inv_inertias(q, inv_inertia)
                w += dt * np.einsum("nij,nj->ni", wi, self._ext_torque)
        self._guard(x, q, v, w, limits)             # before any kernel sees a bad value
        wall_moving = None if frozen is None else self._wallmo.moving_walls()
        c = self._detect(x, quats_to_matrices(q), *self._margins(v, w, dt, x, radii, moving),
                         frozen,
                         None if frozen is None else ~wall_moving)
        t1 = time.perf_counter()
        # a large contact set is solved colour by colour, each colour in parallel (solver.py),
        # on the contacts rearranged into that order; below the threshold, in contact order
        colors = solver.colors_for(c.a, c.b, len(x))
        if colors is not None:
            c = reorder(c, colors.order)
        keys = WarmStart.keys_of(c, len(self._walls))
        t1v, t2v = solver.tangent_basis(c.normal)
        if materials:
            e_c, beta_c, mu_c = self._materials.per_contact(c.a, c.b, self._material,
                                                            self._geometry())
        else:
            e_c, beta_c, mu_c = per_contact(c.b, self._material, self._geometry())
        lam = self._warm.initial(keys, t1v, t2v, mu_c)
        ra, rb = lever_arms(c, x)
        vw = np.zeros((len(c.a), 3))
        if moving:
            isw = c.b < 0
            vw[isw] = self._wallmo.surface_velocity(-1 - c.b[isw], c.point[isw])
        con = solver.Constraints(c.a, c.b, c.normal, t1v, t2v, ra, rb, c.gap, e_c, beta_c, mu_c,
                                 vw)
        invI = (solver.world_inv_inertias_parallel if len(q) >= PARALLEL_ROTATION_BODIES
                else solver.world_inv_inertias)(q, inv_inertia)
        rest = 2.0 * dt * float(np.sqrt((self._gravity ** 2).sum()))
        vn = solver.solve(con, lam, v, w, inv_mass, invI, dt, rest, self._slop(),
                          self._vel_iters, colors)
        self._guard(x, q, v, w, limits)
        x += v * dt
        # rigid.advance_rotations is advance_all's parallel path (the same per-body kernel,
        # the same bits); it pays from a few thousand bodies on (a 22,121-grain column: 2.4
        # against 3.7 ms serially, at one thread already)
        (advance_rotations if len(q) >= PARALLEL_ROTATION_BODIES else advance_all)(
            q, w, inv_inertia, dt)
        solver.project(con, c.gap + dt * vn, inv_mass, invI, self._slop(), self._pos_iters, x,
                       q, colors)
        self._domain.wrap(x)
        if frozen is not None:
            q[frozen] = q_frozen                # a sleeper's pose keeps its bits
            self._sleep.update(c.a, c.b, body_reach(radii, v, w, 1.0), wall_moving, v, w)
        self._guard(x, q, v, w, limits)
        t2 = time.perf_counter()
        # commit
        b = self._bodies
        b.pos, b.quat, b.vel, b.omega = x, q, v, w
        self._warm.store(keys, lam, t1v, t2v)
        if moving:
            self._wallmo.advance(dt)
        self._num_contacts = len(c.a)
        self._step_count += 1
        self._time += dt
        self.timings["solver"] += t2 - t1
        self.timings["total"] += t2 - t0

    def _resolve_dt(self, dt):
        # the step's dt: the argument, else set_dt's; finite and > 0
        if dt is None:
            if self._dt is None:
                raise PecletArgumentError("dt", "given, or set with set_dt(dt) before",
                                          None, "no time step")
            dt = self._dt
        return check_float("dt", dt, 0.0, lo_open=True)

    def _working_state(self):
        # (inverse masses, resolved inverse moments, and copies of the positions (wrapped),
        # quaternions, velocities and angular velocities) that a step advances and commits
        b = self._bodies
        return (b.inv_mass, self._resolved_inv_inertia(), self._domain.wrap(b.pos.copy()),
                b.quat.copy(), b.vel.copy(), b.omega.copy())

    def relax(self, n=1):
        """Remove overlaps without dynamics: ``n`` (an integer in [1, 10000]) passes of
        detection at the current state followed by the position projection (the step's
        non-penetration solve, moving AND turning bodies by the same effective masses) on the
        current gaps. Velocities, time and the step count are untouched; a body with inverse
        mass 0 does not move. Use it on a start state that overlaps (a dense random fill, a
        size distribution grown in place) before stepping."""
        n = check_int("n", n, 1, MAX_SOLVER_ITERATIONS)
        self._check_ready()
        b = self._bodies
        if b.n == 0:
            return
        inv_inertia = self._resolved_inv_inertia()
        for _ in range(n):
            x = self._domain.wrap(b.pos.copy())
            q = b.quat.copy()
            self._guard(x, q, b.vel, b.omega)
            c = self._detect(x, quats_to_matrices(q), self._margins(b.vel, b.omega, None)[0])
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
            solver.project_positions(con, c.gap, b.inv_mass, invI, self._slop(),
                                     max(self._pos_iters, 1), x, q)
            self._domain.wrap(x)
            self._guard(x, q, b.vel, b.omega)
            b.pos, b.quat = x, q
        self._warm.clear()

    # ------------------------------------------------------------------ Hertz–Mindlin engine
    def set_hertz_material(self, material_id, youngs, poisson):
        """Elastic moduli of material id ``material_id`` (in [0, 1023], the ids of
        :meth:`set_material_ids` / :meth:`set_wall_material_id`) for :meth:`step_hertz`:
        Young's modulus ``youngs`` (> 0, pressure in the caller's units) and Poisson ratio
        ``poisson`` in (-1, 0.5). Every body's id must have moduli before a Hertz step; a wall
        without a material id is rigid. Restitution and friction still come from the pair
        material (:meth:`set_pair_material`, :meth:`set_material_params`, the wall's own)."""
        self._hertz.set_material(material_id, youngs, poisson)

    def set_rolling_friction(self, mu_r, material_a=None, material_b=None):
        """Rolling resistance of :meth:`step_hertz` (off by default: ``mu_r`` 0 everywhere).

        ``mu_r`` (dimensionless, in [0, 1]) is the rolling friction coefficient: a contact
        resists the relative rolling of its bodies with a torque that builds up elastically and
        saturates at ``mu_r R* F_n`` (torque units of the caller: length x force), R* the
        contact's effective radius (a sphere's radius against a wall), F_n its normal force;
        the elastic-plastic spring-dashpot law of :mod:`peclet.dem.hertz` (Ai et al. 2011,
        type C). On a flat floor a rolling sphere then decelerates at 5/7 ``mu_r`` g and stops;
        on an incline of slope tan(theta) < ``mu_r`` it stays put. With both material ids None
        the value applies to every pair not declared on its own (and to walls without a
        material id); ``material_a`` and ``material_b`` (ids in [0, 1023] of
        :meth:`set_material_ids` / :meth:`set_wall_material_id`) set one pair. The torque acts
        on both bodies, equal and opposite (a wall takes none). The impulse :meth:`step`
        ignores it. Raises PecletArgumentError for ``mu_r`` outside [0, 1] (or NaN) and for a
        material id outside [0, 1023] or given without the other."""
        self._hertz.set_rolling(mu_r, material_a, material_b)
        self._hertz.cand = None          # the candidates carry each pair's mu_r

    def step_hertz(self, substeps=1, dt=None, skin_frac=None):
        """Advance by ``substeps`` (an integer in [1, 10**6]) explicit Hertz–Mindlin substeps of
        ``dt`` each (else the :meth:`set_dt` value; finite, > 0), for spheres and composed
        particles (see :mod:`peclet.dem.hertz` for the force law, one contact per touching
        patch of a composed particle with R* from both surfaces' curvatures, the damping that
        reproduces each pair's ``e_n``, the tangential history and the integrator).
        ``skin_frac`` (in (0, 10], default ``hertz.DEFAULT_SKIN_FRACTION``) is the skin of the
        candidate list as a fraction of the smallest radius: contacts are detected within it
        and the list is reused while no pair can have closed it; for spheres it sets the speed
        only, never the result (bit for bit); a composed particle's patch solves restart from
        new seeds at each rebuild and at each call, so its bits depend on the skin and the
        call pattern (to round-off), never on the thread count. Raises PecletArgumentError
        when ``dt`` exceeds ``hertz.RAYLEIGH_FRACTION`` of the smallest Rayleigh time, for a
        material id without moduli or ``e_n`` below ``hertz.E_MIN``;
        :class:`peclet.dem.hertz.HertzPatchError` (a PecletArgumentError naming both bodies)
        for a distributed contact (flat, line, edge or corner contacts, which run on the
        distributed law of :mod:`peclet.dem.hertz`) overlapping deeper than
        ``hertz.DIST_DEEP_LIMIT`` x the smaller bounding radius; :class:`StepError` when the
        state goes non-finite or runs away
        (in both cases the state of that substep's start is kept). The impulse :meth:`step`
        is unaffected; the two engines keep separate contact caches. Sleeping does not apply.
        """
        from peclet.dem import hertz

        n = check_int("substeps", substeps, 1, 10 ** 6)
        dt = self._resolve_dt(dt)
        skin = hertz.DEFAULT_SKIN_FRACTION if skin_frac is None else check_float(
            "skin_frac", skin_frac, 0.0, 10.0, lo_open=True)
        self._check_ready()
        hertz.check(self, self._hertz, dt)
        self._hertz.cand = None          # materials, walls or bodies may have changed since
        for _ in range(n):
            if self._bodies.n == 0:
                self._step_count += 1
                self._time += dt
                continue
            hertz.substep(self, self._hertz, dt, skin)

    def hertz_contacts(self):
        """The touching contacts of the last Hertz substep with their forces (a dict, see
        :func:`peclet.dem.hertz.last_listing`; SI-like units of the caller, world frame)."""
        from peclet.dem import hertz
        return hertz.last_listing(self._hertz)

    def _guard(self, x, q, v, w, limits=None):
        # limits: (radii, speed bound) when the caller has them (they do not change in a step)
        check_state(x, q, v, w, *(self._guard_limits() if limits is None else limits),
                    self._step_count + 1)

    def _guard_limits(self):
        # (radii, speed bound) of the guards: fixed within a step (the committed positions)
        radii = self._radii()
        return radii, speed_bound(self._domain, self._bodies.pos, radii)

    # ------------------------------------------------------------------ persistence
    def save(self, path):
        """Write the whole simulation (state, shapes, walls, parameters, warm-start cache) to
        ``path`` (.npz) atomically; :meth:`load` resumes it bitwise."""
        persistence.save(self, path)

    @classmethod
    def load(cls, path):
        """Rebuild a simulation written by :meth:`save`. Anything that is not a consistent
        peclet Simulation save raises one PecletArgumentError naming ``path``."""
        return persistence.load(cls, path)
