"""The page's pour -> tap -> quench protocol (Step 4) on ``peclet.dem.Simulation``.

World frame: y up, gravity -g y, an analytic box floor whose top face is y = 0, periodic in x
and z over [0, L). Every count, speed and factor is an argument with the page's value as its
default. The start cloud is the page's algorithm, driven by ``numpy.random.default_rng(seed)``,
so a seed reproduces it exactly; the DEM step itself is deterministic at any thread count
(docs/architecture.md §7), so the whole pour is reproducible from the seed.

This is the page's entry point; the protocol itself (:class:`PageProtocol`, the start cloud and
the stepping loop) lives in :mod:`peclet.packing.bed.protocols`, shared with
:func:`peclet.packing.pack`.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from peclet.core.validation import check_float, check_int

from .containers import Container
from .material import as_material
from .progress import Progress, compile_note
from .protocols import (Body, PageProtocol, RunState, check_gravity, drive, insert_bodies,
                        new_simulation)
from .protocols import start_cloud as _start_cloud

__all__ = ["Protocol", "PourResult", "start_cloud", "pour", "y_top_for"]

#: The page's protocol, kept under its old name (not the base class of every protocol,
#: :class:`peclet.packing.bed.protocols.Protocol`).
Protocol = PageProtocol

#: The page's domain top; a taller start cloud raises it (see :func:`y_top_for`).
PAGE_Y_TOP = 60.0


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
    first_step_seconds: float = 0.0


def start_cloud(n, box, seed=5, y0=1.2, gap=1.55, dy=0.15, lookback=14):
    """The page's loose start cloud in the periodic box of side ``box``, from
    ``numpy.random.default_rng(seed)`` (see :func:`peclet.packing.bed.protocols.start_cloud`).
    Returns (positions (n, 3), quaternions (n, 4))."""
    check_int("n", n, 1)
    box = check_float("box", box, 0.0, lo_open=True)
    return _start_cloud(int(n), Container("box", (box,)), np.random.default_rng(seed), y0, gap,
                        dy, lookback)


def y_top_for(cloud_top):
    """The domain top for a start cloud reaching ``cloud_top``: the page's 60, or higher for a
    taller cloud (2 diameters above it, as the page's check asked)."""
    return max(PAGE_Y_TOP, float(cloud_top) + 2.0)


def pour(particle, n=48, box=3.5, seed=5, protocol=None, material=(0.15, 0.0, 0.5),
         iterations=(10, 8), gravity=9.81, frame_every=45, progress=True, y_top=None):
    """Pour ``n`` copies of ``particle`` (a ``scene_particle.build`` result: mass,
    inv_inertia_unit, register(sim)) into a periodic box of side ``box``, then tap and quench.

    material = (e_n, e_t, mu) for the bodies and the floor; iterations = (position, velocity)
    solver sweeps; gravity the magnitude of g (length/time^2, > 0, acting along -y towards the
    floor: a value <= 0 is refused, :func:`~peclet.packing.bed.protocols.check_gravity`); y_top the
    domain's top (None: sized from the start cloud, :func:`y_top_for`; a value below the
    cloud's top + 2 is an error). ``progress`` draws a bar on stderr. Returns a
    :class:`PourResult`.
    """
    proto = Protocol() if protocol is None else protocol
    check_int("frame_every", frame_every, 1)
    n = check_int("n", n, 1)
    gravity = check_gravity(gravity)
    mat = as_material(material)
    cont = Container("box", (check_float("box", box, 0.0, lo_open=True),))
    body = Body(-1, float(particle.mass), np.asarray(particle.inv_inertia_unit, float),
                float(particle.bounding_radius), 1.0)
    ctx = dict(container=cont, body=body, count=n)
    P0, Q0 = start_cloud(n, box, seed)
    if y_top is None:
        y_top = y_top_for(P0[:, 1].max())
    elif P0[:, 1].max() + 2 > y_top:
        raise ValueError(f"y_top={y_top} is below the start cloud's top {P0[:, 1].max():.2f}")
    sim, sid = new_simulation(particle.register, cont, mat, mat, iterations, gravity,
                              proto.dt, y_top, n)
    body.shape_id = sid
    insert_bodies(sim, body, P0, Q0, np.zeros_like(P0))

    res = PourResult(sim, sid, None, None, P0.copy(), protocol=proto)

    bar = Progress(proto.total_steps, "pall-ring pour ", enabled=progress, note=compile_note())
    dt = proto.dt

    def on_step(st):
        res.steps = st.step
        res.t.append(st.step * dt)
        if (st.step - 1) % frame_every == 0:
            res.frames.append((np.array(sim.get_positions(), dtype=np.float64),
                               np.array(sim.get_quaternions(), dtype=np.float64)))
            res.frame_t.append(st.step * dt)
        bar.update(1, st.label)

    t0 = time.perf_counter()
    st = drive(sim, proto, ctx, RunState(ke=res.ke), None, on_step=on_step)
    res.ke = st.ke
    res.seconds = time.perf_counter() - t0
    res.first_step_seconds = min(res.seconds, bar.first_seconds or 0.0)
    bar.close()
    res.positions = np.array(sim.get_positions(), dtype=np.float64)
    q = np.array(sim.get_quaternions(), dtype=np.float64)
    res.quaternions = q / np.linalg.norm(q, axis=1)[:, None]
    return res
