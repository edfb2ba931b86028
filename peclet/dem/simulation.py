"""``peclet.dem.Simulation``: rigid-body DEM of spheres and composed analytic (CSG) particles.

Units are whatever the caller uses consistently (the page: lengths in ring diameters, seconds).
Frames and conventions are those of :mod:`peclet.dem.bodies` (centres of mass, quaternions
(x, y, z, w) active home -> world, world-frame velocities, principal inverse moments) and of
the geometry core (phi < 0 inside; a scene shape's tree and probes in the body's home frame).

The step (DESIGN.md §5)::

    predict (gravity) -> periodic wrap / minimum images -> broad phase (cell list over bounding
    spheres + margin) -> narrow phase (both ways, exact paths for spheres, walls) -> manifold
    reduction -> velocity solve (PGS, Coulomb cone, restitution, warm start, speculative
    contacts) -> integrate (x += v dt; torque-free rotation, rigid.advance_rotations) ->
    position projection (translation AND rotation) -> guards -> commit, wrap.

Determinism: every parallel kernel writes only its own slots and every reduction is serial in a
fixed order, so the state is bitwise identical at any thread count, and ``save``/``load``
(which stores the warm-start cache too) resumes a run bitwise.
"""
from __future__ import annotations

import hashlib
import time

import numpy as np

from peclet.core.geom.transforms import quats_to_matrices
from peclet.core.validation import PecletArgumentError, check_float, check_int
from peclet.dem import narrowphase, persistence, solver
from peclet.dem.bodies import Bodies
from peclet.dem.contacts import (Detector, WarmStart, lever_arms, listing, overlap_pairs,
                                 speculative_margin)
from peclet.dem.domain import Domain
from peclet.dem.materials import Material, clamp_to_cone, material, per_contact
from peclet.dem.guards import StepError, check_state, speed_bound  # noqa: F401 (API)
from peclet.dem.rigid import advance_all
from peclet.dem.shapes import analytic_wall, build_geometry, scene_shape, sphere_shape

#: Default speculative margin, as a fraction of the smallest bounding radius in use; the step
#: adds ``2 * max speed * dt`` so that no approach within one step goes unseen.
DEFAULT_MARGIN_FRACTION = 0.05

#: Gaps below this fraction of the smallest bounding radius count as touching (see _slop).
SLOP_FRACTION = 5e-4

#: Bounds on work a call can ask for: Gauss-Seidel sweeps per step, the capacity hints.
MAX_SOLVER_ITERATIONS = 10_000
MAX_CONTACT_CAPACITY = 10 ** 7


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
        self._material = Material()
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

    def add_analytic_wall(self, node_ints, node_reals, root, invert, e, mu):
        """A static solid wall given by a CSG tree in the world frame (e.g. a box below the
        floor). ``invert`` (a bool) True makes the complement the solid (a container). ``e``
        in [0, 1] and ``mu`` >= 0 are the wall's restitution and friction. Returns the wall
        index; in contact listings a wall appears as body ``-1 - index``."""
        return self._register(self._walls, analytic_wall(node_ints, node_reals, root, invert,
                                                         e, mu))

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
    def _geometry(self):
        if self._geo is None:
            self._geo = build_geometry(self._shapes, self._walls)
        return self._geo

    def _radii(self):
        r = np.array([s.radius for s in self._shapes], dtype=np.float64)
        return r[self._bodies.shape]

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
        b = self._bodies
        if b.n:
            self._need_shapes()
        if b.n and b.shape.max() >= len(self._shapes):
            raise PecletArgumentError("shape ids", f"registered shapes in [0, "
                                      f"{len(self._shapes)})", int(b.shape.max()))
        self._domain.check_ready()

    def _margin(self, vel, omega, dt):
        base = self._margin_fraction * float(np.min([s.radius for s in self._shapes]))
        return speculative_margin(base, self._radii(), vel, omega, dt)

    def _detect(self, pos, rot, margin):
        return self._detector.detect(self._geometry(), self._bodies.shape, pos, rot, margin,
                                     self._margin_fraction, self._domain, self.timings)

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
        return self._detect(pos, quats_to_matrices(b.quat), self._margin(b.vel, b.omega,
                                                                          self._dt))

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
        if dt is None:
            if self._dt is None:
                raise PecletArgumentError("dt", "given, or set with set_dt(dt) before",
                                          None, "no time step")
            dt = self._dt
        dt = check_float("dt", dt, 0.0, lo_open=True)
        self._check_ready()
        if self._bodies.n == 0:
            self._step_count += 1
            self._time += dt
            return
        t0 = time.perf_counter()
        b = self._bodies
        inv_mass = b.inv_mass
        inv_inertia = self._resolved_inv_inertia()
        x = self._domain.wrap(b.pos.copy())
        q = b.quat.copy()
        v = b.vel.copy()
        w = b.omega.copy()
        with np.errstate(over="ignore", invalid="ignore"):   # the guard reports it
            v[inv_mass > 0] += self._gravity * dt
        self._guard(x, q, v, w)                     # before any kernel sees a bad value
        c = self._detect(x, quats_to_matrices(q), self._margin(v, w, dt))
        t1 = time.perf_counter()
        keys = WarmStart.keys_of(c, len(self._walls))
        t1v, t2v = solver.tangent_basis(c.normal)
        lam = self._warm.lookup(keys, t1v, t2v)
        e_c, beta_c, mu_c = per_contact(c.b, self._material, self._geometry())
        clamp_to_cone(lam, mu_c)
        ra, rb = lever_arms(c, x)
        con = solver.Constraints(c.a, c.b, c.normal, t1v, t2v, ra, rb, c.gap, e_c, beta_c, mu_c)
        invI = solver.world_inv_inertias(q, inv_inertia)
        rest = 2.0 * dt * float(np.sqrt((self._gravity ** 2).sum()))
        vn = solver.solve_velocities(con, lam, v, w, inv_mass, invI, dt, rest, self._slop(),
                                     self._vel_iters)
        self._guard(x, q, v, w)
        x += v * dt
        advance_all(q, w, inv_inertia, dt)
        solver.project_positions(con, c.gap + dt * vn, inv_mass, invI, self._slop(),
                                 self._pos_iters, x, q)
        self._domain.wrap(x)
        self._guard(x, q, v, w)
        t2 = time.perf_counter()
        # commit
        b.pos, b.quat, b.vel, b.omega = x, q, v, w
        self._warm.store(keys, lam, t1v, t2v)
        self._num_contacts = len(c.a)
        self._step_count += 1
        self._time += dt
        self.timings["solver"] += t2 - t1
        self.timings["total"] += t2 - t0

    def _guard(self, x, q, v, w):
        radii = self._radii()
        check_state(x, q, v, w, radii, speed_bound(self._domain, self._bodies.pos, radii),
                    self._step_count + 1)

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
