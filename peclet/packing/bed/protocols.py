"""Deposition protocols: the page's (drop all, taps, quench) and rain (batches from the top).

Units: lengths in element diameters D (scaled by the element's D in world lengths), time in
the page's units (gravity 9.81 D / time^2, so a library element of D = 1 falls as on the page),
speeds in D / time, kinetic energies relative to ``m g D`` per element.

A protocol is a resumable state machine: :class:`RunState` (step, phase, step within the phase,
elements inserted, consecutive calm steps, the numpy generator's state, kinetic-energy history)
is all it keeps between steps, so a checkpoint of the Simulation plus the RunState resumes a
run bit for bit (``checkpoint.py``). :func:`drive` is the one stepping loop of every protocol
and of ``pour.pour``.

Landing rule (every protocol): when the quench starts (or, for a run without a quench, when it
ends) :func:`drive` records in ``RunState.landing`` how many bodies move faster than
:data:`LAND_SPEED` (1 D/time: the speed of a free fall of 0.05 D, the rain protocol's default
``rest_speed`` for a body at rest on the bed). A run with any such body did not land: its
quench froze falling or bouncing elements, and the result is flagged (``PackResult.landed``
False, a :class:`LandingWarning`; ``peclet pack`` refuses to analyse it). When the run ends,
:func:`drive` also counts the bodies still in the air (:func:`in_air`: no chain of bounding
spheres within :data:`AIR_GAP` D of one another reaches the floor, or a tree container's wall);
a run that ends with any is flagged the same way (the speed rule misses a body that the quench
slowed in mid-air: a batch inserted at rest and quenched at once falls at ~0.5 D/time).
Recording reads the state only: a run's bits are the same with or without it. The page
protocol's landing can also be predicted before any work from its start cloud
(:meth:`PageProtocol.check_landing`, the rule of ``peclet pall-ring``).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields
from typing import NamedTuple

import numpy as np

from peclet.core.validation import PecletArgumentError, check_float, check_int
from peclet.packing.bed.containers import MAX_DROP
from peclet.packing.bed.contact import advance

__all__ = ["Protocol", "Phase", "PROTOCOLS", "PageProtocol", "RainProtocol", "RunState", "Body",
           "start_cloud", "drive", "parse_protocol", "new_simulation", "insert_bodies",
           "LAND_SPEED", "LandingWarning", "landing_state", "AIR_GAP", "in_air",
           "check_gravity"]

G = 9.81

# the landing rule and a run's start, re-exported: their own modules (landing.py, start.py)
from .start import insert_bodies, new_simulation, start_cloud  # noqa: E402,F401
from .landing import (AIR_GAP, LAND_SPEED, LandingWarning, check_gravity,  # noqa: E402,F401
                      in_air, landing_state, record_in_air)

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
    #: the landing rule's record (:func:`landing_state`), None until the quench starts
    landing: dict = None

    def to_json(self):
        d = asdict(self)
        d.pop("ke")
        return d

    @classmethod
    def from_json(cls, d, ke):
        return cls(ke=list(ke), **d)


# ---------------------------------------------------------------------------- base
class Phase(NamedTuple):
    """What a protocol does around its next step: the phase's ``label`` (shown by the progress
    bar, stored in ``RunState.label``), how many tap ``kicks`` go before the step and whether
    the quench ``damp``-s the velocities after it."""

    label: str
    kicks: int
    damp: bool


#: kind -> protocol class: every :class:`Protocol` subclass that names its ``kind``
PROTOCOLS = {}


class Protocol:
    """The base of every deposition protocol (page, rain; a stirred column or a drum next).

    A protocol is a frozen dataclass of its parameters (``dt``, the time step, among them) with
    a class attribute ``kind``, its name in specs, checkpoints and :func:`parse_protocol`
    (defining the subclass registers it). It keeps nothing between steps but the
    :class:`RunState`, so it is resumable. A subclass writes its schedule:

    - :meth:`start` (the bodies it starts with) and, if that returns no top, :meth:`top_bound`;
    - :meth:`now`: the :class:`Phase` of the next step (label, kicks, quench or not);
    - :meth:`after_step`: advance the schedule from the step's kinetic energy (``st.done`` set
      at the end), usually with :meth:`count_calm`, :meth:`settled` and :meth:`next_phase`;
    - :meth:`before_step` if it acts on the bodies or walls before the step: rain inserts a
      batch there; a moving-wall protocol poses and moves its walls there
      (``Simulation.set_wall_transform`` / ``set_wall_velocity``);
    - :meth:`phases`, :meth:`estimate_steps` and :meth:`quench_next` (the landing rule's
      moment, see the module notes).

    and inherits the one :meth:`step` (before_step -> kicks -> ``contact.advance(sim, dt)``,
    the impulse step or the Hertz substeps the simulation's law asks for -> quench ->
    bookkeeping -> after_step), the tap (:meth:`kick`), the quench (:meth:`quench`), the
    kinetic-energy stop rule and :meth:`to_spec`. The shared code reads the parameters it needs
    from the subclass by name: ``tap_speed`` (the kick), ``damp`` (the quench), ``ke_tol``,
    ``calm_steps`` and ``settle_steps`` (the stop rule).
    """

    kind = ""
    #: time before the quench starts, where the schedule fixes it (the landing rule)
    landing_time = None

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if cls.__dict__.get("kind"):
            PROTOCOLS[cls.kind] = cls

    # -- the schedule, written by each protocol
    def start(self, ctx, rng):
        """(positions, quaternions, velocities, top y or None) of the bodies the run starts
        with (arrays of 0 rows for none); refuses a container or count it cannot start in."""
        raise NotImplementedError

    def top_bound(self, ctx):
        """A height no body reaches (the domain's top when :meth:`start` returns no top)."""
        raise NotImplementedError(f"{type(self).__name__} sizes its domain from its start")

    def now(self, st):
        """The :class:`Phase` of the step after ``st``."""
        raise NotImplementedError

    def before_step(self, sim, ctx, st, rng):
        """Act on the bodies or walls before the step's kicks (nothing by default)."""

    def after_step(self, sim, ctx, st, ke):
        """Advance the schedule after a step whose kinetic energy is ``ke`` (``st.step`` and
        ``st.label`` are already updated); set ``st.done`` when the run is complete."""
        raise NotImplementedError

    def phases(self):
        """[(label, first step)] of the phases in order; the first step is None where a stop
        rule, not the schedule, decides it."""
        raise NotImplementedError

    def estimate_steps(self, count):
        """The run's total steps for ``count`` elements (an estimate where a stop rule
        decides; the progress bar's total)."""
        raise NotImplementedError

    def quench_next(self, st):
        """Whether the next step is the quench's first (the landing rule's moment; never for
        a protocol without a quench: its landing is recorded at the end)."""
        return False

    # -- the shared step and its parts
    def step(self, sim, ctx, st, rng):
        """One step from ``st`` (updated in place); returns the kinetic energy after it."""
        label, kicks, damp = self.now(st)
        self.before_step(sim, ctx, st, rng)
        for _ in range(kicks):
            self.kick(sim, ctx)
        advance(sim, self.dt)
        if damp:
            self.quench(sim)
        ke = float(sim.kinetic_energy())
        st.step += 1
        st.label = label
        self.after_step(sim, ctx, st, ke)
        return ke

    def kick(self, sim, ctx):
        """The tap: add ``tap_speed`` D/time (+y) to every body's velocity."""
        v = np.array(sim.get_velocities(), dtype=np.float64)
        v[:, 1] += self.tap_speed * ctx["body"].d
        sim.set_velocities(v)

    def quench(self, sim):
        """Multiply every linear and angular velocity by ``damp``."""
        sim.set_velocities(np.asarray(sim.get_velocities()) * self.damp)
        sim.set_angular_velocities(np.asarray(sim.get_angular_velocities()) * self.damp)

    def count_calm(self, sim, ctx, st, ke):
        """The stop rule's counter: ``st.calm`` counts the consecutive steps whose kinetic
        energy ``ke`` per element is below ``ke_tol`` m g D (reset by any other step)."""
        body = ctx["body"]
        ke_per = ke / (max(sim.num_particles(), 1) * body.mass * G * body.d)
        st.calm = st.calm + 1 if ke_per < self.ke_tol else 0

    def settled(self, st):
        """The stop rule: calm for ``calm_steps`` steps, or ``settle_steps`` steps spent (the
        step budget) in the current phase."""
        return st.calm >= self.calm_steps or st.in_phase >= self.settle_steps

    @staticmethod
    def next_phase(st, n_phases):
        """Move ``st`` to the next of ``n_phases`` phases (done after the last)."""
        st.phase += 1
        st.in_phase = 0
        st.calm = 0
        st.done = st.phase >= n_phases

    def to_spec(self):
        """``{"kind": kind, parameter: value, ...}``: JSON-able, :func:`parse_protocol`'s
        input (specs and checkpoints store it)."""
        return dict(kind=self.kind, **{f.name: getattr(self, f.name) for f in fields(self)})


# ---------------------------------------------------------------------------- page
@dataclass(frozen=True)
class PageProtocol(Protocol):
    """The page's protocol (its values by default).

    pour_steps free fall and settling; ``taps`` times: add ``tap_speed`` (D/time, +y) to every
    body's velocity, then ``tap_steps``; ``relax_steps``; ``quench_steps`` with every linear
    and angular velocity multiplied by ``damp`` after each step. ``dt`` is the step (time).
    Every body starts in the page's loose start cloud (:func:`start_cloud`). A fixed schedule:
    the phase follows from ``st.step`` alone (``st.phase`` stays 0).
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
        """(positions, quaternions, velocities) of the start cloud and the cloud's top y.

        Refuses (PecletArgumentError naming "container") a container the element does not fit
        in (the rain protocol's rule: a clear width of more than 2 r_b, room above the floor)
        and (naming "count") a cloud that would rise above a closed container's ceiling."""
        body, cont = ctx["body"], ctx["container"]
        d = body.d
        gap = max(1.55 * d, 2.0 * body.r_b + 0.05 * d)
        y0 = cont.floor_y + max(1.2 * d, body.r_b + 0.1 * d)
        ceiling = cont.ceiling(body.r_b)
        if not (y0 <= ceiling and (cont.kind == "tree" or cont.fits(body.r_b))):
            raise PecletArgumentError(
                "container", f"a container the element fits in (a clear width > 2 r_b = "
                f"{2.0 * body.r_b / d:.3f} D and room {y0 / d - cont.floor_y / d:.2f} D above "
                "the floor for the start cloud)", cont.label())
        P, Q = start_cloud(ctx["count"], cont, rng, y0=y0, gap=gap, dy=0.15 * d,
                           clearance=body.r_b, y_max=ceiling)
        top = float(P[:, 1].max())
        ctx["fall_time"] = self.fall_time(ctx, top)     # the landing rule's prediction
        return P, Q, np.zeros_like(P), top

    @property
    def landing_time(self):
        """Time (the page's units) before the quench starts: pour, taps and relaxation."""
        return self.dt * (self.pour_steps + self.taps * self.tap_steps + self.relax_steps)

    def fall_time(self, ctx, y_cloud):
        """Free-fall time (the page's units) from ``y_cloud`` to rest on the floor (centre
        at floor + r_b), g = 9.81 D/time^2."""
        body, cont = ctx["body"], ctx["container"]
        h = max(float(y_cloud) - cont.floor_y - body.r_b, 0.0) / body.d
        return math.sqrt(2.0 * h / G)

    def check_landing(self, ctx, y_cloud, name="count"):
        """The predicted landing rule (``peclet pall-ring``'s rule 2): a body at the start
        cloud's top ``y_cloud`` falls freely to rest on the floor (centre at floor + r_b) in
        ``sqrt(2 h / g)``, g = 9.81 D/time^2; that must not exceed :attr:`landing_time`.
        PecletArgumentError naming ``name`` (its value: ``ctx["count"]``) otherwise."""
        body, cont = ctx["body"], ctx["container"]
        h = max(float(y_cloud) - cont.floor_y - body.r_b, 0.0) / body.d
        t_fall = self.fall_time(ctx, y_cloud)
        if t_fall > self.landing_time:
            raise PecletArgumentError(
                name, "small enough for the start cloud to land before the quench",
                ctx["count"],
                f"the cloud's top is {h:.2f} D above the floor, a free fall of {t_fall:.3f} > "
                f"{self.landing_time:.3f} time units of pour, taps and relaxation: fewer "
                "elements, a wider container or a larger steps scale")

    def quench_next(self, st):
        """Whether the next step is the quench's first (the landing rule's moment)."""
        return self.quench_steps > 0 and st.step == self.total_steps - self.quench_steps

    def now(self, st):
        """A tap's kick where a tap starts (one per tap starting at this step); the quench damps
        throughout its steps."""
        kicks = sum(1 for _, first, _, kick, _ in self._phases() if kick and first == st.step)
        for label, first, n, _, damp in self._phases():
            if first <= st.step < first + n:
                return Phase(label, kicks, damp)
        return Phase("", kicks, False)

    def after_step(self, sim, ctx, st, ke):
        st.done = st.step >= self.total_steps


# ---------------------------------------------------------------------------- rain
@dataclass(frozen=True)
class RainProtocol(Protocol):
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
    after each step, held past them until a step's kinetic energy per element is below
    ``ke_tol`` m g D (at most ``settle_steps`` more). ``dt`` is the time step. The phase is ``st.phase`` (an index into
    :meth:`_phases`), ``st.in_phase`` the steps spent in it.
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
                      (("drop", 0.0, MAX_DROP, False), ("speed", 0.0, MAX_DROP, False),
                       ("rest_speed", 0.0, math.inf, True), ("spacing", 0.0, math.inf, False),
                       ("ke_tol", 0.0, math.inf, True), ("tap_speed", 0.0, math.inf, False),
                       ("damp", 0.0, 1.0, True), ("dt", 0.0, math.inf, True)))
        for name in ("batch", "insert_every", "attempts", "calm_steps"):
            check_int(name, getattr(self, name), 1)

    def _phases(self):
        return ["rain", "settle"] + ["tap", "settle"] * self.taps + \
            (["quench"] if self.quench_steps else [])

    def phases(self):
        """[(label, first step)]: rain starts at step 0; every later phase starts where the
        one before it ends, which the stop rule decides (None)."""
        return [(name, 0 if i == 0 else None) for i, name in enumerate(self._phases())]

    def quench_next(self, st):
        """Whether the next step is the quench's first (the landing rule's moment)."""
        ph = self._phases()
        return st.phase < len(ph) and ph[st.phase] == "quench" and st.in_phase == 0

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
        """A height no insertion reaches: the bed's top is at most the count's elements stacked
        one on another."""
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

    def now(self, st):
        """A kick at a tap's first step; the quench damps throughout its steps."""
        name = self._phases()[st.phase]
        return Phase(name, int(name == "tap" and st.in_phase == 0), name == "quench")

    def before_step(self, sim, ctx, st, rng):
        """A batch every ``insert_every`` steps of the rain phase while elements are left."""
        if self._phases()[st.phase] == "rain" and st.in_phase % self.insert_every == 0 \
                and st.inserted < ctx["count"]:
            if st.in_phase > 50 * self.insert_every * ctx["count"]:
                raise RuntimeError(f"rain: {st.inserted} of {ctx['count']} elements inserted "
                                   "after 50 tries each: the container is full")
            self._batch(sim, ctx, st, rng)

    def after_step(self, sim, ctx, st, ke):
        """rain ends with the last insertion, settle by the stop rule, tap and quench after
        their step counts."""
        ph = self._phases()
        name = ph[st.phase]
        st.in_phase += 1
        self.count_calm(sim, ctx, st, ke)
        end = {"rain": st.inserted >= ctx["count"],
               "settle": self.settled(st),
               "tap": st.in_phase >= self.tap_steps,
               # the quench holds until the bed is calm (an element that started to roll
               # during it is damped to rest), at most settle_steps beyond its own steps
               "quench": st.in_phase >= self.quench_steps
               and (st.calm > 0 or st.in_phase >= self.quench_steps + self.settle_steps)}[name]
        if end:
            self.next_phase(st, len(ph))


def _kinds_text():
    kinds, classes = list(PROTOCOLS), [c.__name__ for c in PROTOCOLS.values()]
    return ", ".join(f"'{k}'" for k in kinds) + ", " + \
        ", ".join(f"a {c}" for c in classes[:-1]) + f" or a {classes[-1]}"


def parse_protocol(value):
    """A protocol from its kind ("page", "rain"), a protocol object or a ``to_spec()`` dict."""
    if isinstance(value, Protocol):
        return value
    if isinstance(value, str) and value in PROTOCOLS:
        return PROTOCOLS[value]()
    kind = value.get("kind") if isinstance(value, dict) else None
    if isinstance(kind, str) and kind in PROTOCOLS:
        kw = {k: v for k, v in value.items() if k != "kind"}
        try:
            return PROTOCOLS[kind](**kw)
        except TypeError:
            pass
    raise PecletArgumentError("protocol", _kinds_text(), value)


# ---------------------------------------------------------------------------- helpers
def drive(sim, protocol, ctx, st, rng, max_steps=None, on_step=None):
    """Step ``protocol`` from ``st`` until it is done or ``st.step`` reaches ``max_steps``;
    appends each step's kinetic energy to ``st.ke`` and calls ``on_step(st)`` after it.
    Records the landing rule (``st.landing``, :func:`landing_state`) when the quench starts,
    or when a run without a quench ends, and at the end the bodies still in the air
    (:func:`record_in_air`)."""
    quench_next = getattr(protocol, "quench_next", None)
    while not st.done and (max_steps is None or st.step < max_steps):
        if st.landing is None and quench_next is not None and quench_next(st):
            st.landing = landing_state(sim, ctx, st, protocol)
        st.ke.append(protocol.step(sim, ctx, st, rng))
        if on_step is not None:
            on_step(st)
    if st.done and st.landing is None:
        st.landing = landing_state(sim, ctx, st, protocol)
    if st.done and "in_air" not in st.landing:
        record_in_air(sim, ctx, st)
    return st
