"""The engine the impact family certifies: anything that runs one Chung & Ooi impact
(:class:`~peclet_verify.impact.cases.Impact`) to separation and says what it measured.

Protocol (:class:`ImpactBackend`): ``impact(case) -> dict`` with

- ``v`` (n, 3) and ``w`` (n, 3): the balls' velocities (m/s) and angular velocities (rad/s)
  after separation, world frame;
- ``delta_max`` (m): the largest overlap; ``f_max`` (N): the largest normal force the engine
  applied; ``contact_time`` (s): from the first to the last step in contact, the crossings of
  zero overlap interpolated linearly in time.

and the declarations that decide what is judged (never guessed from a run):

``model`` (dict)
    ``normal``: ``"hertz"`` (judged against the Hertz closed forms with the case's moduli)
    or ``"hooke"`` (a linear spring of the case's ``kn``); ``damping`` and ``tangential``:
    free text the report prints (e.g. ``"Tsuji-form, restitution calibrated"``);
    ``tension`` (bool, default False): the normal force may pull (an unclamped dashpot),
    which changes the sliding closed form (:mod:`peclet_verify.impact.properties`);
    ``coulomb`` (``"compressive"``, the default, or ``"absolute"``): with tension, whether
    the Coulomb limit is mu x the compressive normal force or mu x |F_n|.
``capabilities`` (set of str)
    what the engine can express, from :data:`CAPABILITIES`. A case needing one that is not
    declared is reported "not claimed" with the missing names, never passed and never failed.

Optional: ``name`` (reports), ``close()``. Loading follows every family (the same three
functions, :class:`peclet_verify.registry.Family`): ``--peclet-impact-backend
module:factory``, the ``pytest_peclet_make_impact_backend`` hook, else peclet's Hertz law.
"""
from __future__ import annotations

import math
from typing import Protocol, runtime_checkable

import numpy as np

from ..loading import load_factory
from .follow import follow_impact

__all__ = ["CAPABILITIES", "NORMAL_MODELS", "ImpactBackend", "PecletImpactBackend",
           "SubprocessImpactBackend", "check_backend", "default_backend", "linear_backend",
           "load_backend", "follow_impact"]

#: What an impact case can ask of an engine.
CAPABILITIES = {
    "sphere_sphere": "two spheres in contact",
    "sphere_wall": "a sphere against a rigid plane",
    "unequal_spheres": "two spheres of different radii",
    "restitution": "a normal damping that gives the asked restitution e at any speed",
    "friction": "Coulomb-limited tangential force (sliding friction mu)",
    "spin": "initial angular velocities",
}
#: The normal force models with closed forms here.
NORMAL_MODELS = ("hertz", "hooke")


@runtime_checkable
class ImpactBackend(Protocol):
    """See the module notes."""

    model: dict
    capabilities: frozenset

    def impact(self, case) -> dict: ...


class PecletImpactBackend:
    """peclet.dem as an impact engine: ``law`` ``"hertz"`` (the Hertz–Mindlin law of
    ``Simulation.step_hertz``: Tsuji-form damping calibrated to e, Mindlin tangential spring)
    or ``"linear"`` (the Cundall–Strack law of peclet.dem.linear, stiffness the case's ``kn``,
    tangential spring 2/7 kn). ``threads``: Numba threads during a run (restored after)."""

    def __init__(self, law="hertz", threads=1):
        if law not in ("hertz", "linear"):
            raise ValueError(f"law must be 'hertz' or 'linear', got {law!r}")
        self.law = law
        self.threads = int(threads)
        self.name = f"peclet.dem ({law} law)"
        self.model = ({"normal": "hertz", "damping": "Tsuji form, coefficient calibrated to e",
                       "tangential": "Mindlin spring (8 G* sqrt(R* delta)), Coulomb limit"}
                      if law == "hertz" else
                      {"normal": "hooke", "damping": "viscous, zeta = -ln e / sqrt(pi^2 + "
                       "ln^2 e), unclamped", "tension": True,
                       "tangential": "linear spring kt = 2/7 kn, Coulomb limit"})
        self.capabilities = frozenset(CAPABILITIES)
        self.factory = ("peclet_verify.impact.backend:"
                        + ("default_backend" if law == "hertz" else "linear_backend"))

    def impact(self, case):
        import numba
        before = numba.get_num_threads()
        numba.set_num_threads(min(self.threads, numba.config.NUMBA_NUM_THREADS))
        try:
            return self._run(case)
        finally:
            numba.set_num_threads(before)

    def _simulation(self, case):
        from peclet.core import geom
        from peclet.dem import Simulation
        balls = case.balls
        sim = Simulation(len(balls))
        big = 100.0 * max(b.radius for b in balls)   # a domain: the runaway guard's scale
        sim.set_domain([-big] * 3, [big] * 3)
        for b in balls:
            sim.add_sphere_shape(b.radius)
        sim.set_positions([list(b.x) for b in balls])
        sim.set_shape_ids(list(range(len(balls))))
        sim.set_inv_mass([1.0 / b.mass for b in balls])
        sim.set_velocities([list(b.v) for b in balls])
        sim.set_angular_velocities([list(b.w) for b in balls])
        sim.set_material_ids(list(range(len(balls))))
        for k, b in enumerate(balls):
            sim.set_hertz_material(k, b.youngs, b.poisson)
            for j in range(k, len(balls)):
                sim.set_pair_material(k, j, case.e, 0.0, case.mu)
        if case.wall:                      # the half-space x > 0: a box whose face is x = 0
            size = balls[0].radius
            sb = geom.SceneBuilder()
            root = sb.add_leaf("box", [size, 10 * size, 10 * size],
                               translation=[size, 0.0, 0.0])
            ni, nr, _, _ = sb.encode()
            sim.add_analytic_wall(ni, nr, root, False, case.e, case.mu)
        if self.law == "linear":
            sim.set_contact_law("linear", kn=case.kn)
        else:
            sim.set_contact_law("hertz")
        return sim

    def _run(self, case):
        from peclet.dem.hertz import last_listing
        sim = self._simulation(case)
        r0 = case.balls[0].radius

        def overlap():
            x = sim.get_positions()
            if case.wall:
                return x[0, 0] + r0
            return r0 + case.balls[1].radius - float(np.linalg.norm(x[1] - x[0]))

        def normal_force():
            fn = last_listing(sim.contact_engine.state(sim.world))["normal_force"]
            return float(fn.max()) if len(fn) else 0.0

        m, _, _ = case.effective()
        tc = math.pi * math.sqrt(m / case.kn)          # the order of the contact time
        dmax, fmax, t = follow_impact(lambda: sim.advance(1, case.dt), overlap, normal_force,
                                      case.dt, int(50 * tc / case.dt) + 100)
        return {"v": sim.get_velocities(), "w": sim.get_angular_velocities(),
                "delta_max": dmax, "f_max": fmax,
                "contact_time": math.nan if t is None else t}


class SubprocessImpactBackend:
    """An :class:`ImpactBackend` served by a child process (``cmd``, which runs
    :func:`peclet_verify.wire.serve` with an ``impact`` engine, e.g. in another venv): its
    ``model``, ``capabilities`` and ``name`` are what the child declares. ``env``, ``cwd``,
    ``timeout`` as for :class:`~peclet_verify.processes.ChildProcess`."""

    own_deadline = True  # the child times out: no in-process deadline on top

    def __init__(self, cmd, name=None, env=None, cwd=None, timeout=None):
        from ..processes import ChildProcess
        self.child = ChildProcess(list(cmd), env=env, cwd=cwd, timeout=timeout)
        if "impact" not in self.child.methods:
            self.close()
            raise ValueError(f"child {list(cmd)!r} serves no 'impact'; it offers "
                             f"{sorted(self.child.methods)}")
        d = self.child.declared
        self.name = name or d.get("impact_name") or self.child.name
        self.model = dict(d.get("impact_model", {}))
        self.capabilities = frozenset(d.get("impact_capabilities", ()))

    def impact(self, case):
        out = self.child.call("impact", np.array(case.to_json()))
        names = [str(n) for n in out[0].reshape(-1)]
        ans = dict(zip(names, out[1:]))
        return {k: (float(v) if np.ndim(v) == 0 else v) for k, v in ans.items()}

    def close(self):
        self.child.close()


def check_backend(backend):
    """``backend`` if it has a callable ``impact``, a ``model`` whose ``normal`` is one of
    :data:`NORMAL_MODELS` and ``capabilities`` from :data:`CAPABILITIES`; ValueError naming
    what is wrong otherwise."""
    if not callable(getattr(backend, "impact", None)):
        raise ValueError(f"an impact backend must have impact(case); {backend!r} has none")
    model = getattr(backend, "model", None)
    if not isinstance(model, dict) or model.get("normal") not in NORMAL_MODELS:
        raise ValueError(f"an impact backend declares model = {{'normal': one of "
                         f"{NORMAL_MODELS}, ...}}; {backend!r} has {model!r}")
    caps = getattr(backend, "capabilities", None)
    if caps is None or not set(caps) <= set(CAPABILITIES):
        raise ValueError(f"an impact backend declares capabilities, a subset of "
                         f"{sorted(CAPABILITIES)}; {backend!r} has {caps!r}")
    return backend


def default_backend():
    """The impact engine certified when no other is named: peclet's Hertz law."""
    return PecletImpactBackend("hertz")


def linear_backend():
    """peclet's linear (Cundall–Strack) law as an impact engine."""
    return PecletImpactBackend("linear")


def load_backend(spec, option="--peclet-impact-backend"):
    """The impact backend of ``"module:factory"`` (``"reference"``: peclet's Hertz law);
    ``ValueError`` naming ``option`` on any failure."""
    return load_factory(spec, option, default_backend, check_backend)
