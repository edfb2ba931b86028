"""``peclet.dem.Simulation``: rigid-body DEM of spheres and composed analytic (CSG) particles.

Units are whatever the caller uses consistently (the page: lengths in ring diameters, seconds).
Frames and conventions:

- positions are the bodies' centres of mass, in the world frame;
- quaternions are (x, y, z, w), unit, active, body (principal, "home") frame -> world frame;
- velocities and angular velocities are in the world frame;
- inverse inertia is the diagonal of the inverse inertia tensor in the body's principal frame,
  stored per body as its actual values (1 / (mass length^2)); 0 = locked axis;
- inverse mass 0 = a body that contacts and gravity do not move (it keeps its velocity);
- trees follow the geometry core (phi < 0 inside, gradient outward); a scene shape's tree and
  shell probes are given in the body's home frame.

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

import os
import tempfile

import numpy as np
from numba import njit

from peclet.core.geom import SceneBuilder
from peclet.core.geom.program import compile_root, concatenate
from peclet.dem import broadphase, narrowphase, solver
from peclet.dem.rigid import advance_rotation, advance_rotations

#: Speed guard: |v| (and |omega| times the bounding radius) must stay below this many domain
#: sizes per unit time, or the step raises :class:`StepError`.
SPEED_BOUND_DOMAINS_PER_TIME = 1.0e3

#: Default speculative margin, as a fraction of the smallest bounding radius in use; the step
#: adds ``2 * max speed * dt`` so that no approach within one step goes unseen.
DEFAULT_MARGIN_FRACTION = 0.05

_WALL_BASE = 1 << 22      # key packing for the warm-start cache
_FEATURE_BITS = 26


#: A pair's manifold spreads over the hits within this fraction of the base margin of its
#: deepest point (the touching patch); farther speculative hits are represented by the deepest.
TOUCH_FRACTION = 0.1

#: Gaps below this fraction of the smallest bounding radius count as touching (see _slop).
SLOP_FRACTION = 5e-4

#: Below this estimated work (sphere-task units) the narrow phase runs serially.
SERIAL_WORK = 4000

#: Below this many bodies the rotation update runs serially: it costs ~0.2 us per body, and
#: on a loaded 2-core machine a parallel launch was measured at several milliseconds.
PARALLEL_ROTATION_MIN = 50000


@njit(cache=True)
def _advance_serial(quats, omegas, inv_inertia, dt):
    for i in range(quats.shape[0]):
        qn, wn = advance_rotation(quats[i], omegas[i], inv_inertia[i], dt)
        quats[i, :] = qn
        omegas[i, :] = wn


def _advance_rotations(quats, omegas, inv_inertia, dt):
    """Torque-free rotation of every body in place (rigid.advance_rotation; the batch and the
    scalar kernels give the same bits, so the choice never changes the result)."""
    if len(quats) >= PARALLEL_ROTATION_MIN:
        advance_rotations(quats, omegas, inv_inertia, dt)
    else:
        _advance_serial(quats, omegas, inv_inertia, dt)


class StepError(RuntimeError):
    """A step produced a non-finite or runaway state. ``step`` and ``particle`` name where.

    The simulation's state is left as it was before the failing step.
    """

    def __init__(self, message, step, particle):
        super().__init__(message)
        self.step = step
        self.particle = particle


def _finite_array(value, name, shape_tail, dtype=np.float64):
    a = np.asarray(value, dtype=dtype)
    if a.ndim != 1 + len(shape_tail) or tuple(a.shape[1:]) != tuple(shape_tail):
        tail = ", ".join(str(s) for s in shape_tail)
        raise ValueError(f"{name} must have shape (N, {tail}), got {a.shape}" if shape_tail
                         else f"{name} must have shape (N,), got {a.shape}")
    if dtype == np.float64 and not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite (no NaN or inf)")
    return np.ascontiguousarray(a)


def _positive(value, name):
    v = float(value)
    if not (np.isfinite(v) and v > 0.0):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return v


class Simulation:
    """A rigid-body DEM simulation.

    ``capacity`` is only a hint for the initial particle count: every buffer grows as needed,
    and results never depend on it.

    Particle count: :meth:`set_positions` defines N. While N is unchanged every other
    per-particle attribute (shape id, quaternion, velocities, masses, inertia) is KEPT, so
    ``set_positions`` and ``set_shape_ids`` may be called in either order. When N changes, the
    first min(N_old, N) particles keep their attributes, new particles get the defaults
    (shape 0, identity quaternion, zero velocities, inverse mass 1, inverse inertia of a
    uniform solid sphere of the shape's bounding radius) and the warm-start cache is cleared.
    Any per-particle setter called while N == 0 defines N the same way.
    """

    def __init__(self, capacity=1):
        cap = int(capacity)
        if cap < 0:
            raise ValueError(f"capacity must be an integer >= 0, got {capacity!r}")
        self._capacity_hint = cap
        self._n = 0
        self._pos = np.zeros((0, 3))
        self._vel = np.zeros((0, 3))
        self._omega = np.zeros((0, 3))
        self._quat = np.zeros((0, 4))
        self._shape = np.zeros(0, np.int64)
        self._inv_mass = np.zeros(0)
        self._inv_inertia = np.zeros((0, 3))   # NaN row = default (solid sphere)
        self._shapes = []
        self._walls = []
        self._flat = None
        self._e_n, self._e_t, self._mu = 0.5, 0.0, 0.5
        self._pos_iters, self._vel_iters = 10, 8
        self._gravity = np.zeros(3)
        self._lo = None
        self._hi = None
        self._periodic = np.zeros(3, np.bool_)
        self._dt = None
        self._step_count = 0
        self._time = 0.0
        self._margin_fraction = DEFAULT_MARGIN_FRACTION
        self._ws_keys = np.zeros(0, np.int64)
        self._ws_lam = np.zeros((0, 4))
        self._slot_capacity = max(1, cap) * narrowphase.MAX_PER_TASK
        self._num_contacts = 0
        #: Accumulated wall-clock seconds per phase (broad, narrow, solver = velocity solve +
        #: integration + projection, total), for the benchmark.
        self.timings = {"broad": 0.0, "narrow": 0.0, "solver": 0.0, "total": 0.0}

    # ------------------------------------------------------------------ configuration
    def set_domain(self, lo, hi):
        """Axis-aligned domain [lo, hi) (3 each). Used by periodic axes and the speed guard."""
        lo = np.asarray(lo, dtype=np.float64).reshape(-1)
        hi = np.asarray(hi, dtype=np.float64).reshape(-1)
        if lo.shape != (3,) or hi.shape != (3,):
            raise ValueError("lo and hi must have 3 components each")
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(hi > lo)):
            raise ValueError(f"domain needs finite lo < hi on every axis, got lo={lo}, hi={hi}")
        self._lo, self._hi = lo.copy(), hi.copy()

    def enable_periodicity(self, px, py, pz):
        """Periodic axes (bools). A periodic axis needs :meth:`set_domain` before stepping."""
        self._periodic = np.array([bool(px), bool(py), bool(pz)], np.bool_)

    def set_gravity(self, gx, gy, gz):
        """Gravitational acceleration (world frame, length / time^2)."""
        g = np.array([gx, gy, gz], dtype=np.float64)
        if not np.all(np.isfinite(g)):
            raise ValueError(f"gravity must be finite, got {g}")
        self._gravity = g

    def set_material_params(self, e_n, e_t, mu):
        """Body-body contact material: normal restitution ``e_n`` in [0, 1], tangential
        (Walton) restitution ``e_t`` in [-1, 1] (applied to colliding contacts only: the
        tangential velocity is driven to -e_t times its incoming value, within the Coulomb
        cone), Coulomb friction ``mu`` >= 0. Defaults (0.5, 0.0, 0.5)."""
        e_n, e_t, mu = float(e_n), float(e_t), float(mu)
        if not 0.0 <= e_n <= 1.0:
            raise ValueError(f"e_n must be in [0, 1], got {e_n}")
        if not -1.0 <= e_t <= 1.0:
            raise ValueError(f"e_t must be in [-1, 1], got {e_t}")
        if not (mu >= 0.0 and np.isfinite(mu)):
            raise ValueError(f"mu must be finite and >= 0, got {mu}")
        self._e_n, self._e_t, self._mu = e_n, e_t, mu

    def set_solver_iterations(self, position, velocity):
        """Gauss-Seidel sweeps of the position projection and of the velocity solve
        (integers >= 0; defaults 10 and 8)."""
        for nm, v in (("position", position), ("velocity", velocity)):
            if isinstance(v, bool) or int(v) != v or int(v) < 0:
                raise ValueError(f"{nm} iterations must be an integer >= 0, got {v!r}")
        self._pos_iters, self._vel_iters = int(position), int(velocity)

    def set_contact_margin_fraction(self, fraction):
        """Speculative margin as a fraction of the smallest bounding radius (default 0.05)."""
        self._margin_fraction = _positive(fraction, "fraction")

    def set_dt(self, dt):
        """Default time step for :meth:`step` (finite, > 0)."""
        self._dt = _positive(dt, "dt")

    def set_contact_capacity(self, n):
        """Initial size hint (contacts) of the narrow phase's buffers; any n >= 1 gives the same
        contacts: the buffers are grown from the measured task count before they are filled."""
        if isinstance(n, bool) or int(n) != n or int(n) < 1:
            raise ValueError(f"n must be an integer >= 1, got {n!r}")
        self._slot_capacity = int(n)

    @property
    def contact_capacity(self):
        """Current size (contacts) of the narrow phase's slot buffer (read-only)."""
        return self._slot_capacity

    # ------------------------------------------------------------------ shapes and walls
    def add_sphere_shape(self, radius):
        """Register a sphere of ``radius``; returns its shape id."""
        r = _positive(radius, "radius")
        self._shapes.append({"kind": 0, "radius": r, "shell": np.zeros((0, 3))})
        self._flat = None
        return len(self._shapes) - 1

    def add_scene_shape(self, node_ints, node_reals, root, shell_points, bounding_radius):
        """Register a composed CSG particle; returns its shape id.

        ``node_ints`` (n, 3) / ``node_reals`` (n, 16) is the flat encoding, ``root`` the node
        whose value (in its parent frame = the body's home frame, centred on the centre of
        mass, principal axes) is the particle; ``shell_points`` (M, 3) are surface probes in the
        same frame; ``bounding_radius`` a radius about the origin containing the solid (it is
        raised to the farthest probe if a probe lies outside it).
        """
        b = SceneBuilder.decode(node_ints, node_reals)
        if isinstance(root, bool) or int(root) != root or not 0 <= int(root) < b.num_nodes():
            raise ValueError(f"root must be a node index in [0, {b.num_nodes()}), got {root!r}")
        root = int(root)
        shell = _finite_array(shell_points, "shell_points", (3,))
        if len(shell) == 0:
            raise ValueError("shell_points must hold at least one probe")
        br = _positive(bounding_radius, "bounding_radius")
        br = max(br, float(np.sqrt((shell ** 2).sum(axis=1)).max()))
        ni, nr = b._node_arrays()
        self._shapes.append({
            "kind": 1, "radius": br, "shell": shell.copy(), "node_ints": np.asarray(ni),
            "node_reals": np.asarray(nr, dtype=np.float64), "root": root,
            "program": compile_root(ni, nr, root), "lip": bool(b.is_lipschitz(root))})
        self._flat = None
        return len(self._shapes) - 1

    def add_analytic_wall(self, node_ints, node_reals, root, invert, e, mu):
        """A static solid wall given by a CSG tree in the world frame (e.g. a box below the
        floor). ``invert=True`` makes the complement the solid (a container). ``e`` in [0, 1]
        and ``mu`` >= 0 are the wall's restitution and friction. Returns the wall index; in
        contact listings a wall appears as body ``-1 - index``."""
        b = SceneBuilder.decode(node_ints, node_reals)
        if isinstance(root, bool) or int(root) != root or not 0 <= int(root) < b.num_nodes():
            raise ValueError(f"root must be a node index in [0, {b.num_nodes()}), got {root!r}")
        root = int(root)
        e, mu = float(e), float(mu)
        if not 0.0 <= e <= 1.0:
            raise ValueError(f"e must be in [0, 1], got {e}")
        if not (mu >= 0.0 and np.isfinite(mu)):
            raise ValueError(f"mu must be finite and >= 0, got {mu}")
        ni, nr = b._node_arrays()
        self._walls.append({
            "node_ints": np.asarray(ni), "node_reals": np.asarray(nr, dtype=np.float64),
            "root": root, "invert": bool(invert), "e": e, "mu": mu,
            "program": compile_root(ni, nr, root), "lip": bool(b.is_lipschitz(root))})
        self._flat = None
        return len(self._walls) - 1

    def num_shapes(self):
        return len(self._shapes)

    def num_walls(self):
        return len(self._walls)

    # ------------------------------------------------------------------ particles
    def num_particles(self):
        """Number of particles N."""
        return self._n

    def _resize(self, n):
        old = self._n
        k = min(old, n)

        def grow(a, fill):
            out = np.empty((n,) + a.shape[1:], a.dtype)
            out[:k] = a[:k]
            out[k:] = fill
            return out
        self._pos = grow(self._pos, 0.0)
        self._vel = grow(self._vel, 0.0)
        self._omega = grow(self._omega, 0.0)
        self._quat = grow(self._quat, np.array([0.0, 0.0, 0.0, 1.0]))
        self._shape = grow(self._shape, 0)
        self._inv_mass = grow(self._inv_mass, 1.0)
        self._inv_inertia = grow(self._inv_inertia, np.nan)
        self._n = n
        self._ws_keys = np.zeros(0, np.int64)
        self._ws_lam = np.zeros((0, 4))

    def _per_particle(self, value, name, tail, dtype=np.float64):
        a = _finite_array(value, name, tail, dtype)
        if self._n == 0 and len(a) > 0:
            self._resize(len(a))
        elif len(a) != self._n:
            raise ValueError(f"{name} must have N = {self._n} rows, got {len(a)}")
        return a

    def set_positions(self, positions):
        """Centres of mass (N, 3), world frame. Defines N (see the class docstring)."""
        p = _finite_array(positions, "positions", (3,))
        if len(p) != self._n:
            self._resize(len(p))
        self._pos = p.astype(np.float64, copy=True)

    def get_positions(self):
        """(N, 3) float64 copy of the centres of mass."""
        return self._pos.copy()

    def set_shape_ids(self, ids):
        """Shape id per particle (N,), each a registered shape."""
        a = np.asarray(ids)
        if a.ndim != 1 or not (np.issubdtype(a.dtype, np.integer)
                               or (np.issubdtype(a.dtype, np.floating)
                                   and np.all(np.isfinite(a)) and np.all(a == np.round(a)))):
            raise ValueError(f"ids must be a 1-D array of integers, got {a.dtype} {a.shape}")
        a = a.astype(np.int64)
        if len(a) and (a.min() < 0 or a.max() >= len(self._shapes)):
            raise ValueError(f"ids must be registered shape ids in [0, {len(self._shapes)}), "
                             f"got values in [{a.min()}, {a.max()}]")
        a = self._per_particle(a, "ids", (), np.int64)
        self._shape = a.copy()

    def get_shape_ids(self):
        return self._shape.copy()

    def set_quaternions(self, quats):
        """Orientations (N, 4) as (x, y, z, w), body -> world; normalised on input. A zero
        quaternion raises ValueError."""
        q = self._per_particle(quats, "quats", (4,))
        nrm = np.sqrt((q ** 2).sum(axis=1))
        if np.any(nrm == 0.0):
            i = int(np.flatnonzero(nrm == 0.0)[0])
            raise ValueError(f"quats must be non-zero; row {i} is zero")
        self._quat = q / nrm[:, None]

    def get_quaternions(self):
        """(N, 4) float64 copy of the unit quaternions (x, y, z, w)."""
        return self._quat.copy()

    def set_inv_mass(self, inv_mass):
        """Inverse masses (N,), each >= 0 (0 = not moved by contacts or gravity)."""
        m = self._per_particle(inv_mass, "inv_mass", ())
        if np.any(m < 0.0):
            raise ValueError("inv_mass must be >= 0")
        self._inv_mass = m.astype(np.float64, copy=True)

    def get_inv_mass(self):
        return self._inv_mass.copy()

    def set_inv_inertia(self, inv_inertia):
        """Principal inverse moments of inertia (N, 3), each >= 0 (0 = locked axis)."""
        m = self._per_particle(inv_inertia, "inv_inertia", (3,))
        if np.any(m < 0.0):
            raise ValueError("inv_inertia must be >= 0")
        self._inv_inertia = m.astype(np.float64, copy=True)

    def get_inv_inertia(self):
        """(N, 3) principal inverse moments actually used (defaults resolved)."""
        return self._resolved_inv_inertia()

    def set_velocities(self, v):
        """Linear velocities (N, 3), world frame."""
        self._vel = self._per_particle(v, "velocities", (3,)).astype(np.float64, copy=True)

    def get_velocities(self):
        return self._vel.copy()

    def set_angular_velocities(self, w):
        """Angular velocities (N, 3), world frame, rad / time."""
        self._omega = self._per_particle(w, "angular_velocities", (3,)).astype(np.float64,
                                                                              copy=True)

    def get_angular_velocities(self):
        return self._omega.copy()

    @property
    def step_count(self):
        return self._step_count

    @property
    def time(self):
        return self._time

    # ------------------------------------------------------------------ derived quantities
    def _radii(self):
        r = np.array([s["radius"] for s in self._shapes], dtype=np.float64)
        return r[self._shape]

    def _resolved_inv_inertia(self):
        ii = self._inv_inertia.copy()
        bad = np.isnan(ii[:, 0]) if len(ii) else np.zeros(0, bool)
        if np.any(bad):
            if not self._shapes:
                raise ValueError("no shape registered: register a shape before stepping")
            r = self._radii()[bad]
            ii[bad] = (self._inv_mass[bad] * 2.5 / r ** 2)[:, None]
        return ii

    def kinetic_energy(self):
        """Translational plus rotational kinetic energy; bodies with inverse mass 0 contribute
        no translational part, locked axes no rotational part."""
        m = self._inv_mass > 0
        et = 0.5 * float(((self._vel[m] ** 2).sum(axis=1) / self._inv_mass[m]).sum())
        if self._n == 0:
            return et
        rot = narrowphase.rotation_matrices(self._quat)
        wb = np.einsum("nji,nj->ni", rot, self._omega)
        ii = self._resolved_inv_inertia()
        with np.errstate(divide="ignore", invalid="ignore"):
            er = np.where(ii > 0, wb ** 2 / ii, 0.0)
        return et + 0.5 * float(er.sum())

    def num_contacts(self):
        """Contacts (manifold points) used by the last step."""
        return self._num_contacts

    # ------------------------------------------------------------------ geometry tables
    def _flat_geometry(self):
        if self._flat is not None:
            return self._flat
        progs, kind, rad, lip, p0, clr = [], [], [], [], [], []
        probes, cl_centre, cl_rad, cl_range = [], [], [], []
        npro = ncl = 0
        for s in self._shapes:
            kind.append(s["kind"])
            rad.append(s["radius"])
            lip.append(s.get("lip", True))
            if s["kind"] == 1:
                progs.append(s["program"])
                order, rng, cen, crad = narrowphase.cluster_probes(s["shell"], s["radius"] / 4)
                probes.append(s["shell"][order])
                cl_centre.append(cen)
                cl_rad.append(crad)
                cl_range.append(rng + npro)
                p0.append(npro)
                clr.append((ncl, ncl + len(rng)))
                npro += len(order)
                ncl += len(rng)
            else:
                p0.append(npro)
                clr.append((ncl, ncl))
        for w in self._walls:
            progs.append(w["program"])
        if progs:
            ops, lk, lr, ranges = concatenate(progs)
        else:
            ops = np.zeros((1, 2), np.int32)
            lk = np.zeros(1, np.int32)
            lr = np.zeros((1, 24))
            ranges = np.zeros((0, 2), np.int64)
        shape_op = np.full((len(self._shapes), 2), -1, np.int64)
        k = 0
        for i, s in enumerate(self._shapes):
            if s["kind"] == 1:
                shape_op[i] = ranges[k]
                k += 1
        wall_op = np.asarray(ranges[k:], np.int64).reshape(-1, 2)
        maxm = max([len(s["shell"]) for s in self._shapes] + [1])
        self._flat = {
            "shape_kind": np.asarray(kind, np.int64), "shape_rad": np.asarray(rad, np.float64),
            "shape_op": shape_op, "shape_lip": np.asarray(lip, np.bool_),
            "shape_p0": np.asarray(p0, np.int64),
            "shape_cl": np.asarray(clr, np.int64).reshape(-1, 2),
            "cl_centre": np.concatenate(cl_centre) if cl_centre else np.zeros((0, 3)),
            "cl_rad": np.concatenate(cl_rad) if cl_rad else np.zeros(0),
            "cl_range": np.concatenate(cl_range) if cl_range else np.zeros((0, 2), np.int64),
            "probes": np.ascontiguousarray(np.concatenate(probes)) if probes
            else np.zeros((0, 3)),
            "wall_op": wall_op,
            "wall_sign": np.array([-1.0 if w["invert"] else 1.0 for w in self._walls]),
            "wall_lip": np.array([w["lip"] for w in self._walls], np.bool_),
            "wall_e": np.array([w["e"] for w in self._walls]),
            "wall_mu": np.array([w["mu"] for w in self._walls]),
            "ops": ops, "lk": lk, "lr": lr, "max_hits": 2 * maxm + 2,
        }
        return self._flat

    # ------------------------------------------------------------------ contacts
    def _check_ready(self):
        if self._n and not self._shapes:
            raise ValueError("no shape registered: add a shape before stepping")
        if self._n and self._shape.max() >= len(self._shapes):
            raise ValueError("shape ids refer to unregistered shapes")
        if self._periodic.any() and self._lo is None:
            raise ValueError("a periodic axis needs set_domain(lo, hi) first")

    def _wrap(self, pos):
        if self._periodic.any():
            for a in np.flatnonzero(self._periodic):
                L = self._hi[a] - self._lo[a]
                pos[:, a] = self._lo[a] + np.mod(pos[:, a] - self._lo[a], L)
                # np.mod may round up to exactly L
                pos[pos[:, a] >= self._hi[a], a] = self._lo[a]
        return pos

    def _margin(self, vel, omega, dt):
        radii = self._radii()
        speed = np.sqrt((vel ** 2).sum(axis=1)) + np.sqrt((omega ** 2).sum(axis=1)) * radii
        vmax = float(speed.max()) if len(speed) else 0.0
        base = self._margin_fraction * float(np.min([s["radius"] for s in self._shapes]))
        return base + 2.0 * vmax * (dt if dt is not None else 0.0)

    def _detect(self, pos, rot, margin):
        """All contacts of the state (pos, rot). Returns a dict of per-contact arrays."""
        import time
        t0 = time.perf_counter()
        fl = self._flat_geometry()
        n = self._n
        radii = fl["shape_rad"][self._shape]
        cutoff = 2.0 * float(radii.max()) + margin
        if self._periodic.any():
            for a in np.flatnonzero(self._periodic):
                L = self._hi[a] - self._lo[a]
                if L <= 2.0 * cutoff:
                    raise ValueError(
                        f"periodic axis {a}: the domain length {L} must exceed twice the "
                        f"interaction cutoff {cutoff} (2 * largest bounding radius + margin)")
        dlo = self._lo if self._lo is not None else np.zeros(3)
        dhi = self._hi if self._hi is not None else np.ones(3)
        lo, cell, dims, box = broadphase.grid_for(pos, cutoff, dlo, dhi, self._periodic,
                                                  max(64, 4 * n))
        pa, pb, shift = broadphase.find_pairs(pos, radii, margin, lo, cell, dims, box,
                                              self._periodic)
        nw = len(self._walls)
        if nw:
            wa = np.repeat(np.arange(n, dtype=np.int64), nw)
            wb = np.tile(-1 - np.arange(nw, dtype=np.int64), n)
            ta = np.concatenate([pa, wa])
            tb = np.concatenate([pb, wb])
            ts = np.concatenate([shift, np.zeros((len(wa), 3))])
            order = np.lexsort((tb, ta))
            ta, tb, ts = ta[order], tb[order], np.ascontiguousarray(ts[order])
        else:
            ta, tb, ts = pa, pb, shift
        t1 = time.perf_counter()
        ntask = len(ta)
        slots = ntask * narrowphase.MAX_PER_TASK
        if slots > self._slot_capacity:
            self._slot_capacity = max(slots, 2 * self._slot_capacity)
        cap = self._slot_capacity
        count = np.zeros(ntask, np.int64)
        point = np.empty((cap, 3))
        normal = np.empty((cap, 3))
        gap = np.empty(cap)
        feat = np.empty(cap, np.int64)
        scale = float(fl["shape_rad"].min())
        narrowphase.narrow_phase(
            ta, tb, ts, pos, rot, self._shape, fl["shape_kind"], fl["shape_rad"],
            fl["shape_op"], fl["shape_lip"], fl["shape_p0"], fl["shape_cl"], fl["cl_centre"],
            fl["cl_rad"], fl["cl_range"], fl["probes"], fl["wall_op"], fl["wall_sign"],
            fl["wall_lip"], fl["ops"], fl["lk"], fl["lr"], margin, fl["max_hits"],
            (1e-6 * scale) ** 2, TOUCH_FRACTION * self._margin_fraction * scale,
            self._narrow_chunks(ta, tb), count, point, normal, gap, feat)
        total = int(count.sum())
        excl = np.concatenate([[0], np.cumsum(count)[:-1]]) if ntask else np.zeros(0, np.int64)
        idx = (np.repeat(np.arange(ntask, dtype=np.int64) * narrowphase.MAX_PER_TASK - excl,
                         count) + np.arange(total, dtype=np.int64))
        t2 = time.perf_counter()
        self.timings["broad"] += t1 - t0
        self.timings["narrow"] += t2 - t1
        ca = np.repeat(ta, count)
        cb = np.repeat(tb, count)
        return {"a": ca, "b": cb, "shift": np.repeat(ts, count, axis=0),
                "point": point[idx], "normal": normal[idx], "gap": gap[idx], "feat": feat[idx]}

    def _slop(self):
        # a gap below the slop counts as touching in the velocity solve: no speculative
        # approach velocity is granted for it, so the sub-slop gaps the position projection
        # leaves behind do not feed velocity noise back into resting stacks
        return SLOP_FRACTION * float(self._flat_geometry()["shape_rad"].min())

    def _narrow_chunks(self, ta, tb):
        # rough work estimate: a task with a tree costs ~50 sphere tasks; below
        # SERIAL_WORK the parallel launch costs more than it saves. Either path gives the
        # same bits.
        kinds = self._flat["shape_kind"][self._shape]
        work = len(ta) + 49 * int(np.count_nonzero(kinds[ta] == 1))
        return 1 if work < SERIAL_WORK else 2

    def _keys(self, c):
        return ((c["a"] * _WALL_BASE + (c["b"] + len(self._walls) + 1)) << _FEATURE_BITS) \
            + c["feat"]

    def _current_contacts(self):
        self._check_ready()
        if self._n == 0 or not self._shapes:
            return None
        pos = self._wrap(self._pos.copy())
        rot = narrowphase.rotation_matrices(self._quat)
        return self._detect(pos, rot, self._margin(self._vel, self._omega, self._dt))

    def detect_contacts(self):
        """Contacts of the CURRENT state (nothing advances), sorted by (body_a, body_b,
        feature). Returns a dict of arrays: ``body_a``, ``body_b`` (a wall is -1 - index),
        ``point`` (n, 3) world, ``normal`` (n, 3) unit, from b towards a, ``depth`` (n,)
        penetration depth (negative = a speculative contact that is still apart),
        ``feature`` (n,) the probe id (offset by 2**24 for b's probes in a's tree)."""
        c = self._current_contacts()
        if c is None:
            return {"body_a": np.zeros(0, np.int64), "body_b": np.zeros(0, np.int64),
                    "point": np.zeros((0, 3)), "normal": np.zeros((0, 3)),
                    "depth": np.zeros(0), "feature": np.zeros(0, np.int64)}
        o = np.lexsort((c["feat"], c["b"], c["a"]))
        return {"body_a": c["a"][o], "body_b": c["b"][o], "point": c["point"][o],
                "normal": c["normal"][o], "depth": -c["gap"][o], "feature": c["feat"][o]}

    def compute_overlaps(self):
        """Maximum penetration depth (length, >= 0) over the current contacts."""
        c = self._current_contacts()
        if c is None or len(c["gap"]) == 0:
            return 0.0
        return float(max(0.0, -c["gap"].min()))

    def overlap_pairs(self):
        """Per pair (body_a, body_b, max depth) of the current contacts that overlap."""
        c = self.detect_contacts()
        m = c["depth"] > 0
        a, b, d = c["body_a"][m], c["body_b"][m], c["depth"][m]
        if len(a) == 0:
            return {"body_a": a, "body_b": b, "depth": d}
        key = np.stack([a, b], axis=1)
        uk, inv = np.unique(key, axis=0, return_inverse=True)
        mx = np.full(len(uk), -np.inf)
        np.maximum.at(mx, inv.reshape(-1), d)
        return {"body_a": uk[:, 0], "body_b": uk[:, 1], "depth": mx}

    # ------------------------------------------------------------------ the step
    def step(self, dt=None):
        """Advance by ``dt`` (else the :meth:`set_dt` value; with neither, ValueError).

        Raises :class:`StepError` (state unchanged) when a particle's state becomes
        non-finite or its speed exceeds ``1e3`` domain sizes per unit time (the domain size is
        the largest side of :meth:`set_domain`, else of the particles' bounding box plus two
        bounding radii)."""
        if dt is None:
            if self._dt is None:
                raise ValueError("dt: no time step given and none set with set_dt(dt)")
            dt = self._dt
        dt = _positive(dt, "dt")
        self._check_ready()
        if self._n == 0:
            self._step_count += 1
            self._time += dt
            return
        import time
        t0 = time.perf_counter()
        fl = self._flat_geometry()
        inv_mass = self._inv_mass
        inv_inertia = self._resolved_inv_inertia()
        x = self._wrap(self._pos.copy())
        q = self._quat.copy()
        v = self._vel.copy()
        w = self._omega.copy()
        with np.errstate(over="ignore", invalid="ignore"):   # the guard reports it
            v[inv_mass > 0] += self._gravity * dt
        self._guard(x, q, v, w)                     # before any kernel sees a bad value
        rot = narrowphase.rotation_matrices(q)
        margin = self._margin(v, w, dt)
        c = self._detect(x, rot, margin)
        t1 = time.perf_counter()
        nc = len(c["a"])
        keys = self._keys(c)
        lam = np.zeros((nc, 3))
        t1v, t2v = solver.tangent_basis(c["normal"])
        if nc and len(self._ws_keys):
            j = np.searchsorted(self._ws_keys, keys)
            j = np.minimum(j, len(self._ws_keys) - 1)
            hit = self._ws_keys[j] == keys
            old = self._ws_lam[j[hit]]
            lam[hit, 0] = old[:, 0]
            lam[hit, 1] = (old[:, 1:] * t1v[hit]).sum(axis=1)
            lam[hit, 2] = (old[:, 1:] * t2v[hit]).sum(axis=1)
        isw = c["b"] < 0
        bidx = np.where(isw, 0, c["b"])
        ra = c["point"] - x[c["a"]]
        rb = np.where(isw[:, None], 0.0, c["point"] - (x[bidx] + c["shift"]))
        widx = np.where(isw, -1 - c["b"], 0)
        if len(self._walls):
            e_c = np.where(isw, fl["wall_e"][widx], self._e_n)
            mu_c = np.where(isw, fl["wall_mu"][widx], self._mu)
        else:
            e_c = np.full(nc, self._e_n)
            mu_c = np.full(nc, self._mu)
        beta_c = np.full(nc, self._e_t)
        # the cone must hold for the warm-start impulses too
        tm = np.sqrt(lam[:, 1] ** 2 + lam[:, 2] ** 2)
        lim = mu_c * lam[:, 0]
        over = tm > lim
        if np.any(over):
            sc = np.where(tm[over] > 0, lim[over] / np.where(tm[over] > 0, tm[over], 1.0), 0.0)
            lam[over, 1] *= sc
            lam[over, 2] *= sc
        invI = solver.world_inv_inertias(q, inv_inertia)
        rest = 2.0 * dt * float(np.sqrt((self._gravity ** 2).sum()))
        vn = solver.solve_velocities(
            c["a"], c["b"], c["normal"], t1v, t2v, np.ascontiguousarray(ra),
            np.ascontiguousarray(rb), c["gap"], e_c, beta_c, mu_c, lam, v, w, inv_mass, invI,
            dt, rest, self._slop(), self._vel_iters)
        self._guard(x, q, v, w)
        x += v * dt
        _advance_rotations(q, w, inv_inertia, dt)
        gap_end = c["gap"] + dt * vn
        solver.project_positions(c["a"], c["b"], c["normal"], np.ascontiguousarray(ra),
                                 np.ascontiguousarray(rb), gap_end, inv_mass, invI,
                                 self._slop(), self._pos_iters, x, q)
        self._wrap(x)
        self._guard(x, q, v, w)
        t2 = time.perf_counter()
        # commit
        self._pos, self._quat, self._vel, self._omega = x, q, v, w
        lam_world = np.empty((nc, 4))
        lam_world[:, 0] = lam[:, 0]
        lam_world[:, 1:] = lam[:, 1:2] * t1v + lam[:, 2:3] * t2v
        o = np.argsort(keys, kind="stable")
        self._ws_keys = keys[o]
        self._ws_lam = lam_world[o]
        self._num_contacts = nc
        self._step_count += 1
        self._time += dt
        self.timings["solver"] += t2 - t1
        self.timings["total"] += t2 - t0

    def _speed_bound(self):
        if self._lo is not None:
            size = float((self._hi - self._lo).max())
        else:
            ext = self._pos.max(axis=0) - self._pos.min(axis=0)
            size = float(ext.max()) + 2.0 * float(self._radii().max())
        return SPEED_BOUND_DOMAINS_PER_TIME * size

    def _guard(self, x, q, v, w):
        step = self._step_count + 1
        bad = ~(np.isfinite(x).all(axis=1) & np.isfinite(q).all(axis=1)
                & np.isfinite(v).all(axis=1) & np.isfinite(w).all(axis=1))
        if np.any(bad):
            i = int(np.flatnonzero(bad)[0])
            raise StepError(f"step {step}: particle {i} has a non-finite state "
                            f"(x={x[i]}, v={v[i]}, omega={w[i]})", step, i)
        bound = self._speed_bound()
        speed = np.maximum(np.sqrt((v ** 2).sum(axis=1)),
                           np.sqrt((w ** 2).sum(axis=1)) * self._radii())
        fast = speed > bound
        if np.any(fast):
            i = int(np.flatnonzero(fast)[0])
            raise StepError(f"step {step}: particle {i} moves at {speed[i]:.6g} > the bound "
                            f"{bound:.6g} (1e3 domain sizes per unit time)", step, i)

    # ------------------------------------------------------------------ persistence
    def save(self, path):
        """Write the whole simulation (state, shapes, walls, parameters, warm-start cache) to
        ``path`` (.npz) atomically; :meth:`load` resumes it bitwise."""
        d = {
            "version": np.int64(1), "n": np.int64(self._n), "pos": self._pos,
            "vel": self._vel, "omega": self._omega, "quat": self._quat, "shape": self._shape,
            "inv_mass": self._inv_mass, "inv_inertia": self._inv_inertia,
            "material": np.array([self._e_n, self._e_t, self._mu]),
            "iters": np.array([self._pos_iters, self._vel_iters], np.int64),
            "gravity": self._gravity, "periodic": self._periodic,
            "domain": (np.stack([self._lo, self._hi]) if self._lo is not None
                       else np.zeros((0, 3))),
            "dt": np.array([] if self._dt is None else [self._dt]),
            "step_count": np.int64(self._step_count), "time": np.float64(self._time),
            "margin_fraction": np.float64(self._margin_fraction),
            "ws_keys": self._ws_keys, "ws_lam": self._ws_lam,
            "slot_capacity": np.int64(self._slot_capacity),
            "capacity_hint": np.int64(self._capacity_hint),
            "n_shapes": np.int64(len(self._shapes)), "n_walls": np.int64(len(self._walls)),
        }
        for i, s in enumerate(self._shapes):
            d[f"shape{i}_kind"] = np.int64(s["kind"])
            d[f"shape{i}_radius"] = np.float64(s["radius"])
            if s["kind"] == 1:
                d[f"shape{i}_ni"] = s["node_ints"]
                d[f"shape{i}_nr"] = s["node_reals"]
                d[f"shape{i}_root"] = np.int64(s["root"])
                d[f"shape{i}_shell"] = s["shell"]
        for i, w in enumerate(self._walls):
            d[f"wall{i}_ni"] = w["node_ints"]
            d[f"wall{i}_nr"] = w["node_reals"]
            d[f"wall{i}_root"] = np.int64(w["root"])
            d[f"wall{i}_prm"] = np.array([float(w["invert"]), w["e"], w["mu"]])
        path = os.fspath(path)
        folder = os.path.dirname(os.path.abspath(path))
        fd, tmp = tempfile.mkstemp(prefix=".peclet-dem-", suffix=".npz", dir=folder)
        try:
            with os.fdopen(fd, "wb") as f:
                np.savez(f, **d)
            os.replace(tmp, path)
        except BaseException:
            if os.path.exists(tmp):
                os.unlink(tmp)
            raise

    @classmethod
    def load(cls, path):
        """Rebuild a simulation written by :meth:`save`."""
        with np.load(os.fspath(path)) as z:
            d = {k: z[k] for k in z.files}
        sim = cls(int(d["capacity_hint"]))
        for i in range(int(d["n_shapes"])):
            if int(d[f"shape{i}_kind"]) == 0:
                sim.add_sphere_shape(float(d[f"shape{i}_radius"]))
            else:
                sim.add_scene_shape(d[f"shape{i}_ni"], d[f"shape{i}_nr"],
                                    int(d[f"shape{i}_root"]), d[f"shape{i}_shell"],
                                    float(d[f"shape{i}_radius"]))
        for i in range(int(d["n_walls"])):
            inv, e, mu = d[f"wall{i}_prm"]
            sim.add_analytic_wall(d[f"wall{i}_ni"], d[f"wall{i}_nr"], int(d[f"wall{i}_root"]),
                                  bool(inv), float(e), float(mu))
        sim._n = int(d["n"])
        sim._pos, sim._vel, sim._omega = d["pos"].copy(), d["vel"].copy(), d["omega"].copy()
        sim._quat, sim._shape = d["quat"].copy(), d["shape"].astype(np.int64)
        sim._inv_mass, sim._inv_inertia = d["inv_mass"].copy(), d["inv_inertia"].copy()
        sim._e_n, sim._e_t, sim._mu = (float(v) for v in d["material"])
        sim._pos_iters, sim._vel_iters = (int(v) for v in d["iters"])
        sim._gravity = d["gravity"].copy()
        sim._periodic = d["periodic"].astype(np.bool_)
        if len(d["domain"]):
            sim._lo, sim._hi = d["domain"][0].copy(), d["domain"][1].copy()
        sim._dt = float(d["dt"][0]) if len(d["dt"]) else None
        sim._step_count = int(d["step_count"])
        sim._time = float(d["time"])
        sim._margin_fraction = float(d["margin_fraction"])
        sim._ws_keys = d["ws_keys"].astype(np.int64)
        sim._ws_lam = d["ws_lam"].copy()
        sim._slot_capacity = int(d["slot_capacity"])
        return sim
