"""``peclet.dem.Simulation``: rigid-body DEM of spheres and composed analytic (CSG) particles.

Units are whatever the caller uses consistently (the page: lengths in ring diameters, seconds).
Frames and conventions are those of :mod:`peclet.dem.bodies` (centres of mass, quaternions
(x, y, z, w) active home -> world, world-frame velocities, principal inverse moments) and of
the geometry core (phi < 0 inside; a scene shape's tree and probes in the body's home frame).

The impulse step (:mod:`peclet.dem.impulse`, docs/architecture.md §6)::

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

import numpy as np

from peclet.core.validation import PecletArgumentError, check_float, check_int
from peclet.dem import broadphase, impulse, narrowphase, persistence, solver
from peclet.dem.api_laws import ContactLaws
from peclet.dem.api_walls import WallsAndLoads
from peclet.dem.contacts import listing, overlap_pairs
from peclet.dem.guards import StepError  # noqa: F401 (API)
from peclet.dem.impulse import MAX_SOLVER_ITERATIONS, PARALLEL_ROTATION_BODIES  # noqa: F401
from peclet.dem.limits import MAX_SIZE_RATIO, check_inverses, check_size_ratio
from peclet.dem.materials import material
from peclet.dem.scales import Scales
from peclet.dem.shapes import analytic_wall, scene_shape, sphere_shape
from peclet.dem.world import DEFAULT_MARGIN_FRACTION, SLOP_FRACTION, World  # noqa: F401

#: Bound on the contact capacity hint.
MAX_CONTACT_CAPACITY = 10 ** 7


def step_kernels_cached():
    """Whether the step's main kernels (broad phase, narrow phase, velocity and position
    solves) are in Numba's on-disk cache: False means the first step compiles them (about two
    minutes on 2 cores), None that it cannot be told."""
    from peclet.core.jitcache import all_cached

    return all_cached([broadphase.find_pairs, narrowphase.narrow_workers,
                       solver.solve_velocities, solver.project_positions])


class Simulation(WallsAndLoads, ContactLaws):
    """A rigid-body DEM simulation: the user's facade over one :class:`~peclet.dem.world.World`
    (``sim.world``: bodies, shapes, walls, domain, materials, detection, clock) and the contact
    engines (:mod:`peclet.dem.engine`: :meth:`step` the impulse engine, :meth:`step_hertz` the
    Hertz–Mindlin one, :meth:`advance` the law of :meth:`set_contact_law`), with persistence.
    Walls, materials and loads: :class:`~peclet.dem.api_walls.WallsAndLoads`; the laws:
    :class:`~peclet.dem.api_laws.ContactLaws`.

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
        #: The state every engine reads and writes (:mod:`peclet.dem.world`); this class is
        #: its user-facing facade.
        self.world = World(check_int("capacity", capacity, 0, self.MAX_CAPACITY))
        self._engine = None             # the law of set_contact_law, built at first advance

    @property
    def timings(self):
        """Accumulated wall-clock seconds per phase (``broad``, ``narrow``, ``solver`` = the
        engine's solve and integration, ``total``), for the benchmarks (a live dict)."""
        return self.world.timings

    # ------------------------------------------------------------------ configuration
    def set_domain(self, lo, hi):
        """Axis-aligned domain [lo, hi) (3 finite numbers each, of magnitude <= 1e100, hi - lo
        in [1e-100, 2e100] on every axis: :mod:`peclet.dem.limits`). Used by periodic axes and
        the speed guard."""
        self.world.domain.set_box(lo, hi)

    def enable_periodicity(self, px, py, pz):
        """Periodic axes (each a bool; the string "False" is an error). A periodic axis needs
        :meth:`set_domain` before stepping."""
        self.world.domain.set_periodic(px, py, pz)

    def set_gravity(self, gx, gy, gz):
        """Gravitational acceleration (world frame, length / time^2), three finite numbers
        (any: a ``g dt`` that overflows stops the step with a StepError naming the gravity)."""
        self.world.gravity = np.array([check_float("gx", gx), check_float("gy", gy),
                                  check_float("gz", gz)])

    def set_material_params(self, e_n, e_t, mu):
        """Body-body contact material: normal restitution ``e_n`` in [0, 1], tangential
        (Walton) restitution ``e_t`` in [-1, 1] (applied to colliding contacts only: the
        tangential velocity is driven to -e_t times its incoming value, within the Coulomb
        cone), Coulomb friction ``mu`` >= 0, all finite. Defaults (0.5, 0.0, 0.5)."""
        self.world.default_material = material(e_n, e_t, mu)

    def set_solver_iterations(self, position, velocity):
        """Gauss-Seidel sweeps of the position projection and of the velocity solve
        (integers in [0, 10000]; defaults 10 and 8)."""
        self.world.pos_iters, self.world.vel_iters = (
            check_int("position", position, 0, MAX_SOLVER_ITERATIONS),
            check_int("velocity", velocity, 0, MAX_SOLVER_ITERATIONS))

    def set_sleeping(self, speed, steps):
        """Let bodies at rest sleep (:mod:`peclet.dem.sleep`): a body whose surface speed
        ``|v| + |omega| r`` stays below ``speed`` (> 0, length/time) for ``steps`` (an integer
        in [1, 1000000]) consecutive steps, with every contact partner as still or asleep,
        is held fixed and skipped by the narrow phase until a moving partner, a moving wall,
        a load or an API call wakes it. Off by default; every body starts awake. Applies to
        :meth:`step` (the Hertz engine ignores it)."""
        self.world.sleep.configure(speed, steps)

    def disable_sleeping(self):
        """Sleeping off (the default): every body awake, the step exactly as without it."""
        self.world.sleep.disable()

    def get_sleeping(self):
        """(N,) bool: the bodies asleep now (all False with sleeping off)."""
        if not self.world.sleep.on:
            return np.zeros(self.world.bodies.n, bool)
        return self.world.sleep.sized(self.world.bodies.n)[0].copy()

    def set_contact_margin_fraction(self, fraction):
        """Speculative margin as a fraction of the smallest bounding radius, in (0, 10]
        (default 0.05)."""
        self.world.margin_fraction = check_float("fraction", fraction, 0.0, 10.0, lo_open=True)

    def set_dt(self, dt):
        """Default time step for :meth:`step` (time, in [1e-100, 1e100]:
        :mod:`peclet.dem.limits`)."""
        self.world.dt = self.world.checked_dt(dt)

    def set_contact_capacity(self, n):
        """Initial size hint (contacts, an integer in [1, 10**7]) of the narrow phase's
        buffers; any n gives the same contacts: the buffers are grown from the measured task
        count before they are filled."""
        self.world.detector.slot_capacity = check_int("n", n, 1, MAX_CONTACT_CAPACITY)

    @property
    def contact_capacity(self):
        """Current size (contacts) of the narrow phase's slot buffer (read-only)."""
        return self.world.detector.slot_capacity

    # ------------------------------------------------------------------ shapes and walls
    def add_sphere_shape(self, radius):
        """Register a sphere of ``radius`` (length, in [1e-100, 1e100], and within a factor
        1e6 of every bounding radius in use: :mod:`peclet.dem.limits`); returns its shape
        id."""
        shape = sphere_shape(radius)
        check_size_ratio("radius", shape.radius, self.world.radii_in_use())
        return self.world.register(self.world.shapes, shape)

    def add_scene_shape(self, node_ints, node_reals, root, shell_points, bounding_radius):
        """Register a composed CSG particle; returns its shape id.

        ``node_ints`` (n, 3) / ``node_reals`` (n, 16) is the flat encoding, ``root`` the node
        whose value (in its parent frame = the body's home frame, centred on the centre of
        mass, principal axes) is the particle; ``shell_points`` (M >= 1, 3) are surface probes
        in the same frame; ``bounding_radius`` (> 0) a radius about the origin containing the
        solid (it is raised to the farthest probe if a probe lies outside it), a length in
        [1e-100, 1e100] within a factor 1e6 of every bounding radius in use
        (:mod:`peclet.dem.limits`).
        """
        shape = scene_shape(node_ints, node_reals, root, shell_points, bounding_radius,
                            self.world.radii_in_use())
        return self.world.register(self.world.shapes, shape)

    def add_analytic_wall(self, node_ints, node_reals, root, invert, e_n, mu):
        """A solid wall given by a CSG tree in the world frame (e.g. a box below the floor),
        static unless moved (:meth:`set_wall_transform`, :meth:`set_wall_velocity`).
        ``invert`` (a bool) True makes the complement the solid (a container). ``e_n`` in
        [0, 1] and ``mu`` >= 0 are the wall's restitution and friction (its tangential
        restitution is the body material's ``e_t``), unless it is given a material id
        (:meth:`set_wall_material_id`). Returns the wall index; in contact listings a wall
        appears as body ``-1 - index``."""
        w = self.world.register(self.world.walls, analytic_wall(node_ints, node_reals, root, invert,
                                                      e_n, mu))
        self.world.wall_motion.add()
        self.world.materials.wall_ids = np.append(self.world.materials.wall_ids, -1)
        return w

    def num_shapes(self):
        return len(self.world.shapes)

    def num_walls(self):
        return len(self.world.walls)

    # ------------------------------------------------------------------ particles
    def num_particles(self):
        """Number of particles N."""
        return self.world.bodies.n

    def _per_particle(self, setter, *args):
        n = self.world.bodies.n
        self.world.sleep.wake_all()
        setter(*args)
        if self.world.bodies.n != n:
            self.world.warm.clear()

    def set_positions(self, positions):
        """Centres of mass (N, 3), world frame, coordinates of magnitude <= 1e100
        (:mod:`peclet.dem.limits`). Defines N (see the class docstring)."""
        self._per_particle(self.world.bodies.set_positions, positions)

    def get_positions(self):
        """(N, 3) float64 copy of the centres of mass."""
        return self.world.bodies.pos.copy()

    def set_shape_ids(self, ids):
        """Shape id per particle (N,), each a registered shape."""
        self._per_particle(self.world.bodies.set_shape_ids, ids, len(self.world.shapes))

    def get_shape_ids(self):
        return self.world.bodies.shape.copy()

    def set_quaternions(self, quats):
        """Orientations (N, 4) as (x, y, z, w), body -> world; normalised on input (any finite
        magnitude). A zero row raises PecletArgumentError."""
        self._per_particle(self.world.bodies.set_quaternions, quats)

    def get_quaternions(self):
        """(N, 4) float64 copy of the unit quaternions (x, y, z, w)."""
        return self.world.bodies.quat.copy()

    def set_scales(self, scales):
        """Scale factor per body (N,), each in [1e-6, 1000]: a body of shape k and scale s is
        shape k enlarged by s about its centre of mass (sphere radius, tree, probes, bounding
        radius; :mod:`peclet.dem.scales`). Mass and inertia follow: changing a body's scale
        from s to s' divides its inverse mass by (s'/s)^3 and its inverse moments by
        (s'/s)^5, so set masses for the CURRENT scales, or scales first. Positions are
        centres and stay where they are (a grown body may overlap: :meth:`relax`). Refused
        (nothing changes) when a scaled radius falls outside a factor 1e6 of the other
        bounding radii in use, or a rescaled inverse mass or moment leaves [1e-100, 1e100]
        (:mod:`peclet.dem.limits`)."""
        w = self.world
        b = w.bodies
        new = w.scales.checked(scales, b.n)
        w.scales.resize(b.n)
        old = w.scales.values if w.scales.values is not None else np.ones(b.n)
        if len(w.shapes) and b.n:
            r = np.array([s.radius for s in w.shapes])
            scaled = new * r[np.minimum(b.shape, len(r) - 1)]
            lo, hi = min(r.min(), scaled.min()), max(r.max(), scaled.max())
            if hi > MAX_SIZE_RATIO * lo * (1.0 + 1e-12):     # the bound itself is in
                i = int(np.argmin(scaled) if scaled.min() == lo else np.argmax(scaled))
                raise PecletArgumentError(
                    "scales", f"numbers giving bounding radii within a factor "
                    f"{MAX_SIZE_RATIO:g} of the registered shapes' [{r.min():g}, {r.max():g}] "
                    "(the broad phase's cells follow the largest, the contact margins the "
                    "smallest)", scales, f"body {i}: scale {new[i]:g} gives {scaled[i]:g}")
        k = new / old
        inv_mass = b.inv_mass / k ** 3
        inv_inertia = b.inv_inertia / (k ** 5)[:, None]
        check_inverses("scales", inv_mass, scales, " (the inverse mass the scale implies)")
        check_inverses("scales", np.nan_to_num(inv_inertia), scales,
                       " (an inverse moment the scale implies)")
        w.sleep.wake_all()
        b.inv_mass, b.inv_inertia = inv_mass, inv_inertia
        w.scales.values = new

    def set_scales_uniform(self, scale):
        """Every body's scale set to ``scale`` in [1e-6, 1000] (see :meth:`set_scales`)."""
        self.set_scales(np.full(self.world.bodies.n, Scales.checked_uniform(scale)))

    def get_scales(self):
        """(N,) scale per body (1 for a body never scaled)."""
        self.world.scales.resize(self.world.bodies.n)
        v = self.world.scales.values
        return np.ones(self.world.bodies.n) if v is None else v.copy()

    def set_inv_mass(self, inv_mass):
        """Inverse masses (N,), 1/mass, each 0 (not moved by contacts or gravity) or in
        [1e-100, 1e100] (:mod:`peclet.dem.limits`)."""
        self._per_particle(self.world.bodies.set_inv_mass, inv_mass)

    def get_inv_mass(self):
        return self.world.bodies.inv_mass.copy()

    def set_inv_inertia(self, inv_inertia):
        """Principal inverse moments of inertia (N, 3), 1/(mass length^2), each 0 (a locked
        axis) or in [1e-100, 1e100] (:mod:`peclet.dem.limits`)."""
        self._per_particle(self.world.bodies.set_inv_inertia, inv_inertia)

    def get_inv_inertia(self):
        """(N, 3) principal inverse moments actually used (defaults resolved)."""
        return self.world.resolved_inv_inertia()

    def set_velocities(self, v):
        """Linear velocities (N, 3), world frame, length/time, each row of norm <= 1e100
        (:mod:`peclet.dem.limits`)."""
        self._per_particle(self.world.bodies.set_velocities, v)

    def get_velocities(self):
        return self.world.bodies.vel.copy()

    def set_angular_velocities(self, w):
        """Angular velocities (N, 3), world frame, rad / time, each row of norm <= 1e100
        (:mod:`peclet.dem.limits`)."""
        self._per_particle(self.world.bodies.set_angular_velocities, w)

    def get_angular_velocities(self):
        return self.world.bodies.omega.copy()

    @property
    def step_count(self):
        return self.world.step_count

    @property
    def time(self):
        return self.world.time

    # ------------------------------------------------------------------ derived quantities

    def state_hash(self):
        """SHA-256 (hex) of the state's float64 bytes: positions, quaternions (x, y, z, w),
        velocities and angular velocities, in that order. Equal hashes: the same state bit for
        bit (e.g. the same run at another thread count, or with another buffer capacity)."""
        h = hashlib.sha256()
        b = self.world.bodies
        for a in (b.pos, b.quat, b.vel, b.omega):
            h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
        return h.hexdigest()

    def kinetic_energy(self):
        """Translational plus rotational kinetic energy; bodies with inverse mass 0 contribute
        no translational part, locked axes no rotational part."""
        b = self.world.bodies
        return b.kinetic_energy(self.world.resolved_inv_inertia() if b.n else None)

    def num_contacts(self):
        """Contacts (manifold points) used by the last step."""
        return self.world.num_contacts

    # ------------------------------------------------------------------ contacts

    def detect_contacts(self):
        """Contacts of the CURRENT state (nothing advances), sorted by (body_a, body_b,
        feature). Returns a dict of arrays: ``body_a``, ``body_b`` (a wall is -1 - index),
        ``point`` (n, 3) world, ``normal`` (n, 3) unit, from b towards a, ``depth`` (n,)
        penetration depth (negative = a speculative contact that is still apart),
        ``feature`` (n,) the probe id (offset by 2**24 for b's probes in a's tree)."""
        return listing(self.world.current_contacts())

    def compute_overlaps(self):
        """Maximum penetration depth (length, >= 0) over the current contacts."""
        c = self.world.current_contacts()
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
        impulse.step(self.world, self.world.resolve_dt(dt))

    def relax(self, n=1):
        """Remove overlaps without dynamics: ``n`` (an integer in [1, 10000]) passes of
        detection at the current state followed by the position projection (the step's
        non-penetration solve, moving AND turning bodies by the same effective masses) on the
        current gaps. Velocities, time and the step count are untouched; a body with inverse
        mass 0 does not move. Use it on a start state that overlaps (a dense random fill, a
        size distribution grown in place) before stepping."""
        impulse.relax(self.world, n)

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
