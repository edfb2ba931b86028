"""Known-bad engines that the certification suite must catch (and their correct twins).

Used by the suite's own tests and by anyone who wants to see a certificate fail:

- :class:`OverclaimingBoundBackend` flags ``hollow_cylinder_shell`` balls certified (it is
  sign-exact only, so Equation 1 fails far from it);
- :class:`TreeWalkBackend` evaluates the flat encoding node by node in numpy; with
  ``flip="torus"`` it flips the sign of every torus leaf;
- :func:`biased_cell_quadrature` counts cells whose centre has ``phi < bias * h``;
- :func:`thread_order_pour` adds to a running total with a ``prange`` float reduction
  (thread-count dependent);
- :class:`FixedBufferEngine` never grows its contact buffer (``grow=True`` is the correct twin);
- :class:`BadAnswerBackend` answers ``evaluate`` with something that is not a finite phi of the
  right shape (one of :data:`BAD_ANSWERS`); a factory per kind for ``--peclet-backend``;
- DEM engines (peclet.dem with one defect each; factories for ``--peclet-dem-backend``):
  :class:`NondeterministicSimulation` (random last bits: fails determinism at one thread),
  :class:`DroppingContactsSimulation` (a contact buffer that never grows: fails buffer
  growth, "silently wrong"), :class:`RefusingCapacitySimulation` (the same buffer, but an
  error naming it: fails buffer growth, "refused"), :class:`RestitutionOffSimulation` (e 5 % low: fails binary restitution);
- :class:`OverclaimingVolumeMassBackend` (volume 1e-4 off, claims 1e-8: fails the mass
  properties certificate; factory for ``--peclet-mass-backend``).
"""
from __future__ import annotations

from functools import partial

import numpy as np
from numba import njit, prange

from peclet.core.geom import SceneBuilder, quat_to_matrix

from .geometry.backend import ReferenceBackend

__all__ = ["OverclaimingBoundBackend", "TreeWalkBackend", "biased_cell_quadrature",
           "cell_quadrature", "thread_order_pour", "FixedBufferEngine", "fixed_buffer_engine",
           "growing_buffer_engine", "BadAnswerBackend", "BAD_ANSWERS", "nan_backend",
           "inf_backend", "none_backend", "empty_backend", "short_backend", "zero_backend",
           "raising_backend", "NondeterministicSimulation", "DroppingContactsSimulation",
           "RefusingCapacitySimulation", "RestitutionOffSimulation",
           "nondeterministic_dem_backend", "dropping_contacts_dem_backend",
           "refusing_capacity_dem_backend", "restitution_off_dem_backend",
           "OverclaimingVolumeMassBackend", "overclaiming_mass_backend"]

SHELL, HOLLOW_CYLINDER = 4, 2


class OverclaimingBoundBackend(ReferenceBackend):
    """Reference values, but its bound treats ``hollow_cylinder_shell`` as exact (certified)."""

    name = "overclaiming-shell-bound"

    def bound(self, node_ints, node_reals, root):
        ni = np.array(node_ints, dtype=np.int32)
        nr = np.array(node_reals, dtype=np.float64)
        for i in np.nonzero(ni[:, 0] == SHELL)[0]:
            ro, ri, h = nr[i, :3]
            # a hollow_cylinder with the same enclosing ball (both are centred at the origin)
            ni[i, 0] = HOLLOW_CYLINDER
            nr[i, :3] = (ro, h, min(ro - ri, ro * (1 - 1e-12)))
        return SceneBuilder.decode(ni, nr).node_bound(int(root))


class TreeWalkBackend:
    """A second evaluator: walks the encoding node by node in numpy (leaf formulas from the
    reference leaf table). ``flip`` names a leaf kind whose sign is flipped (a planted bug)."""

    def __init__(self, flip=None):
        from peclet.core.geom import leaf_spec
        self.flip = None if flip is None else leaf_spec(flip).kind
        self.name = "tree-walk" if flip is None else f"tree-walk(sign flip: {flip})"

    def evaluate(self, node_ints, node_reals, root, points):
        return self._node(np.asarray(node_ints), np.asarray(node_reals, float), int(root),
                          np.asarray(points, float))

    def _node(self, ni, nr, i, p):
        kind, left, right = (int(v) for v in ni[i])
        t, q, s = nr[i, 8:11], nr[i, 11:15], nr[i, 15]
        local = (p - t) @ quat_to_matrix(q) / s
        if left < 0:
            b = SceneBuilder()
            from peclet.core.geom import leaf_spec
            spec = leaf_spec(kind)
            leaf = b.add_leaf(kind, nr[i, :spec.n_params])
            phi = b.eval_root(leaf, local)
            if kind == self.flip:
                phi = -phi
        else:
            a = self._node(ni, nr, left, local)
            c = self._node(ni, nr, right, local)
            phi = {32: np.minimum(a, c), 33: np.maximum(a, c), 34: np.maximum(a, -c)}[kind]
        return s * phi


def cell_quadrature(builder, root, lo, hi, n, bias=0.0):
    """Midpoint cell rule on an n^3 grid over [lo, hi] counting cells with ``phi < bias * h``:
    (volume, com, principal moments ascending). ``bias = 0`` is merely first order; a
    positive bias is the planted one-sided error."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    h = (hi - lo) / n
    axes = [lo[k] + (np.arange(n) + 0.5) * h[k] for k in range(3)]
    X = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    w = (builder.eval_root(root, X) < bias * h.max()) * np.prod(h)
    v = w.sum()
    com = (w[:, None] * X).sum(axis=0) / v
    d = X - com
    r2 = (d * d).sum(axis=1)
    inertia = (w[:, None, None] * (r2[:, None, None] * np.eye(3) - d[:, :, None] * d[:, None, :])
               ).sum(axis=0)
    return float(v), com, np.sort(np.linalg.eigvalsh(inertia))


def biased_cell_quadrature(builder, root, lo, hi, tol):
    """:func:`cell_quadrature` with a half-cell outward bias (the planted quadrature bug), as a
    ``measure`` for :func:`quadrature_convergence`: ``tol`` picks about tol^(-1/3) cells per
    axis, the resolution an honest first-order cell rule would need."""
    n = int(min(48, max(8, round(tol ** (-1.0 / 3.0)))))
    return cell_quadrature(builder, root, lo, hi, n, bias=0.5)


@njit(parallel=True, cache=True)
def _racy_energy(pos, vel, total):
    # the planted bug: a prange float reduction onto a running total; numba combines the
    # per-thread partial sums in an order that depends on the thread count, so the bits do
    # too (already with two bodies once the total is non-zero)
    e = total
    for i in prange(len(pos)):
        e += 0.5 * (vel[i, 0] ** 2 + vel[i, 1] ** 2 + vel[i, 2] ** 2) + 9.81 * pos[i, 1]
    return e


def thread_order_pour(state, steps: int = 8):
    """A toy 'pour' that keeps a running energy total (dimensionless toy units) with a
    ``prange`` float reduction and feeds it back into the velocities: its bits depend on the
    thread count (the planted determinism bug). Returns [positions, velocities].

    Each step after the first is a fresh chance for the thread-count-dependent rounding, so
    nearly every state of two or more bodies shows it and a failing state shrinks to two."""
    pos = np.array(state.positions, float)
    vel = np.array(state.velocities, float)
    total = 0.0
    for _ in range(steps):
        total = _racy_energy(pos, vel, total)
        vel[:, 1] -= 1e-3 * total
        pos += 1e-3 * vel
    return [pos, vel]


@njit(cache=True)
def _write_contacts(buf, rows):
    # no capacity check on purpose: the caller is expected to have sized buf
    for k in range(rows.shape[0]):
        for j in range(rows.shape[1]):
            buf[k, j] = rows[k, j]
    return rows.shape[0]


class FixedBufferEngine:
    """Probe-vs-tree contact detection (brute force) writing into a contact buffer.

    With ``grow=False`` the buffer keeps the capacity it had at construction (the page
    engine's bug); with ``grow=True`` it is resized to the measured count first.
    """

    def __init__(self, ni, nr, root, probes, radius, positions, quaternions, grow,
                 capacity=4):
        self.b = SceneBuilder.decode(ni, nr)
        self.root, self.probes = int(root), np.asarray(probes, float)
        self.pos, self.quat = np.asarray(positions, float), np.asarray(quaternions, float)
        self.grow = grow
        self.buf = np.zeros((capacity, 9))

    def set_contact_capacity(self, n):
        if self.grow:
            self.buf = np.zeros((max(int(n), 1), 9))

    def detect_contacts(self):
        rows = []
        rots = [quat_to_matrix(q) for q in self.quat]
        for ia in range(len(self.pos)):
            world = self.probes @ rots[ia].T + self.pos[ia]
            for ib in range(len(self.pos)):
                if ia == ib:
                    continue
                local = (world - self.pos[ib]) @ rots[ib]
                phi, g = self.b.eval_root_grad(self.root, local)
                for k in np.nonzero(phi < 0.0)[0]:
                    rows.append([ia, ib, *world[k], *(rots[ib] @ g[k]), -phi[k]])
        rows = np.array(rows, float).reshape(-1, 9)
        if self.grow and len(rows) > len(self.buf):
            self.buf = np.zeros((len(rows), 9))  # count pass, then fill
        m = _write_contacts(self.buf, rows)
        out = self.buf[:m]
        return {"body_a": out[:, 0], "body_b": out[:, 1], "point": out[:, 2:5],
                "normal": out[:, 5:8], "depth": out[:, 8]}


def fixed_buffer_engine(ni, nr, root, probes, radius, positions, quaternions):
    """Factory for :func:`peclet_verify.dem.buffers.buffer_growth`: the never-grown buffer."""
    return FixedBufferEngine(ni, nr, root, probes, radius, positions, quaternions, grow=False)


def growing_buffer_engine(ni, nr, root, probes, radius, positions, quaternions):
    """Factory: the correct twin (count, then size the buffer)."""
    return FixedBufferEngine(ni, nr, root, probes, radius, positions, quaternions, grow=True)


def sign_flip_torus_backend():
    """Factory (for ``--peclet-backend``): the tree walk with every torus leaf's sign flipped."""
    return TreeWalkBackend(flip="torus")


def overclaiming_backend():
    """Factory (for ``--peclet-backend``): :class:`OverclaimingBoundBackend`."""
    return OverclaimingBoundBackend()


#: The unusable answers :class:`BadAnswerBackend` can plant, each with what it answers.
BAD_ANSWERS = {
    "nan": "NaN at every point",
    "inf": "the reference phi, but +inf wherever it is positive (outside)",
    "none": "None",
    "empty": "an empty array",
    "short": "the reference phi without its last point",
    "zero": "0.0 at every point",
    "raise": "raises RuntimeError",
}


class BadAnswerBackend:
    """An engine whose ``evaluate`` answers one of :data:`BAD_ANSWERS` (``bad``).

    Every certificate that asks it must fail: comparisons with NaN are never violations, +inf
    outside satisfies every inequality, and a short or empty answer broadcasts or slices
    silently, so none of these is caught by the figures alone."""

    def __init__(self, bad):
        if bad not in BAD_ANSWERS:
            raise ValueError(f"bad must be one of {sorted(BAD_ANSWERS)}, got {bad!r}")
        self.bad = bad
        self.name = f"bad-answer({bad})"
        self._reference = ReferenceBackend()

    def evaluate(self, node_ints, node_reals, root, points):
        n = len(points)
        if self.bad == "raise":
            raise RuntimeError("planted: this engine raises on every call")
        if self.bad == "none":
            return None
        if self.bad == "nan":
            return np.full(n, np.nan)
        if self.bad == "empty":
            return np.zeros(0)
        if self.bad == "zero":
            return np.zeros(n)
        phi = self._reference.evaluate(node_ints, node_reals, root, points)
        if self.bad == "inf":
            return np.where(phi > 0, np.inf, phi)
        return phi[:-1]  # short


# Factories for ``--peclet-backend`` (e.g. ``peclet_verify.planted:nan_backend``), one per
# planted bad answer: NaN everywhere; +inf wherever the reference is positive; None; an empty
# array; one value fewer than asked for; 0.0 everywhere; an exception on every call.
nan_backend = partial(BadAnswerBackend, "nan")
inf_backend = partial(BadAnswerBackend, "inf")
none_backend = partial(BadAnswerBackend, "none")
empty_backend = partial(BadAnswerBackend, "empty")
short_backend = partial(BadAnswerBackend, "short")
zero_backend = partial(BadAnswerBackend, "zero")
raising_backend = partial(BadAnswerBackend, "raise")


# ---------------------------------------------------------------------------- DEM and mass
# Known-bad engines of the DEM and mass-property families: each is peclet's own engine with
# ONE defect, so each fails exactly the certificate that looks for that defect.
class _PecletPage:
    """peclet.dem.Simulation behind the page's API (everything delegated)."""

    def __init__(self, capacity):
        from peclet.dem import Simulation
        self._sim = Simulation(capacity)

    def __getattr__(self, item):
        return getattr(self._sim, item)


def _last_bit_noise(a):
    """``a`` with a random last-bit change on random elements (at least one): fresh OS
    entropy every call, so two identical runs differ."""
    a = np.array(a, dtype=np.float64)
    rng = np.random.default_rng()  # unseeded on purpose: the planted nondeterminism
    flat = a.reshape(-1)
    if flat.size:
        step = rng.integers(-1, 2, flat.size)
        step[rng.integers(flat.size)] = 1
        flat[:] = np.where(step > 0, np.nextafter(flat, np.inf),
                           np.where(step < 0, np.nextafter(flat, -np.inf), flat))
    return a


class NondeterministicSimulation(_PecletPage):
    """Planted: every getter answers the state with random last-bit noise (the kind a racy
    parallel reduction leaves), never fed back into the state. Two runs at one thread differ;
    the physics is untouched (errors of 1e-16)."""

    def get_positions(self):
        return _last_bit_noise(self._sim.get_positions())

    def get_quaternions(self):
        return _last_bit_noise(self._sim.get_quaternions())

    def get_velocities(self):
        return _last_bit_noise(self._sim.get_velocities())

    def get_angular_velocities(self):
        return _last_bit_noise(self._sim.get_angular_velocities())


class DroppingContactsSimulation(_PecletPage):
    """Planted: a contact buffer that never grows. Its size is the constructor's hint
    (``capacity`` x 16 contacts, peclet's initial slot buffer) or the last
    ``set_contact_capacity(n)``; every contact beyond it is silently dropped. Under ample
    hints it is peclet."""

    def __init__(self, capacity):
        super().__init__(capacity)
        from peclet.dem.narrowphase import MAX_PER_TASK
        self.buffer = max(1, int(capacity)) * MAX_PER_TASK
        det = self._sim.world.detector      # a planted fault wraps the engine's detector
        detect = det.detect

        def truncated(*args, **kwargs):
            c = detect(*args, **kwargs)
            if len(c.a) <= self.buffer:
                return c
            return type(c)(*(f[:self.buffer] for f in c))
        truncated.__wrapped__ = detect
        det.detect = truncated

    def set_contact_capacity(self, n):
        self._sim.set_contact_capacity(n)
        self.buffer = int(n)


class RefusingCapacitySimulation(DroppingContactsSimulation):
    """Planted: the same fixed buffer, but a step that needs more contacts than it holds
    stops with an error naming the capacity (an engine that refuses clearly: it fails the
    buffer-growth certificate as "refused", not "silently wrong")."""

    def __init__(self, capacity):
        super().__init__(capacity)
        det = self._sim.world.detector
        truncated = det.detect

        def refusing(*args, **kwargs):
            c = truncated.__wrapped__(*args, **kwargs)
            if len(c.a) > self.buffer:
                raise RuntimeError(f"contact buffer full: {len(c.a)} contacts, capacity "
                                   f"{self.buffer} (raise set_contact_capacity)")
            return c
        det.detect = refusing


class RestitutionOffSimulation(_PecletPage):
    """Planted: every normal restitution (body material, walls, pairs) is taken 5 % low."""

    FACTOR = 0.95

    def set_material_params(self, e_n, e_t, mu):
        self._sim.set_material_params(self.FACTOR * e_n, e_t, mu)

    def add_analytic_wall(self, node_ints, node_reals, root, invert, e_n, mu):
        return self._sim.add_analytic_wall(node_ints, node_reals, root, invert,
                                           self.FACTOR * e_n, mu)

    def set_pair_material(self, a, b, e_n, e_t, mu):
        self._sim.set_pair_material(a, b, self.FACTOR * e_n, e_t, mu)


def _planted_dem(cls, name):
    from .dem.backend import PageApiBackend, numba_thread_counts, numba_threads
    return PageApiBackend(cls, numba_threads, name=name, thread_counts=numba_thread_counts())


def nondeterministic_dem_backend():
    """Factory (``--peclet-dem-backend``): :class:`NondeterministicSimulation`."""
    return _planted_dem(NondeterministicSimulation, "planted: nondeterministic at one thread")


def dropping_contacts_dem_backend():
    """Factory (``--peclet-dem-backend``): :class:`DroppingContactsSimulation`."""
    return _planted_dem(DroppingContactsSimulation, "planted: drops contacts (small buffer)")


def refusing_capacity_dem_backend():
    """Factory (``--peclet-dem-backend``): :class:`RefusingCapacitySimulation`."""
    return _planted_dem(RefusingCapacitySimulation, "planted: refuses a full contact buffer")


def restitution_off_dem_backend():
    """Factory (``--peclet-dem-backend``): :class:`RestitutionOffSimulation`."""
    return _planted_dem(RestitutionOffSimulation, "planted: restitution 5 % low")


class OverclaimingVolumeMassBackend:
    """Planted: peclet's quadrature with every volume 1e-4 (relative) too large, while it
    claims a volume error of 1e-8 of the volume."""

    name = "planted: volume 1e-4 off, claims 1e-8"

    def __init__(self):
        from .mass.backend import PecletMassBackend
        self._ref = PecletMassBackend(claim="estimate")
        self.resolutions, self.order, self.constant = (self._ref.resolutions, self._ref.order,
                                                       self._ref.constant)

    def mass_properties(self, node_ints, node_reals, root, lo, hi, resolution_or_tol):
        v, com, inertia, claimed = self._ref.mass_properties(node_ints, node_reals, root, lo,
                                                             hi, resolution_or_tol)
        return v * (1.0 + 1e-4), com, inertia, {"volume": 1e-8 * v,
                                                "inertia": claimed["inertia"]}


def overclaiming_mass_backend():
    """Factory (``--peclet-mass-backend``): :class:`OverclaimingVolumeMassBackend`."""
    return OverclaimingVolumeMassBackend()
