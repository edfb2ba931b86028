"""A DEM run as data, shared by the dem and mechanics families: :class:`Scenario` (the page's
API as a list of calls), its replay on any simulation that speaks the page's API
(:func:`run_scenario`) and the check of a recorded trajectory (stdlib + numpy only).

Like :mod:`peclet_verify.wire` (which sends scenarios to a child) this module imports nothing
of ``peclet``: a child process in another virtual environment (one whose ``peclet`` is another
engine, e.g. the upstream ``peclet-dem`` 1.1.0 wheel) loads both by file path and serves its
engine with :func:`peclet_verify.wire.serve`.

A :class:`Scenario` is a list of page-API calls (``Simulation(capacity)``, then e.g.
``set_domain``, ``set_gravity``, ``add_sphere_shape``, ``set_positions``, ...), a time step, a
number of ``step(dt)`` calls and what to record. Its arguments are plain Python numbers, bools
and (nested) lists, so it travels as JSON (Python's float repr round-trips every double
exactly) and prints as a runnable page-API snippet (:meth:`Scenario.snippet`).
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

#: The page-API calls a scenario may make before stepping (name -> argument names).
PAGE_CALLS = {
    "set_domain": ("lo", "hi"),
    "enable_periodicity": ("px", "py", "pz"),
    "set_gravity": ("gx", "gy", "gz"),
    "set_material_params": ("e_n", "e_t", "mu"),
    "set_solver_iterations": ("position", "velocity"),
    "set_contact_capacity": ("n",),
    "set_dt": ("dt",),
    "add_sphere_shape": ("radius",),
    "add_scene_shape": ("node_ints", "node_reals", "root", "shell_points", "bounding_radius"),
    "add_analytic_wall": ("node_ints", "node_reals", "root", "invert", "e_n", "mu"),
    "set_positions": ("positions",),
    "set_shape_ids": ("ids",),
    "set_quaternions": ("quats",),
    "set_velocities": ("v",),
    "set_angular_velocities": ("w",),
    "set_inv_mass": ("inv_mass",),
    "set_inv_inertia": ("inv_inertia",),
    "set_material_ids": ("ids",),
    "set_pair_material": ("a", "b", "e_n", "e_t", "mu"),
}
#: What a scenario can record, and the page-API getter of each (``contacts``: the contact
#: points the last step used, ``num_contacts()``).
RECORDABLE = {"positions": "get_positions", "quaternions": "get_quaternions",
              "velocities": "get_velocities", "angular_velocities": "get_angular_velocities",
              "contacts": "num_contacts"}
STATE = ("positions", "quaternions", "velocities", "angular_velocities")


def plain(x):
    """``x`` as plain Python (lists, floats, ints, bools): JSON-able and repr-exact."""
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, (list, tuple)):
        return [plain(v) for v in x]
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x)
    raise TypeError(f"scenario arguments must be numbers, bools or arrays, got {type(x)}")


@dataclass
class Scenario:
    """A DEM run through the page's API.

    ``capacity``: the ``Simulation(capacity)`` hint; ``calls``: ``[(method, args), ...]`` from
    :data:`PAGE_CALLS`, made in order; then ``steps`` calls of ``step(dt)``. Recorded: the
    getters named in ``record`` (keys of :data:`RECORDABLE`) after every ``record_every``
    steps (0: after the last step only), always after the last one. ``contact_capacity``, if
    set, is a contact-buffer size hint (``set_contact_capacity``) that an engine without such
    a knob ignores. ``label`` is a comment for the snippet.
    """

    capacity: int
    calls: list
    dt: float
    steps: int
    record: tuple = STATE
    record_every: int = 0
    contact_capacity: int | None = None
    label: str = ""
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        self.calls = [(str(m), tuple(plain(a) for a in args)) for m, args in self.calls]
        for m, args in self.calls:
            if m not in PAGE_CALLS:
                raise ValueError(f"scenario call {m!r} is not a page-API call "
                                 f"({', '.join(PAGE_CALLS)})")
            if len(args) != len(PAGE_CALLS[m]):
                raise ValueError(f"scenario call {m} takes {len(PAGE_CALLS[m])} arguments "
                                 f"{PAGE_CALLS[m]}, got {len(args)}")
        self.record = tuple(self.record)
        unknown = set(self.record) - set(RECORDABLE)
        if unknown:
            raise ValueError(f"cannot record {sorted(unknown)}; recordable: {list(RECORDABLE)}")
        self.capacity, self.steps, self.record_every = (int(self.capacity), int(self.steps),
                                                        int(self.record_every))
        self.dt = float(self.dt)

    def replace(self, **changes) -> "Scenario":
        d = dict(self.__dict__, **changes)
        return Scenario(**d)

    def to_json(self) -> str:
        return json.dumps({"capacity": self.capacity, "calls": [[m, list(a)] for m, a in
                                                                self.calls],
                           "dt": self.dt, "steps": self.steps, "record": list(self.record),
                           "record_every": self.record_every,
                           "contact_capacity": self.contact_capacity, "label": self.label,
                           "meta": self.meta})

    @classmethod
    def from_json(cls, text: str) -> "Scenario":
        d = json.loads(text)
        d["calls"] = [(m, tuple(a)) for m, a in d["calls"]]
        return cls(**d)

    def record_steps(self):
        """Step counts after which a record is taken (0 = before the first step)."""
        if self.record_every > 0:
            out = list(range(0, self.steps + 1, self.record_every))
            if out[-1] != self.steps:
                out.append(self.steps)
            return out
        return [self.steps]

    def snippet(self) -> str:
        """Runnable Python, in the page's API, that makes this run (with peclet.dem)."""
        def arg(a):
            if isinstance(a, list) and a and isinstance(a[0], list):
                return f"np.array({a!r})"
            return repr(a)
        lines = ["import numpy as np", "from peclet.dem import Simulation", ""]
        if self.label:
            lines.insert(0, f"# {self.label}")
        lines.append(f"sim = Simulation({self.capacity})")
        if self.contact_capacity is not None:
            lines.append(f"sim.set_contact_capacity({self.contact_capacity})")
        for m, args in self.calls:
            lines.append(f"sim.{m}({', '.join(arg(a) for a in args)})")
        lines.append(f"for _ in range({self.steps}):")
        lines.append(f"    sim.step({self.dt!r})")
        for k in self.record:
            call = RECORDABLE[k] + "()"
            lines.append(f"print({k!r}, sim.{call})")
        return "\n".join(lines)

    def __repr__(self):
        return f"Scenario.from_json({self.to_json()!r})"


def run_scenario(make_simulation, scenario: Scenario) -> dict:
    """Replay ``scenario`` on ``make_simulation(capacity)`` (an object with the page's API)
    and return the trajectory: ``{"step": (R,) int64, name: (R, ...) float64 ...}`` with R
    records (:meth:`Scenario.record_steps`); ``contacts`` is (R,) float64. Arrays are
    converted to float64 here, whatever precision the engine answers in."""
    sim = make_simulation(scenario.capacity)
    if scenario.contact_capacity is not None and hasattr(sim, "set_contact_capacity"):
        sim.set_contact_capacity(scenario.contact_capacity)
    for m, args in scenario.calls:
        getattr(sim, m)(*args)
    when = scenario.record_steps()
    rec = {k: [] for k in scenario.record}

    def take():
        for k in scenario.record:
            got = getattr(sim, RECORDABLE[k])
            val = got() if callable(got) else got
            rec[k].append(np.array(val, dtype=np.float64, copy=True))
    done = 0
    for target in when:
        while done < target:
            sim.step(scenario.dt)
            done += 1
        take()
    out = {"step": np.asarray(when, np.int64)}
    for k, vals in rec.items():
        out[k] = np.stack(vals) if vals else np.zeros(0)
    return out


def trajectory_problem(traj, scenario: Scenario, n_bodies: int):
    """Why ``traj`` is not a usable trajectory of ``scenario`` (None if it is): not a mapping,
    a missing record, a wrong shape, NaN or inf."""
    if not isinstance(traj, dict):
        return f"returned {type(traj).__name__}, not a dict of arrays"
    r = len(scenario.record_steps())
    shapes = {"positions": (r, n_bodies, 3), "quaternions": (r, n_bodies, 4),
              "velocities": (r, n_bodies, 3), "angular_velocities": (r, n_bodies, 3),
              "contacts": (r,)}
    for k in scenario.record:
        if k not in traj or traj[k] is None:
            return f"no {k!r} recorded (returned None)"
        a = np.asarray(traj[k])
        if a.shape != shapes[k]:
            return f"{k} has shape {a.shape}, expected {shapes[k]}"
        if not np.issubdtype(a.dtype, np.number) or not np.all(np.isfinite(a)):
            bad = np.argwhere(~np.isfinite(a.astype(float)))[0].tolist()
            return f"{k} is non-finite at index {bad}: {a[tuple(bad)]!r}"
    return None
