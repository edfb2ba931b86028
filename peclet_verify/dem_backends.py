"""DEM engines under certification: the protocols, peclet's own engine, a child-process engine.

A DEM certificate describes its run as a :class:`~peclet_verify.family_wire.Scenario` (the
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
:class:`SubprocessDemBackend` with a child that calls :func:`peclet_verify.family_wire.serve`
(see :mod:`peclet_verify.peclet_dem_child` and :mod:`peclet_verify.peclet_dem_wheel_child`).
"""
from __future__ import annotations

import os
import sys
from typing import Callable, Optional, Protocol, Sequence, runtime_checkable

import numpy as np

from .family_child import FamilyChild, load_factory
from .family_wire import Scenario, run_scenario

__all__ = ["PageSimulation", "DemBackend", "PageApiBackend", "PecletDemBackend",
           "SubprocessDemBackend", "check_dem_backend", "load_dem_backend",
           "peclet_dem_child_command", "wheel_dem_child_command", "dem_thread_counts",
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
    for the names in ``scenario.record`` (:func:`peclet_verify.family_wire.run_scenario`
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


def _numba_threads(n):
    import numba
    numba.set_num_threads(max(1, min(int(n), numba.config.NUMBA_NUM_THREADS)))


def _numba_thread_counts():
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
        super().__init__(make, _numba_threads, name="peclet.dem", thread_counts=
                         _numba_thread_counts(), thread_determinism=True)

    def run(self, scenario, threads=1):
        import numba
        before = numba.get_num_threads()
        try:
            return super().run(scenario, threads)
        finally:
            numba.set_num_threads(before)


class SubprocessDemBackend:
    """A :class:`DemBackend` served by child processes (``cmd``, which run
    :func:`peclet_verify.family_wire.serve` with a ``dem`` engine), one child per thread count,
    started on first use with ``OMP_NUM_THREADS`` and ``NUMBA_NUM_THREADS`` set to that count
    (an OpenMP engine fixes its threads at start-up) and the count also passed with each run.

    ``thread_counts`` / ``thread_determinism`` are what the child declares (its engine's
    attributes) unless given here. ``timeout`` as for :class:`~peclet_verify.backends.
    SubprocessBackend`: a child that does not answer in time is killed, the call raises
    ``TimeoutError``."""

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
            self._children[threads] = FamilyChild(self._spec["cmd"], env=env,
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

    def close(self):
        for c in self._children.values():
            c.close()
        self._children = {}


def dem_thread_counts(backend):
    return tuple(getattr(backend, "thread_counts", (1, 2)))


def check_dem_backend(backend):
    """``backend`` if it has a callable ``run``, else ``ValueError``."""
    if not callable(getattr(backend, "run", None)):
        raise ValueError(f"a DEM backend must have run(scenario, threads); {backend!r} has "
                         "none")
    return backend


def load_dem_backend(spec, option="--peclet-dem-backend"):
    """The DEM backend of ``"module:factory"`` (``"reference"``: :class:`PecletDemBackend`);
    ``ValueError`` naming ``option`` on any failure."""
    return load_factory(spec, option, PecletDemBackend, check_dem_backend)


_HERE = os.path.dirname(os.path.abspath(__file__))


def peclet_dem_child_command(python=None):
    """Command serving peclet's own DEM engine from a child of ``python``."""
    return [python or sys.executable, os.path.join(_HERE, "peclet_dem_child.py")]


def wheel_dem_child_command(python):
    """Command serving the upstream ``peclet-dem`` 1.1.0 wheel installed for ``python``
    (through its dialect adapter :mod:`peclet_verify.peclet_dem_wheel_child`)."""
    return [python, os.path.join(_HERE, "peclet_dem_wheel_child.py")]
