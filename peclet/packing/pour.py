"""The page's pour -> tap -> quench protocol (Step 4) on ``peclet.dem.Simulation``.

World frame: y up, gravity -g y, an analytic box floor whose top face is y = 0, periodic in x
and z over [0, L). Every count, speed and factor is an argument with the page's value as its
default. The start cloud is the page's algorithm, driven by ``numpy.random.default_rng(seed)``,
so a seed reproduces it exactly; the DEM step itself is deterministic at any thread count
(DESIGN.md §5), so the whole pour is reproducible from the seed.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .freeze import add_floor
from .progress import Progress

__all__ = ["Protocol", "PourResult", "start_cloud", "pour"]


@dataclass(frozen=True)
class Protocol:
    """Step counts and factors of the protocol (the page's values by default).

    pour_steps free fall and settling; ``taps`` times: add ``tap_speed`` (length/time, +y) to
    every body's velocity, then ``tap_steps``; ``relax_steps``; ``quench_steps`` with every
    linear and angular velocity multiplied by ``damp`` after each step. ``dt`` is the step (time).
    """

    pour_steps: int = 1400
    taps: int = 2
    tap_speed: float = 0.8
    tap_steps: int = 400
    relax_steps: int = 600
    quench_steps: int = 900
    damp: float = 0.96
    dt: float = 2e-3

    def __post_init__(self):
        for name in ("pour_steps", "taps", "tap_steps", "relax_steps", "quench_steps"):
            v = getattr(self, name)
            if isinstance(v, bool) or not float(v).is_integer() or v < 0:
                raise ValueError(f"{name} must be an integer >= 0, got {v!r}")
        if not np.isfinite(self.tap_speed) or self.tap_speed < 0:
            raise ValueError(f"tap_speed must be a finite number >= 0, got {self.tap_speed!r}")
        if not 0.0 < self.damp <= 1.0:
            raise ValueError(f"damp must be in (0, 1], got {self.damp!r}")
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"dt must be a finite number > 0, got {self.dt!r}")

    def scaled(self, factor):
        """The same protocol with every step count multiplied by ``factor`` (> 0), rounded, at
        least 1 step per non-empty phase (reduced runs for tests)."""
        if not (np.isfinite(factor) and factor > 0):
            raise ValueError(f"steps scale must be a finite number > 0, got {factor!r}")
        s = lambda n: 0 if n == 0 else max(1, int(round(n * factor)))  # noqa: E731
        return Protocol(s(self.pour_steps), self.taps, self.tap_speed, s(self.tap_steps),
                        s(self.relax_steps), s(self.quench_steps), self.damp, self.dt)

    @property
    def total_steps(self) -> int:
        return (self.pour_steps + self.taps * self.tap_steps + self.relax_steps
                + self.quench_steps)

    def phases(self):
        """[(label, first step)] of the phases, as the page marks them on its plot."""
        out = [("pour", 0)]
        s = self.pour_steps
        for _ in range(self.taps):
            out.append(("tap", s))
            s += self.tap_steps
        out.append(("relax", s))
        out.append(("quench", s + self.relax_steps))
        return out


@dataclass
class PourResult:
    """What :func:`pour` returns. Positions (N, 3) and quaternions (N, 4, x y z w, normalised)
    at the end; ke / t the kinetic energy (mass x length^2 / time^2) and time after every
    step; frames [(positions, quaternions)] after every ``frame_every``-th step (from the
    first), at times frame_t; seconds the
    wall-clock of the stepping; sim the live Simulation; shape_id the element's shape."""

    sim: object
    shape_id: int
    positions: np.ndarray
    quaternions: np.ndarray
    start_positions: np.ndarray
    ke: list = field(default_factory=list)
    t: list = field(default_factory=list)
    frames: list = field(default_factory=list)
    frame_t: list = field(default_factory=list)
    steps: int = 0
    seconds: float = 0.0
    protocol: Protocol = None


def start_cloud(n, box, seed=5, y0=1.2, gap=1.55, dy=0.15, lookback=14):
    """The page's loose non-overlapping start cloud and random orientations.

    Bodies are placed one by one at a uniform (x, z) in [0, box)^2 and the current height y
    (starting at ``y0``); a candidate is accepted if, against each of the last ``lookback``
    accepted, it is more than ``gap`` away horizontally OR vertically; otherwise y grows by
    ``dy``. Orientations are normalised 4-D Gaussians (uniform on SO(3)). Returns (positions
    (n, 3), quaternions (n, 4)), from ``numpy.random.default_rng(seed)`` in the page's order.
    """
    if isinstance(n, bool) or not float(n).is_integer() or n < 1:
        raise ValueError(f"n must be an integer >= 1, got {n!r}")
    if not (np.isfinite(box) and box > 0):
        raise ValueError(f"box must be a length > 0, got {box!r}")
    rng = np.random.default_rng(seed)
    pos, y = [], float(y0)
    while len(pos) < int(n):
        c = np.array([rng.uniform(0, box), y, rng.uniform(0, box)])
        if all(np.linalg.norm((c - q)[[0, 2]]) > gap or abs(c[1] - q[1]) > gap
               for q in pos[-lookback:]):
            pos.append(c)
        else:
            y += dy
    quat = rng.normal(size=(int(n), 4))
    quat /= np.linalg.norm(quat, axis=1)[:, None]
    return np.asarray(pos, dtype=np.float64), quat


def pour(particle, n=48, box=3.5, seed=5, protocol=None, material=(0.15, 0.0, 0.5),
         iterations=(10, 8), gravity=9.81, frame_every=45, progress=True, y_top=60.0):
    """Pour ``n`` copies of ``particle`` (a ``scene_particle.build`` result: mass,
    inv_inertia_unit, register(sim)) into a periodic box of side ``box``, then tap and quench.

    material = (e_n, e_t, mu) for the bodies and the floor; iterations = (position, velocity)
    solver sweeps; gravity the magnitude of g (length/time^2, acting along -y). ``progress``
    draws a bar on stderr. Returns a :class:`PourResult`.
    """
    from peclet.dem import Simulation

    proto = Protocol() if protocol is None else protocol
    if isinstance(frame_every, bool) or not float(frame_every).is_integer() or frame_every < 1:
        raise ValueError(f"frame_every must be an integer >= 1, got {frame_every!r}")
    P0, Q0 = start_cloud(n, box, seed)
    if P0[:, 1].max() + 2 > y_top:
        raise ValueError(f"y_top={y_top} is below the start cloud's top {P0[:, 1].max():.2f}")
    sim = Simulation(n + 8)
    sim.set_domain((0.0, -1.2, 0.0), (box, y_top, box))
    sim.enable_periodicity(True, False, True)
    sim.set_gravity(0.0, -float(gravity), 0.0)
    sim.set_material_params(*material)
    sim.set_solver_iterations(*iterations)
    sid = particle.register(sim)
    add_floor(sim, box, box, material)
    sim.set_positions(P0)
    sim.set_shape_ids(np.full(n, sid, np.int32))      # after set_positions, as on the page
    sim.set_quaternions(Q0)
    sim.set_inv_mass(np.full(n, 1.0 / particle.mass))
    # inv_inertia_unit = 1/principal moments (mass-weighted at the particle's density), as the
    # page passes it
    sim.set_inv_inertia(np.tile(np.asarray(particle.inv_inertia_unit, float), (n, 1)))
    sim.set_dt(proto.dt)

    res = PourResult(sim, sid, None, None, P0.copy(), protocol=proto)
    bar = Progress(proto.total_steps, "pall-ring pour ", enabled=progress)
    dt = proto.dt

    def advance(count, label, damp=None):
        for i in range(count):
            sim.step(dt)
            if damp is not None:
                sim.set_velocities(np.asarray(sim.get_velocities()) * damp)
                sim.set_angular_velocities(np.asarray(sim.get_angular_velocities()) * damp)
            res.steps += 1
            res.ke.append(float(sim.kinetic_energy()))
            res.t.append(res.steps * dt)
            if (res.steps - 1) % frame_every == 0:
                res.frames.append((np.array(sim.get_positions(), dtype=np.float64),
                                   np.array(sim.get_quaternions(), dtype=np.float64)))
                res.frame_t.append(res.steps * dt)
            bar.update(1, label)

    t0 = time.perf_counter()
    advance(proto.pour_steps, "pour")
    for _ in range(proto.taps):
        v = np.array(sim.get_velocities(), dtype=np.float64)
        v[:, 1] += proto.tap_speed
        sim.set_velocities(v)
        advance(proto.tap_steps, "tap")
    advance(proto.relax_steps, "relax")
    advance(proto.quench_steps, "quench", damp=proto.damp)
    res.seconds = time.perf_counter() - t0
    bar.close()
    res.positions = np.array(sim.get_positions(), dtype=np.float64)
    q = np.array(sim.get_quaternions(), dtype=np.float64)
    res.quaternions = q / np.linalg.norm(q, axis=1)[:, None]
    return res

