"""Deposition protocols: the page's (drop all, taps, quench) and rain (batches from the top).

Units: lengths in element diameters D (scaled by the element's D in world lengths), time in
the page's units (gravity 9.81 D / time^2, so a library element of D = 1 falls as on the page),
speeds in D / time, kinetic energies relative to ``m g D`` per element.

A protocol is a resumable state machine: :class:`RunState` (step, phase, step within the phase,
elements inserted, consecutive calm steps, the numpy generator's state, kinetic-energy history)
is all it keeps between steps, so a checkpoint of the Simulation plus the RunState resumes a
run bit for bit (``checkpoint.py``). :func:`drive` is the one stepping loop of every protocol
and of ``pour.pour``.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields

import numpy as np

from peclet.core.validation import PecletArgumentError, check_float, check_int

__all__ = ["PageProtocol", "RainProtocol", "RunState", "Body", "start_cloud", "drive",
           "parse_protocol", "new_simulation", "insert_bodies"]

G = 9.81


def _check_fields(obj, ints=(), floats=()):
    for name in ints:
        object.__setattr__(obj, name, check_int(name, getattr(obj, name), 0))
    for name, lo, hi, lo_open in floats:
        object.__setattr__(obj, name, check_float(name, getattr(obj, name), lo, hi, lo_open))


@dataclass
class Body:
    """The element as the protocols see it: its DEM shape id, mass, inverse principal moments
    (3,), bounding radius r_b about the centre of mass and diameter D (world lengths)."""

    shape_id: int
    mass: float
    inv_inertia: np.ndarray
    r_b: float
    d: float


@dataclass
class RunState:
    """Everything a protocol carries from one step to the next (JSON-able but ``ke``)."""

    step: int = 0
    phase: int = 0
    in_phase: int = 0
    inserted: int = 0
    calm: int = 0
    done: bool = False
    label: str = ""
    rng: dict = None
    ke: list = field(default_factory=list)

    def to_json(self):
        d = asdict(self)
        d.pop("ke")
        return d

    @classmethod
    def from_json(cls, d, ke):
        return cls(ke=list(ke), **d)


# ---------------------------------------------------------------------------- page
@dataclass(frozen=True)
class PageProtocol:
    """The page's protocol (its values by default).

    pour_steps free fall and settling; ``taps`` times: add ``tap_speed`` (D/time, +y) to every
    body's velocity, then ``tap_steps``; ``relax_steps``; ``quench_steps`` with every linear
    and angular velocity multiplied by ``damp`` after each step. ``dt`` is the step (time).
    Every body starts in the page's loose start cloud (:func:`start_cloud`).
    """

    pour_steps: int = 1400
    taps: int = 2
    tap_speed: float = 0.8
    tap_steps: int = 400
    relax_steps: int = 600
    quench_steps: int = 900
    damp: float = 0.96
    dt: float = 2e-3
    kind = "page"

    def __post_init__(self):
        _check_fields(self, ("pour_steps", "taps", "tap_steps", "relax_steps", "quench_steps"),
                      (("tap_speed", 0.0, math.inf, False), ("damp", 0.0, 1.0, True),
                       ("dt", 0.0, math.inf, True)))

    def scaled(self, factor):
        """The same protocol with every step count multiplied by ``factor`` (> 0), rounded, at
        least 1 step per non-empty phase (reduced runs for tests)."""
        factor = check_float("steps scale", factor, 0.0, lo_open=True)
        s = lambda n: 0 if n == 0 else max(1, int(round(n * factor)))  # noqa: E731
        return PageProtocol(s(self.pour_steps), self.taps, self.tap_speed, s(self.tap_steps),
                            s(self.relax_steps), s(self.quench_steps), self.damp, self.dt)

    @property
    def total_steps(self) -> int:
        return (self.pour_steps + self.taps * self.tap_steps + self.relax_steps
                + self.quench_steps)

    def estimate_steps(self, count):
        return self.total_steps

    def _phases(self):
        """[(label, first step, steps, kick, damp)]."""
        out, s = [("pour", 0, self.pour_steps, False, False)], self.pour_steps
        for _ in range(self.taps):
            out.append(("tap", s, self.tap_steps, True, False))
            s += self.tap_steps
        out.append(("relax", s, self.relax_steps, False, False))
        out.append(("quench", s + self.relax_steps, self.quench_steps, False, True))
        return out

    def phases(self):
        """[(label, first step)] of the phases, as the page marks them on its plot."""
        return [(p[0], p[1]) for p in self._phases()]

    def start(self, ctx, rng):
        """(positions, quaternions, velocities) of the start cloud and the cloud's top y."""
        body, cont = ctx["body"], ctx["container"]
        d = body.d
        gap = max(1.55 * d, 2.0 * body.r_b + 0.05 * d)
        y0 = cont.floor_y + max(1.2 * d, body.r_b + 0.1 * d)
        P, Q = start_cloud(ctx["count"], cont, rng, y0=y0, gap=gap, dy=0.15 * d,
                           clearance=body.r_b)
        return P, Q, np.zeros_like(P), float(P[:, 1].max())

    def step(self, sim, ctx, st, rng):
        """One step (a tap's kick first where a tap starts); returns the kinetic energy."""
        dt = self.dt
        for label, first, n, kick, _ in self._phases():
            if kick and first == st.step:
                v = np.array(sim.get_velocities(), dtype=np.float64)
                v[:, 1] += self.tap_speed * ctx["body"].d
                sim.set_velocities(v)
        label, damp = "", False
        for lab, first, n, _, dmp in self._phases():
            if first <= st.step < first + n:
                label, damp = lab, dmp
                break
        sim.step(dt)
        if damp:
            sim.set_velocities(np.asarray(sim.get_velocities()) * self.damp)
            sim.set_angular_velocities(np.asarray(sim.get_angular_velocities()) * self.damp)
        st.step += 1
        st.label = label
        st.done = st.step >= self.total_steps
        return float(sim.kinetic_energy())

    def to_spec(self):
        return dict(kind="page", **{f.name: getattr(self, f.name) for f in fields(self)})


# ---------------------------------------------------------------------------- rain
@dataclass(frozen=True)
class RainProtocol:
    """Rain deposition: elements inserted in small batches above the bed at a set rate.

    Every ``insert_every`` steps up to ``batch`` elements are placed at random (x, z) in the
    container (admissible for their bounding radius r_b) at the height ``drop`` D above the
    bed's top (the highest point of any body moving slower than ``rest_speed`` D/time; the
    floor when there is none; in a closed tree container at most the highest height with
    room), with random orientations, moving down at ``speed`` D/time. A candidate whose
    bounding sphere comes within ``spacing`` D of another body's is dropped (``attempts``
    candidates are drawn per batch; a batch may insert fewer, even none). The insertion rate
    is thus up to ``batch / (insert_every dt)``
    elements per unit time; they strike the bed at about sqrt(speed^2 + 2 g drop).
    When all ``count`` elements are in, "settle": until the kinetic energy per element stays
    below ``ke_tol`` m g D for ``calm_steps`` consecutive steps, or ``settle_steps`` steps
    (the step budget). Then ``taps`` times: add ``tap_speed`` (D/time, +y) to every velocity,
    ``tap_steps``, settle again. Last, ``quench_steps`` with velocities multiplied by ``damp``
    after each step. ``dt`` is the time step.
    """

    batch: int = 1
    insert_every: int = 4
    drop: float = 30.0
    speed: float = 2.0
    rest_speed: float = 1.0
    spacing: float = 0.02
    attempts: int = 200
    ke_tol: float = 1e-5
    calm_steps: int = 100
    settle_steps: int = 6000
    taps: int = 0
    tap_speed: float = 0.8
    tap_steps: int = 400
    quench_steps: int = 200
    damp: float = 0.96
    dt: float = 2e-3
    kind = "rain"

    def __post_init__(self):
        _check_fields(self, ("batch", "insert_every", "attempts", "calm_steps", "settle_steps",
                             "taps", "tap_steps", "quench_steps"),
                      (("drop", 0.0, math.inf, False), ("speed", 0.0, math.inf, False),
                       ("rest_speed", 0.0, math.inf, True), ("spacing", 0.0, math.inf, False),
                       ("ke_tol", 0.0, math.inf, True), ("tap_speed", 0.0, math.inf, False),
                       ("damp", 0.0, 1.0, True), ("dt", 0.0, math.inf, True)))
        for name in ("batch", "insert_every", "attempts", "calm_steps"):
            check_int(name, getattr(self, name), 1)

    def _phases(self):
        return ["rain", "settle"] + ["tap", "settle"] * self.taps + \
            (["quench"] if self.quench_steps else [])

    def estimate_steps(self, count):
        """A rough total for the progress bar (the KE criterion decides the real one)."""
        fall = math.sqrt(2.0 * self.drop / G) / self.dt
        return int(math.ceil(count / self.batch) * self.insert_every + fall + 1500
                + self.taps * (self.tap_steps + 1500) + self.quench_steps)

    def start(self, ctx, rng):
        cont, body = ctx["container"], ctx["body"]
        clear = body.r_b * (1 + 1e-9)
        y = min(cont.floor_y + body.r_b + self.drop * body.d, cont.ceiling(clear))
        if not (y >= cont.floor_y + body.r_b and cont.fits(clear, y)):
            raise PecletArgumentError("container", "a container that encloses the insertion "
                                      "zone (room for one element above the floor)",
                                      cont.label())
        e = np.zeros((0, 3))
        return e, np.zeros((0, 4)), e, None

    def top_bound(self, ctx):
        """A height no insertion reaches: the bed's top is at most the count's elements
        stacked one on another."""
        b = ctx["body"]
        return ctx["container"].floor_y + ctx["count"] * 2.0 * b.r_b + (self.drop + 4.0) * b.d

    def _batch(self, sim, ctx, st, rng):
        cont, body, d = ctx["container"], ctx["body"], ctx["body"].d
        n0 = sim.num_particles()
        P = np.asarray(sim.get_positions()) if n0 else np.zeros((0, 3))
        V = np.asarray(sim.get_velocities()) if n0 else np.zeros((0, 3))
        rest = (V ** 2).sum(axis=1) < (self.rest_speed * d) ** 2
        top = max([cont.floor_y] + ([float(P[rest, 1].max()) + body.r_b] if rest.any() else []))
        y = min(top + self.drop * d, cont.ceiling(body.r_b * (1 + 1e-9)))
        if y + body.r_b > ctx["y_top"]:
            raise RuntimeError(f"rain: insertion height {y:.3f} above the container's top "
                               f"{ctx['y_top']:.3f}")
        want = min(ctx["count"] - st.inserted, self.batch)
        per, L = cont.periodic[0], cont.period
        sep2 = (2.0 * body.r_b + self.spacing * d) ** 2
        near = P[np.abs(P[:, 1] - y) < 2.0 * body.r_b + self.spacing * d]
        new = []
        for c in cont.sample_many(rng, body.r_b * (1 + 1e-9), y, self.attempts):
            if len(new) >= want:
                break
            others = np.vstack([near] + [np.array(new)]) if new else near
            dx, dy, dz = c[0] - others[:, 0], y - others[:, 1], c[1] - others[:, 2]
            if per:
                dx = dx - L[0] * np.round(dx / L[0])
                dz = dz - L[1] * np.round(dz / L[1])
            if np.all(dx * dx + dy * dy + dz * dz >= sep2):
                new.append([c[0], y, c[1]])
        k = len(new)
        if k == 0:
            return
        q = rng.normal(size=(k, 4))
        q /= np.linalg.norm(q, axis=1)[:, None]
        v = np.zeros((k, 3))
        v[:, 1] = -self.speed * d
        insert_bodies(sim, body, np.array(new), q, v)
        st.inserted += k

    def step(self, sim, ctx, st, rng):
        body = ctx["body"]
        ph = self._phases()
        name = ph[st.phase]
        if name == "rain" and st.in_phase % self.insert_every == 0 \
                and st.inserted < ctx["count"]:
            if st.in_phase > 50 * self.insert_every * ctx["count"]:
                raise RuntimeError(f"rain: {st.inserted} of {ctx['count']} elements inserted "
                                   "after 50 tries each: the container is full")
            self._batch(sim, ctx, st, rng)
        if name == "tap" and st.in_phase == 0:
            v = np.array(sim.get_velocities(), dtype=np.float64)
            v[:, 1] += self.tap_speed * body.d
            sim.set_velocities(v)
        sim.step(self.dt)
        if name == "quench":
            sim.set_velocities(np.asarray(sim.get_velocities()) * self.damp)
            sim.set_angular_velocities(np.asarray(sim.get_angular_velocities()) * self.damp)
        ke = float(sim.kinetic_energy())
        st.step += 1
        st.in_phase += 1
        st.label = name
        ke_per = ke / (max(sim.num_particles(), 1) * body.mass * G * body.d)
        st.calm = st.calm + 1 if ke_per < self.ke_tol else 0
        end = {"rain": st.inserted >= ctx["count"],
               "settle": st.calm >= self.calm_steps or st.in_phase >= self.settle_steps,
               "tap": st.in_phase >= self.tap_steps,
               "quench": st.in_phase >= self.quench_steps}[name]
        if end:
            st.phase += 1
            st.in_phase = 0
            st.calm = 0
            st.done = st.phase >= len(ph)
        return ke

    def to_spec(self):
        return dict(kind="rain", **{f.name: getattr(self, f.name) for f in fields(self)})


def parse_protocol(value):
    """A protocol from "page", "rain", a protocol object or a ``to_spec()`` dict."""
    if isinstance(value, (PageProtocol, RainProtocol)):
        return value
    if isinstance(value, str) and value in ("page", "rain"):
        return PageProtocol() if value == "page" else RainProtocol()
    if isinstance(value, dict) and value.get("kind") in ("page", "rain"):
        kw = {k: v for k, v in value.items() if k != "kind"}
        try:
            return (PageProtocol if value["kind"] == "page" else RainProtocol)(**kw)
        except TypeError:
            pass
    raise PecletArgumentError("protocol", "'page', 'rain', a PageProtocol or a RainProtocol",
                              value)


# ---------------------------------------------------------------------------- helpers
def start_cloud(n, container, rng, y0=1.2, gap=1.55, dy=0.15, lookback=14, clearance=0.0):
    """The page's loose non-overlapping start cloud and random orientations.

    Bodies are placed one by one at an (x, z) drawn by ``container.sample_xz`` (uniform in
    [0, L)^2 for the page's box) and the current height y (starting at ``y0``); a candidate
    is accepted if, against each of the last ``lookback`` accepted, it is more than ``gap``
    away horizontally OR vertically; otherwise y grows by ``dy``. Orientations are normalised
    4-D Gaussians (uniform on SO(3)). Returns (positions (n, 3), quaternions (n, 4)), drawn
    from ``rng`` in the page's order.
    """
    pos, y = [], float(y0)
    while len(pos) < int(n):
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
    already in keep their state; the warm-start cache is cleared, as any change of N does)."""
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


def new_simulation(register, container, material, wall_material, iterations, gravity, dt,
                   y_top, count):
    """A Simulation set up as the page does (domain, periodicity, gravity, materials, solver
    sweeps, the shape via ``register(sim)``, the container's walls, dt). Returns (sim, sid)."""
    from peclet.dem import Simulation

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


def drive(sim, protocol, ctx, st, rng, max_steps=None, on_step=None):
    """Step ``protocol`` from ``st`` until it is done or ``st.step`` reaches ``max_steps``;
    appends each step's kinetic energy to ``st.ke`` and calls ``on_step(st)`` after it."""
    while not st.done and (max_steps is None or st.step < max_steps):
        st.ke.append(protocol.step(sim, ctx, st, rng))
        if on_step is not None:
            on_step(st)
    return st
