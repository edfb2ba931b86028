"""DEM engines under certification: the protocols, peclet's own engine, a child-process engine.

A DEM (or mechanics) certificate describes its run as a :class:`~peclet_verify.scenario.Scenario` (the
page's API as data: ``Simulation(capacity)``, ``set_domain``, ``set_gravity``,
``set_material_params``, ``add_sphere_shape`` / ``add_scene_shape`` / ``add_analytic_wall``,
positions, quaternions, masses, inertia, then ``steps`` x ``step(dt)``) and asks the engine
under certification to run it at a thread count. Whatever differs between engines (method
names, ``step(dt)`` vs ``set_dt`` + ``step(1)``, float32 arrays, argument order) lives in the
adapter, never in a certificate.

Protocols
---------
:class:`PageSimulation` is the page's API a scenario uses; :class:`DemBackend` is what a
certificate talks to. Most engines are certified through :class:`PageApiBackend`, which
replays the scenario on ``make_simulation(capacity)`` (an object with the page's API, e.g. a
thin dialect wrapper of the engine) after ``set_threads(threads)``.

Reaching a backend: ``--peclet-dem-backend module:factory`` (``factory()`` returns a
DemBackend), else a ``pytest_peclet_make_dem_backend(config)`` hook in ``conftest.py``, else
peclet's own engine (:class:`PecletDemBackend`). An engine in another virtual environment:
:class:`SubprocessDemBackend` with a child that calls :func:`peclet_verify.wire.serve` (see
:mod:`peclet_verify.dem.child` and :mod:`peclet_verify.dem.wheel_child`). The mechanics family
certifies the same backend (:mod:`peclet_verify.mechanics.backend`).
"""
from __future__ import annotations

import atexit
import os
import sys
from typing import Callable, Optional, Protocol, Sequence, runtime_checkable

import numpy as np

from ..loading import load_factory
from ..processes import ChildProcess
from ..scenario import Scenario, run_scenario

__all__ = ["PageSimulation", "DemBackend", "PageApiBackend", "PecletDemBackend",
           "SubprocessDemBackend", "check_backend", "load_backend", "default_backend",
           "child_command", "wheel_child_command", "thread_counts", "numba_threads",
           "numba_thread_counts", "factory_spec", "fresh_engines", "close_fresh_engines",
           "Scenario"]


@runtime_checkable
class PageSimulation(Protocol):
    """The page's ``Simulation`` API a scenario uses (peclet.dem.Simulation has all of it).

    Arrays are float64 (N, 3) / (N, 4) (quaternions x, y, z, w, body -> world), shape ids
    int; the flat CSG encoding is docs/architecture.md §2. ``set_contact_capacity`` is an
    optional hint (an engine without a contact-buffer knob omits it).
    """

    def set_domain(self, lo, hi) -> None: ...
    def enable_periodicity(self, px: bool, py: bool, pz: bool) -> None: ...
    def set_gravity(self, gx: float, gy: float, gz: float) -> None: ...
    def set_material_params(self, e_n: float, e_t: float, mu: float) -> None: ...
    def set_solver_iterations(self, position: int, velocity: int) -> None: ...
    def set_dt(self, dt: float) -> None: ...
    def add_sphere_shape(self, radius: float) -> int: ...
    def add_scene_shape(self, node_ints, node_reals, root: int, shell_points,
                        bounding_radius: float) -> int: ...
    def add_analytic_wall(self, node_ints, node_reals, root: int, invert: bool, e_n: float,
                          mu: float) -> int: ...
    def set_pair_material(self, a: int, b: int, e_n: float, e_t: float, mu: float) -> None: ...
    def set_positions(self, positions) -> None: ...
    def set_shape_ids(self, ids) -> None: ...
    def set_quaternions(self, quats) -> None: ...
    def set_velocities(self, v) -> None: ...
    def set_angular_velocities(self, w) -> None: ...
    def set_inv_mass(self, inv_mass) -> None: ...
    def set_inv_inertia(self, inv_inertia) -> None: ...
    def step(self, dt: Optional[float] = None) -> None: ...
    def get_positions(self) -> np.ndarray: ...
    def get_quaternions(self) -> np.ndarray: ...
    def get_velocities(self) -> np.ndarray: ...
    def get_angular_velocities(self) -> np.ndarray: ...
    def num_contacts(self) -> int: ...


@runtime_checkable
class DemBackend(Protocol):
    """A DEM engine under certification.

    ``run(scenario, threads) -> trajectory``: make the run of ``scenario`` with ``threads``
    threads and return ``{"step": (R,) int, name: (R, N, k) float array, "contacts": (R,)}``
    for the names in ``scenario.record`` (:func:`peclet_verify.scenario.run_scenario`
    builds exactly that from any :class:`PageSimulation`). Optional attributes:

    ``name`` (str)
        used in reports.
    ``thread_counts`` (tuple of int, default (1, 2))
        the thread counts the engine can run; the across-threads certificate compares each
        with one thread.
    ``thread_determinism`` (bool, default True)
        False declares results are NOT claimed bitwise identical across thread counts: that
        certificate is then reported "not claimed" (never passed).
    ``close()``
        called once at the end of the session.
    """

    def run(self, scenario: Scenario, threads: int = 1) -> dict: ...


class PageApiBackend:
    """A :class:`DemBackend` from a page-API simulation factory.

    ``make_simulation(capacity) -> PageSimulation``; ``set_threads(n)`` (optional) sets the
    engine's thread count before each run; the other arguments are the protocol's optional
    attributes."""

    def __init__(self, make_simulation: Callable, set_threads: Optional[Callable] = None,
                 name: str = "page-api engine", thread_counts: Sequence[int] = (1, 2),
                 thread_determinism: bool = True):
        self.make_simulation = make_simulation
        self.set_threads = set_threads
        self.name = name
        self.thread_counts = tuple(int(t) for t in thread_counts)
        self.thread_determinism = bool(thread_determinism)

    def run(self, scenario: Scenario, threads: int = 1) -> dict:
        if self.set_threads is not None:
            self.set_threads(int(threads))
        return run_scenario(self.make_simulation, scenario)


def numba_threads(n):
    """Set Numba's thread count of this thread to ``n`` (clipped to the pool)."""
    import numba
    numba.set_num_threads(max(1, min(int(n), numba.config.NUMBA_NUM_THREADS)))


def numba_thread_counts():
    """The thread counts peclet's engine runs here: (1, 2), or (1,) on a one-thread pool."""
    try:
        import numba
        cap = numba.config.NUMBA_NUM_THREADS
    except ImportError:  # pragma: no cover - numba is a dependency of peclet
        cap = 1
    return (1, 2) if cap >= 2 else (1,)


class PecletDemBackend(PageApiBackend):
    """peclet's own engine (``peclet.dem.Simulation``), in this process; threads through
    ``numba.set_num_threads`` (restored after each run). It claims bitwise-identical results
    at any thread count."""

    def __init__(self):
        def make(capacity):
            from peclet.dem import Simulation
            return Simulation(capacity)
        super().__init__(make, numba_threads, name="peclet.dem",
                         thread_counts=numba_thread_counts(), thread_determinism=True)

    def run(self, scenario, threads=1):
        import numba
        before = numba.get_num_threads()
        try:
            return super().run(scenario, threads)
        finally:
            numba.set_num_threads(before)


class SubprocessDemBackend:
    """A :class:`DemBackend` served by child processes (``cmd``, which run
    :func:`peclet_verify.wire.serve` with a ``dem`` engine), one child per thread count,
    started on first use with ``OMP_NUM_THREADS`` and ``NUMBA_NUM_THREADS`` set to that count
    (an OpenMP engine fixes its threads at start-up) and the count also passed with each run.

    ``thread_counts`` / ``thread_determinism`` are what the child declares (its engine's
    attributes) unless given here. ``timeout`` as for :class:`~peclet_verify.processes.ChildProcess`: a
    child that does not answer in time is killed, the call raises ``TimeoutError``.
    :meth:`fresh` gives another backend of the same command, with children of its own."""

    own_deadline = True  # its children time out: no in-process deadline on top

    def __init__(self, cmd, name=None, env=None, cwd=None, timeout=None, thread_counts=None,
                 thread_determinism=None):
        self._spec = dict(cmd=list(cmd), env=dict(env or {}), cwd=cwd, timeout=timeout)
        self._children = {}
        first = self._child(1)
        if "run" not in first.methods:
            self.close()
            raise ValueError(f"child {list(cmd)!r} serves no DEM 'run'; it offers "
                             f"{sorted(first.methods)}")
        d = first.declared
        self.name = name or d.get("dem_name") or first.name
        self.thread_counts = tuple(thread_counts or d.get("thread_counts", (1, 2)))
        self.thread_determinism = bool(d.get("thread_determinism", True)
                                       if thread_determinism is None else thread_determinism)

    def _child(self, threads):
        if threads not in self._children:
            env = dict(self._spec["env"], OMP_NUM_THREADS=str(threads),
                       NUMBA_NUM_THREADS=str(threads))
            self._children[threads] = ChildProcess(self._spec["cmd"], env=env,
                                                  cwd=self._spec["cwd"],
                                                  timeout=self._spec["timeout"],
                                                  name=f"{self._spec['cmd'][-1]} "
                                                       f"({threads} thread(s))")
        return self._children[threads]

    def run(self, scenario, threads=1):
        out = self._child(int(threads)).call("run", np.array(scenario.to_json()),
                                             np.array(int(threads)))
        names = [str(n) for n in out[0].reshape(-1)]
        return dict(zip(names, out[1:]))

    def fresh(self):
        """Another backend of the same command, name and declarations, served by children
        of its own (fresh processes)."""
        return SubprocessDemBackend(name=self.name, thread_counts=self.thread_counts,
                                    thread_determinism=self.thread_determinism, **self._spec)

    def close(self):
        for c in self._children.values():
            c.close()
        self._children = {}


def thread_counts(backend):
    """The thread counts ``backend`` declares it runs (default (1, 2))."""
    return tuple(getattr(backend, "thread_counts", (1, 2)))


def check_backend(backend):
    """``backend`` if it has a callable ``run``, else ``ValueError``."""
    if not callable(getattr(backend, "run", None)):
        raise ValueError(f"a DEM backend must have run(scenario, threads); {backend!r} has "
                         "none")
    return backend


def default_backend():
    """The DEM engine certified when no other is named: :class:`PecletDemBackend`."""
    return PecletDemBackend()


def load_backend(spec, option="--peclet-dem-backend"):
    """The DEM backend of ``"module:factory"`` (``"reference"``: :class:`PecletDemBackend`);
    ``ValueError`` naming ``option`` on any failure."""
    return load_factory(spec, option, default_backend, check_backend)


_HERE = os.path.dirname(os.path.abspath(__file__))


def child_command(python=None, factory=None):
    """Command serving peclet's own DEM engine (or the one ``factory``, a ``"module:factory"``
    spec, makes) from a child of ``python``."""
    return [python or sys.executable, os.path.join(_HERE, "child.py")] + \
        ([factory] if factory else [])


def wheel_child_command(python):
    """Command serving the upstream ``peclet-dem`` 1.1.0 wheel installed for ``python``
    (through its dialect adapter :mod:`peclet_verify.dem.wheel_child`)."""
    return [python, os.path.join(_HERE, "wheel_child.py")]


# ---------------------------------------------------------------------------- fresh processes
#: id(backend) -> (backend, its engines in fresh processes), kept for the session.
_FRESH = {}


def factory_spec(backend):
    """``(spec, None)``: a ``"module:factory"`` spec that makes an engine like ``backend`` in
    a fresh process, or ``(None, why)``. Tried in order: the spec the engine was loaded from
    or declares (its ``factory`` attribute), then its class if that is importable by name and
    takes no argument."""
    import importlib.util
    import inspect
    spec = getattr(backend, "factory", None)
    if isinstance(spec, str) and spec:
        return spec, None
    engine = getattr(backend, "backend", backend)  # the engine behind a deadline wrapper
    cls = type(engine)
    where = f"{cls.__module__}:{cls.__qualname__}"
    if cls.__module__ in ("__main__", "builtins") or "<" in cls.__qualname__ or \
            "." in cls.__qualname__:
        return None, f"its class {where} is not importable by name"
    try:
        if importlib.util.find_spec(cls.__module__) is None:
            raise ImportError(cls.__module__)
        required = [q for q in inspect.signature(cls).parameters.values()
                    if q.default is q.empty and q.kind in (q.POSITIONAL_ONLY,
                                                           q.POSITIONAL_OR_KEYWORD,
                                                           q.KEYWORD_ONLY)]
    except (ImportError, ValueError, TypeError) as exc:
        return None, f"its class {where} cannot be found or inspected ({exc})"
    if required:
        return None, (f"its class {where} takes arguments ({', '.join(q.name for q in required)})"
                      "; name it with --peclet-dem-backend module:factory or give the engine a "
                      "'factory' attribute")
    return where, None


def fresh_engines(backend, n=2):
    """``(engines, None)``: ``n`` engines like ``backend``, each in a fresh process of its own
    (made once per backend and kept for the session), or ``(None, why)`` when the engine
    cannot be remade elsewhere. A backend with ``fresh()`` (:class:`SubprocessDemBackend`)
    makes them; any other is made by :func:`factory_spec` in a child
    (:mod:`peclet_verify.dem.child`)."""
    kept = _FRESH.get(id(backend))
    if kept is not None and kept[0] is backend:
        return kept[1]
    fresh = getattr(backend, "fresh", None)
    try:
        if callable(fresh):
            out = ([fresh() for _ in range(n)], None)
        else:
            spec, why = factory_spec(backend)
            if spec is None:
                out = (None, why)
            else:
                timeout = getattr(backend, "deadline", None)
                out = ([SubprocessDemBackend(child_command(factory=spec),
                                             name=f"{spec} (fresh process {k + 1})",
                                             timeout=timeout if isinstance(timeout, float)
                                             else None)
                        for k in range(n)], None)
    except Exception as exc:  # an engine that cannot start elsewhere is reported, not raised
        out = (None, f"starting it in a fresh process failed: {type(exc).__name__}: "
                     f"{str(exc)[-500:]}")
    _FRESH[id(backend)] = (backend, out)
    return out


def close_fresh_engines():
    """Close every engine :func:`fresh_engines` started (at exit, or when a session ends)."""
    for _, (engines, _why) in list(_FRESH.values()):
        for e in engines or ():
            e.close()
    _FRESH.clear()


atexit.register(close_fresh_engines)
