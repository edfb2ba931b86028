"""DEM certificates for any :class:`~peclet_verify.dem_backends.DemBackend`: determinism at one
thread, determinism across threads, contact-buffer growth, and closed-form mechanics (binary
restitution, slide to roll, incline stick/slip, the free rigid body).

Each property takes a backend and one drawn input, builds a
:class:`~peclet_verify.family_wire.Scenario` (the page's API as data), runs it, and returns a
:class:`~peclet_verify.properties.PropertyResult`; the strategies below draw the inputs on
integer grids (a failure shrinks in few steps) and every input prints as a runnable page-API
snippet (``describe``). Units: SI-like (m, s, kg), gravity 9.81 m/s^2 along -y, unit density
not assumed (masses are drawn). Tolerances are per property (keyword arguments, with the
basis of each default in its docstring); the physics follows validation/sanity.py.
"""
from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass

import numpy as np
from hypothesis import strategies as st

from .family_wire import STATE, Scenario, trajectory_problem
from .properties import PropertyResult, _bad_answer, _result, unavailable

__all__ = ["NOT_CLAIMED", "Pour", "pours", "pour_scenario", "determinism_one_thread",
           "determinism_across_threads", "buffer_growth", "capacity_hints",
           "Collision", "collisions", "binary_restitution", "Roll", "rolls", "slide_to_roll",
           "Incline", "inclines", "incline", "Rotor", "rotors", "free_rigid_body", "G",
           "run_checked"]

#: Status of a certificate an engine declares it does not claim (reported, never passed).
NOT_CLAIMED = "not claimed"
G = 9.81


def _box_encoding(half, translation=(0.0, 0.0, 0.0), rotation=None):
    from peclet.core.geom import SceneBuilder
    b = SceneBuilder()
    r = b.add_leaf("box", [float(h) for h in half], translation=list(translation),
                   rotation=None if rotation is None else list(rotation))
    ni, nr, _, _ = b.encode()
    return ni.tolist(), nr.tolist(), int(r)


def _name(backend):
    return getattr(backend, "name", type(backend).__name__)


def run_checked(backend, scenario, threads=1, n_bodies=None):
    """(trajectory, None) or (None, why): the backend's run, its answer checked first (an
    exception, None, a missing record, a wrong shape, NaN or inf is a ``why``)."""
    n = scenario.meta.get("n_bodies") if n_bodies is None else n_bodies
    try:
        traj = backend.run(scenario, threads)
    except Exception as exc:  # the engine's failure is the certificate's failure
        text = f"{type(exc).__name__}: {exc}".strip()
        return None, f"{_name(backend)} run at {threads} thread(s) raised {text[-1500:]}"
    why = trajectory_problem(traj, scenario, int(n))
    if why:
        return None, f"{_name(backend)} at {threads} thread(s): {why}"
    return {k: np.asarray(v, np.float64) for k, v in traj.items()}, None


def trajectory_hash(traj, keys=STATE + ("contacts",)) -> str:
    h = hashlib.sha256()
    for k in keys:
        if k in traj:
            a = np.ascontiguousarray(traj[k], dtype=np.float64)
            h.update(k.encode() + str(a.shape).encode() + a.tobytes())
    return h.hexdigest()


def _first_difference(a, b, scenario):
    steps = scenario.record_steps()
    for k in STATE + ("contacts",):
        if k in a and k in b:
            d = np.abs(a[k] - b[k]) if a[k].shape == b[k].shape else None
            if d is None:
                return f"{k}: shapes {a[k].shape} vs {b[k].shape}"
            bad = np.nonzero(d.reshape(len(d), -1).max(axis=1) > 0)[0] if d.ndim > 1 else \
                np.nonzero(d > 0)[0]
            if len(bad):
                i = int(bad[0])
                return (f"first difference in {k} at step {steps[i]} (record {i}), max |diff| "
                        f"{float(d[i].max()):.3e} there, {float(d.max()):.3e} over the run")
    return "no difference in the recorded arrays"


# ---------------------------------------------------------------------------- the pour
@dataclass(frozen=True)
class Pour:
    """Spheres (radii ``radii``, unit inverse mass) on a jittered lattice in a box container
    (an inverted box wall, floor y = 0), poured under gravity for ``steps`` steps of ``dt``."""

    radii: tuple
    jitter: tuple          # (n, 3) in units of 1/64 of the smallest radius
    velocities: tuple      # (n, 3) m/s
    e: float
    mu: float
    steps: int = 120
    dt: float = 2e-3

    @property
    def n(self):
        return len(self.radii)


def pour_scenario(p: Pour, capacity=None, contact_capacity=None, record_every=20) -> Scenario:
    """The page-API run of a :class:`Pour`."""
    r = np.asarray(p.radii, float)
    rmax, rmin = float(r.max()), float(r.min())
    pitch = 2.1 * rmax + 0.5 * rmin     # no overlap whatever the jitter (<= rmin / 4)
    per_row = 3
    idx = np.arange(p.n)
    cells = np.stack([idx % per_row, idx // (per_row * per_row), (idx // per_row) % per_row],
                     axis=1).astype(float)
    jit = np.asarray(p.jitter, float).reshape(p.n, 3) * rmin / 64.0
    pos = (cells + 0.5) * pitch + jit
    pos[:, 1] += 0.2 * rmax
    L = per_row * pitch
    H = float(pos[:, 1].max() + 2.0 * rmax)
    ni, nr, root = _box_encoding((L / 2, H / 2, L / 2), (L / 2, H / 2, L / 2))
    shapes = sorted(set(r.tolist()))
    calls = [("set_domain", ([-0.5 * L, -0.5 * L, -0.5 * L], [1.5 * L, H + L, 1.5 * L])),
             ("set_gravity", (0.0, -G, 0.0)),
             ("set_material_params", (p.e, 0.0, p.mu)),
             ("set_solver_iterations", (10, 8))]
    calls += [("add_sphere_shape", (s,)) for s in shapes]
    calls += [("add_analytic_wall", (ni, nr, root, True, p.e, p.mu)),
              ("set_positions", (pos,)),
              ("set_shape_ids", ([shapes.index(x) for x in r.tolist()],)),
              ("set_velocities", (np.asarray(p.velocities, float).reshape(p.n, 3),)),
              ("set_inv_mass", ([1.0] * p.n,)),
              ("set_inv_inertia", ([[2.5 / x ** 2] * 3 for x in r.tolist()],))]
    return Scenario(p.n if capacity is None else capacity, calls, p.dt, p.steps,
                    record=STATE + ("contacts",), record_every=record_every,
                    contact_capacity=contact_capacity,
                    label=f"pour of {p.n} spheres in a box", meta={"n_bodies": p.n,
                                                                   "radii": list(p.radii)})


def pours(n=(4, 12), steps=120) -> st.SearchStrategy:
    """:class:`Pour` of n (an int or (min, max)) spheres, radii 0.05 .. 0.1 m (two sizes), e in
    [0, 0.9], mu in [0, 0.8], speeds up to 1 m/s."""
    lo, hi = (n, n) if isinstance(n, int) else n

    def build(big, sizes, jit, vel, e, mu):
        m = len(sizes)
        radii = tuple(0.1 if s else 0.1 * big / 8 for s in sizes)
        return Pour(radii, tuple(map(tuple, np.asarray(jit[:m * 3]).reshape(m, 3).tolist())),
                    tuple(tuple(v / 64 for v in vel[3 * i:3 * i + 3]) for i in range(m)),
                    e / 10, mu / 10, steps)
    return st.integers(lo, hi).flatmap(lambda m: st.builds(
        build, st.integers(4, 8), st.lists(st.booleans(), min_size=m, max_size=m),
        st.lists(st.integers(-16, 16), min_size=3 * m, max_size=3 * m),
        st.lists(st.integers(-64, 64), min_size=3 * m, max_size=3 * m),
        st.integers(0, 9), st.integers(0, 8)))


def determinism_one_thread(backend, p: Pour) -> PropertyResult:
    """Two runs of the same pour at one thread give the same bytes (every recorded position,
    quaternion, velocity, angular velocity and contact count). Figure: distinct trajectory
    hashes (1 passes)."""
    name = "determinism_one_thread"
    sc = pour_scenario(p)
    runs = []
    for _ in range(2):
        traj, why = run_checked(backend, sc, 1)
        if why:
            return _bad_answer(name, "distinct state hashes", "max", why)
        runs.append(traj)
    hashes = [trajectory_hash(t) for t in runs]
    distinct = len(set(hashes))
    text = (f"{_name(backend)}: two runs at 1 thread differ: run 1 {hashes[0][:16]}, run 2 "
            f"{hashes[1][:16]}; {_first_difference(runs[0], runs[1], sc)}")
    return _result(name, distinct == 1, distinct, "distinct state hashes", "max", text,
                   hashes=hashes)


def determinism_across_threads(backend, p: Pour) -> PropertyResult:
    """The pour at every thread count the backend runs (``thread_counts``) gives the bytes of
    the one-thread run. A backend with ``thread_determinism = False`` does not claim it: status
    "not claimed". Needs a backend with a count above 1 ("unavailable" otherwise) and one that
    is deterministic at one thread (if the one-thread run does not reproduce, this certificate
    cannot judge and is "unavailable"; the one-thread certificate fails instead)."""
    name = "determinism_across_threads"
    fig = "distinct state hashes"
    if not getattr(backend, "thread_determinism", True):
        return PropertyResult(name, False, 0, float("nan"), fig,
                              f"{_name(backend)} declares thread_determinism = False: results "
                              "are not claimed identical across thread counts", NOT_CLAIMED)
    counts = [int(t) for t in getattr(backend, "thread_counts", (1, 2)) if int(t) > 1]
    if not counts:
        return unavailable(name, f"{_name(backend)} runs one thread only (thread_counts "
                                 f"{tuple(getattr(backend, 'thread_counts', ()))})")
    sc = pour_scenario(p)
    base, why = run_checked(backend, sc, 1)
    if why:
        return _bad_answer(name, fig, "max", why)
    hashes = {"1 thread": trajectory_hash(base)}
    first_diff = None
    for t in counts:
        traj, why = run_checked(backend, sc, t)
        if why:
            return _bad_answer(name, fig, "max", why)
        hashes[f"{t} threads"] = trajectory_hash(traj)
        if first_diff is None and hashes[f"{t} threads"] != hashes["1 thread"]:
            first_diff = f"{t} threads vs 1: {_first_difference(base, traj, sc)}"
    distinct = len(set(hashes.values()))
    if distinct > 1:
        again, why = run_checked(backend, sc, 1)
        if why:
            return _bad_answer(name, fig, "max", why)
        if trajectory_hash(again) != hashes["1 thread"]:
            return unavailable(name, f"{_name(backend)} is not deterministic at one thread "
                                     "(two one-thread runs differ), so agreement across "
                                     "thread counts cannot be judged; see the one-thread "
                                     "determinism certificate")
    text = (f"{_name(backend)}: state hashes differ across thread counts: " +
            "; ".join(f"{k}: {v[:16]}" for k, v in hashes.items()) + f"\n{first_diff}")
    return _result(name, distinct == 1, distinct, fig, "max", text, hashes=hashes,
                   thread_counts=[1] + counts)


def capacity_hints(max_size=3) -> st.SearchStrategy:
    """Lists of (particle capacity hint, contact capacity hint) pairs, each forcing growth:
    particle hints 1 .. 4, contact hints 1 .. 8."""
    return st.lists(st.tuples(st.integers(1, 4), st.integers(1, 8)), min_size=1,
                    max_size=max_size)


def _max_overlap(traj, radii):
    """Worst sphere-sphere overlap over the records, as a fraction of the smaller radius."""
    r = np.asarray(radii, float)
    worst = 0.0
    for x in traj["positions"]:
        d = np.linalg.norm(x[:, None, :] - x[None, :, :], axis=2)
        s = r[:, None] + r[None, :]
        np.fill_diagonal(d, np.inf)
        ov = (s - d) / np.minimum(r[:, None], r[None, :])
        worst = max(worst, float(ov.max()))
    return worst


def buffer_growth(backend, p: Pour, hints, max_overlap=0.1) -> PropertyResult:
    """The pour under capacity hints that force growth (``Simulation(capacity)`` with fewer
    particles than the pour has, a contact-capacity hint of a few contacts) gives the same
    trajectory as under ample hints (bit for bit; for an engine that does not reproduce its own
    ample run, within 4 x its run-to-run spread), the same contact counts (no contact lost),
    no crash, and no sphere pair overlapping by more than ``max_overlap`` of the smaller
    radius at any record (a dropped contact lets spheres sink into each other; peclet's
    tolerated overlap is 5e-4 of a radius). Figure: the number of hint pairs whose run differs
    (0 passes)."""
    name = "buffer_growth"
    fig = "differing contact sets"
    ample_sc = pour_scenario(p, capacity=4 * p.n, contact_capacity=64 * 8 * p.n)
    ample, why = run_checked(backend, ample_sc, 1)
    if why:
        return _bad_answer(name, fig, "max", why)
    spread = None
    differing, lines = 0, []
    ov = _max_overlap(ample, p.radii)
    if ov > max_overlap:
        differing += 1
        lines.append(f"ample hints: spheres overlap by {ov:.3g} of a radius (> {max_overlap})")
    for cap, ccap in hints:
        sc = pour_scenario(p, capacity=cap, contact_capacity=ccap)
        traj, why = run_checked(backend, sc, 1)
        if why:
            differing += 1
            lines.append(f"Simulation({cap}), contact capacity {ccap}: {why}")
            continue
        same = trajectory_hash(traj) == trajectory_hash(ample)
        if not same:
            if spread is None:
                again, why = run_checked(backend, ample_sc, 1)
                if why:
                    return _bad_answer(name, fig, "max", why)
                spread = max(float(np.abs(again[k] - ample[k]).max()) for k in STATE)
            if spread > 0:
                worst = max(float(np.abs(traj[k] - ample[k]).max()) for k in STATE)
                same = worst <= 4.0 * spread and np.array_equal(traj["contacts"],
                                                                ample["contacts"])
        ov = _max_overlap(traj, p.radii)
        lost = int(np.sum(traj["contacts"] < ample["contacts"]))
        if not same or ov > max_overlap:
            differing += 1
            lines.append(f"Simulation({cap}), contact capacity {ccap}: "
                         f"{_first_difference(traj, ample, sc)}; contact counts "
                         f"{traj['contacts'].astype(int).tolist()} vs ample "
                         f"{ample['contacts'].astype(int).tolist()} ({lost} record(s) with "
                         f"fewer contacts); worst overlap {ov:.3g} of a radius")
    text = f"{_name(backend)}: " + "\n".join(lines)
    return _result(name, differing == 0, differing, fig, "max", text,
                   ample_contacts=ample["contacts"].astype(int).tolist(),
                   run_to_run_spread=spread)


# ---------------------------------------------------------------------------- restitution
def _unit(v):
    v = np.asarray(v, float)
    n = np.linalg.norm(v)
    return np.array([1.0, 0.0, 0.0]) if n == 0 else v / n


@dataclass(frozen=True)
class Collision:
    """Two spheres head-on along ``axis`` without gravity: radii, masses, approach speeds (each
    towards the other), restitution e and friction mu."""

    radii: tuple
    masses: tuple
    speeds: tuple
    axis: tuple
    e: float
    mu: float
    dt: float = 1e-3

    def scenario(self):
        n = _unit(self.axis)
        r1, r2 = self.radii
        v1, v2 = self.speeds
        closing = v1 + v2
        gap = 20 * self.dt * closing         # contact after ~20 steps
        x2 = (r1 + r2 + gap) * n
        calls = [("set_gravity", (0.0, 0.0, 0.0)),
                 ("set_material_params", (self.e, 0.0, self.mu)),
                 ("set_solver_iterations", (10, 8)),
                 ("add_sphere_shape", (r1,)), ("add_sphere_shape", (r2,)),
                 ("set_positions", ([[0.0, 0.0, 0.0], x2.tolist()],)),
                 ("set_shape_ids", ([0, 1],)),
                 ("set_velocities", ([(v1 * n).tolist(), (-v2 * n).tolist()],)),
                 ("set_inv_mass", ([1.0 / self.masses[0], 1.0 / self.masses[1]],)),
                 ("set_inv_inertia", ([[2.5 / (self.masses[0] * r1 ** 2)] * 3,
                                       [2.5 / (self.masses[1] * r2 ** 2)] * 3],))]
        return Scenario(2, calls, self.dt, 60, record=("velocities",),
                        label=f"binary collision, e = {self.e!r}: separation / approach "
                              f"speed must be e", meta={"n_bodies": 2})


def collisions() -> st.SearchStrategy:
    """Radii 0.1 .. 0.6 m, masses 0.2 .. 5 kg, speeds 0.25 .. 3 m/s, e in [0, 1] (1/64
    steps), mu in [0, 1], axis any direction (integer components)."""
    return st.builds(
        lambda r1, r2, m1, m2, s1, s2, ax, e, mu: Collision(
            (r1 / 20, r2 / 20), (m1 / 5, m2 / 5), (s1 / 4, s2 / 4),
            tuple(float(c) for c in ax) if any(ax) else (1.0, 0.0, 0.0), e / 64, mu / 8),
        st.integers(2, 12), st.integers(2, 12), st.integers(1, 25), st.integers(1, 25),
        st.integers(1, 12), st.integers(1, 12),
        st.tuples(st.integers(-4, 4), st.integers(-4, 4), st.integers(-4, 4)),
        st.integers(0, 64), st.integers(0, 8))


def binary_restitution(backend, c: Collision, tol=1e-4, momentum_rtol=1e-6):
    """Separation speed / approach speed along the line of centres equals e (within ``tol``,
    absolute: an impulse solve of one two-body contact is exact, peclet's error is ~1e-15;
    1e-4 leaves room for single precision), and momentum is conserved (``momentum_rtol`` of
    the larger momentum). Figure: |ratio - e|."""
    name = "binary_restitution"
    sc = c.scenario()
    traj, why = run_checked(backend, sc, 1)
    if why:
        return _bad_answer(name, "|ratio - e|", "max", why)
    n = _unit(c.axis)
    v = traj["velocities"][-1]
    approach = c.speeds[0] + c.speeds[1]
    sep = float((v[1] - v[0]) @ n)
    ratio = sep / approach
    m = np.asarray(c.masses, float)
    p0 = m[0] * c.speeds[0] * n - m[1] * c.speeds[1] * n
    dp = float(np.linalg.norm((m[:, None] * v).sum(axis=0) - p0))
    pscale = float(max(m * np.asarray(c.speeds)))
    err = abs(ratio - c.e)
    ok = err <= tol and dp <= momentum_rtol * pscale
    text = (f"{_name(backend)}: separation / approach = {sep:.9g} / {approach:.9g} = "
            f"{ratio:.9g}, expected e = {c.e!r} (|diff| {err:.3e}, tol {tol:g}); momentum "
            f"change {dp:.3e} (allowed {momentum_rtol * pscale:.3e})")
    return _result(name, ok, err, "|ratio - e|", "max", text, ratio=ratio, momentum_error=dp)


# ---------------------------------------------------------------------------- slide to roll
@dataclass(frozen=True)
class Roll:
    """A solid sphere (radius, mass) set down sliding at v0 (no spin) on a floor with friction
    mu (wall and body), e = 0."""

    radius: float
    mass: float
    v0: float
    mu: float
    dt: float = 2e-3

    @property
    def t_roll(self):
        return 2.0 * self.v0 / (7.0 * self.mu * G)

    def scenario(self):
        r = self.radius
        ni, nr, root = _box_encoding((50.0, 1.0, 50.0), (0.0, -1.0, 0.0))
        steps = int(math.ceil((self.t_roll + 0.1) / self.dt))
        calls = [("set_gravity", (0.0, -G, 0.0)),
                 ("set_material_params", (0.0, 0.0, self.mu)),
                 ("set_solver_iterations", (10, 8)),
                 ("add_sphere_shape", (r,)),
                 ("add_analytic_wall", (ni, nr, root, False, 0.0, self.mu)),
                 ("set_positions", ([[0.0, r, 0.0]],)), ("set_shape_ids", ([0],)),
                 ("set_velocities", ([[self.v0, 0.0, 0.0]],)),
                 ("set_inv_mass", ([1.0 / self.mass],)),
                 ("set_inv_inertia", ([[2.5 / (self.mass * r * r)] * 3],))]
        return Scenario(1, calls, self.dt, steps, record=("velocities", "angular_velocities"),
                        label=f"slide to roll: v must reach 5/7 v0 = {5 * self.v0 / 7!r} "
                              f"from t = {self.t_roll:.4g} s", meta={"n_bodies": 1})


def rolls() -> st.SearchStrategy:
    """Radius 0.1 .. 1 m, mass 0.5 .. 5 kg, v0 0.5 .. 3 m/s, mu 0.2 .. 0.8 (the roll starts
    within 0.44 s)."""
    return st.builds(lambda r, m, v, mu: Roll(r / 10, m / 2, v / 4, mu / 20),
                     st.integers(1, 10), st.integers(1, 10), st.integers(2, 12),
                     st.integers(4, 16))


def slide_to_roll(backend, roll: Roll, rtol=1e-4):
    """After the slip stops (t = 2 v0 / (7 mu g), run 0.1 s past it) the sphere rolls at
    v = 5/7 v0 with omega r = v: both within ``rtol`` x v0 (peclet: 1e-9, exact sliding
    friction impulses; 1e-4 leaves room for single precision). Figure: worst relative error."""
    name = "slide_to_roll"
    sc = roll.scenario()
    traj, why = run_checked(backend, sc, 1)
    if why:
        return _bad_answer(name, "rel error", "max", why)
    v = traj["velocities"][-1, 0]
    w = traj["angular_velocities"][-1, 0]
    vx = float(v[0])
    wr = float(-w[2] * roll.radius)
    e_v = abs(vx - 5.0 * roll.v0 / 7.0) / roll.v0
    e_roll = abs(vx - wr) / roll.v0
    worst = max(e_v, e_roll)
    text = (f"{_name(backend)}: final v = {vx:.9g} m/s, expected 5/7 v0 = "
            f"{5 * roll.v0 / 7:.9g} (rel error {e_v:.2e}); omega r = {wr:.9g} (slip "
            f"{e_roll:.2e} of v0); tol {rtol:g}")
    return _result(name, worst <= rtol, worst, "rel error", "max", text, v=vx, omega_r=wr)


# ---------------------------------------------------------------------------- incline
def cube_shell(half, k=5):
    """Surface probes of a cube of half side ``half``: a k x k grid on every face (edges and
    corners included), duplicates removed."""
    u = np.linspace(-half, half, k)
    a, b = np.meshgrid(u, u, indexing="ij")
    pts = []
    for ax in range(3):
        o1, o2 = [i for i in range(3) if i != ax]
        for s in (-half, half):
            p = np.zeros((k * k, 3))
            p[:, ax] = s
            p[:, o1] = a.ravel()
            p[:, o2] = b.ravel()
            pts.append(p)
    return np.unique(np.round(np.concatenate(pts), 12), axis=0)


@dataclass(frozen=True)
class Incline:
    """A cube (half side ``half``, mass 1, a box CSG scene shape) released at rest on a plane
    inclined at ``theta_deg``, friction mu (wall and body), e = 0; ``t_end`` seconds."""

    half: float
    theta_deg: float
    mu: float
    dt: float = 1e-3
    t_end: float = 0.4

    @property
    def sticks(self):
        return math.tan(math.radians(self.theta_deg)) < self.mu

    def scenario(self):
        from peclet.core.geom.transforms import matrix_to_quat
        th = math.radians(self.theta_deg)
        c, s = math.cos(th), math.sin(th)
        R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        q = matrix_to_quat(R).tolist()
        h = self.half
        wall = _box_encoding((20.0, 1.0, 20.0), (R @ [0.0, -1.0, 0.0]).tolist(), q)
        cube = _box_encoding((h, h, h))
        shell = cube_shell(h)
        x0 = (R @ np.array([0.0, h, 0.0])).tolist()
        calls = [("set_gravity", (0.0, -G, 0.0)),
                 ("set_material_params", (0.0, 0.0, self.mu)),
                 ("set_solver_iterations", (10, 8)),
                 ("add_scene_shape", (cube[0], cube[1], cube[2], shell.tolist(),
                                      math.sqrt(3.0) * h)),
                 ("add_analytic_wall", (wall[0], wall[1], wall[2], False, 0.0, self.mu)),
                 ("set_positions", ([x0],)), ("set_shape_ids", ([0],)),
                 ("set_quaternions", ([q],)), ("set_inv_mass", ([1.0],)),
                 ("set_inv_inertia", ([[1.5 / h ** 2] * 3],))]
        steps = int(round(self.t_end / self.dt))
        return Scenario(1, calls, self.dt, steps, record=("positions",), record_every=1,
                        label=f"cube on an incline of {self.theta_deg!r} deg (tan = "
                              f"{math.tan(th):.4f}), mu = {self.mu!r}: must "
                              f"{'stick' if self.sticks else 'slide with a = g (sin - mu cos)'}",
                        meta={"n_bodies": 1})


def inclines() -> st.SearchStrategy:
    """Half side 0.2 .. 0.6 m, theta 10 .. 35 deg; mu = tan(theta) x f with f in [0.5, 0.85]
    (slides) or [1.15, 2] (sticks): at least 15 % away from the threshold."""
    def build(h, th, stick, f):
        t = math.tan(math.radians(th))
        mu = t * ((115 + f) / 100 if stick else (85 - f * 35 / 85) / 100)
        return Incline(h / 10, float(th), round(mu, 6))
    return st.builds(build, st.integers(2, 6), st.integers(10, 35), st.booleans(),
                     st.integers(0, 85))


def incline(backend, inc: Incline, settle=0.1, creep_tol=1e-6, a_rtol=1e-3):
    """tan(theta) < mu: the cube sticks (after ``settle`` s its displacement down the slope
    changes by at most ``creep_tol`` x half side; in all at most the free slide of 3 steps,
    g sin(theta) (3 dt)^2 / 2, for a friction that starts cold). tan(theta) > mu: it slides
    with a = g (sin theta - mu cos theta) (least squares over t >= ``settle``, within
    ``a_rtol``; peclet 1e-6). Figure: the worst error over its allowance (<= 1 passes)."""
    name = "incline"
    fig = "error / allowed"
    sc = inc.scenario()
    traj, why = run_checked(backend, sc, 1)
    if why:
        return _bad_answer(name, fig, "max", why)
    th = math.radians(inc.theta_deg)
    down = np.array([-math.cos(th), -math.sin(th), 0.0])
    x = traj["positions"][:, 0, :]
    d = (x - x[0]) @ down
    t = np.asarray(sc.record_steps(), float) * inc.dt
    k = int(np.searchsorted(t, settle - 1e-12))
    if inc.sticks:
        creep = abs(d[-1] - d[k])
        slip = abs(d[-1])
        cold = 0.5 * G * math.sin(th) * (3 * inc.dt) ** 2
        ratio = max(creep / (creep_tol * inc.half), slip / cold)
        text = (f"{_name(backend)}: tan(theta) = {math.tan(th):.4f} < mu = {inc.mu}: must "
                f"stick, but it moved {creep:.3e} m after {settle} s (allowed "
                f"{creep_tol * inc.half:.1e}) and {slip:.3e} m in all (allowed {cold:.2e})")
        return _result(name, ratio <= 1.0, ratio, fig, "max", text, creep=creep, slip=slip)
    a_exp = G * (math.sin(th) - inc.mu * math.cos(th))
    m = t >= settle
    A = np.column_stack([np.ones(m.sum()), t[m], 0.5 * t[m] ** 2])
    a = float(np.linalg.lstsq(A, d[m], rcond=None)[0][2])
    err = abs(a - a_exp) / a_exp
    text = (f"{_name(backend)}: tan(theta) = {math.tan(th):.4f} > mu = {inc.mu}: slides "
            f"with a = {a:.9g} m/s^2, expected g (sin - mu cos) = {a_exp:.9g} (rel error "
            f"{err:.2e}, tol {a_rtol:g})")
    return _result(name, err <= a_rtol, err / a_rtol, fig, "max", text, a=a, a_expected=a_exp)


# ---------------------------------------------------------------------------- free rotor
@dataclass(frozen=True)
class Rotor:
    """A torque-free body with principal moments ``moments`` (distinct), spinning mostly about
    the intermediate axis (body angular velocity ``omega_body``), orientation ``quat``."""

    moments: tuple
    omega_body: tuple
    quat: tuple
    per_period: int = 400
    periods: float = 2.4

    def reference_period(self):
        from .reference.rotor import free_rotor_period
        iinv = 1.0 / np.asarray(self.moments, float)
        return free_rotor_period(iinv, np.asarray(self.moments) * np.asarray(self.omega_body))

    def scenario(self):
        from peclet.core.geom import quat_to_matrix
        T = self.reference_period()
        dt = T / self.per_period
        R = quat_to_matrix(np.asarray(self.quat, float))
        w_world = (R @ np.asarray(self.omega_body, float)).tolist()
        calls = [("set_gravity", (0.0, 0.0, 0.0)),
                 ("add_sphere_shape", (0.5,)),
                 ("set_positions", ([[0.0, 0.0, 0.0]],)), ("set_shape_ids", ([0],)),
                 ("set_quaternions", ([list(self.quat)],)),
                 ("set_angular_velocities", ([w_world],)),
                 ("set_inv_mass", ([1.0],)),
                 ("set_inv_inertia", ([[1.0 / m for m in self.moments]],))]
        return Scenario(1, calls, dt, int(math.ceil(self.periods * self.per_period)),
                        record=("quaternions", "angular_velocities"), record_every=1,
                        label=f"free rigid body, moments {self.moments}: energy and angular "
                              f"momentum conserved, flip period {T:.6g} s",
                        meta={"n_bodies": 1})


def rotors() -> st.SearchStrategy:
    """Moments I1 < I2 < I3 (I2 = I1 (1 + a), I3 = I2 (1 + b), a, b in [0.25, 2]), |omega|
    2 .. 20 rad/s about the intermediate axis tilted by 1 .. 10 % towards the others, any
    orientation (integer axis, angle in 1/64 turns)."""
    def build(i1, a, b, w, e1, e3, ax, k):
        I1 = i1 / 4
        I2 = I1 * (1 + a / 4)
        I3 = I2 * (1 + b / 4)
        om = (w * e1 / 100, float(w), w * e3 / 100)
        axis = _unit(ax if any(ax) else (0, 0, 1))
        half = math.pi * k / 64
        q = (*(math.sin(half) * axis), math.cos(half))
        return Rotor((I1, I2, I3), om, tuple(float(v) for v in q))
    return st.builds(build, st.integers(1, 8), st.integers(1, 8), st.integers(1, 8),
                     st.integers(2, 20), st.integers(1, 10), st.integers(1, 10),
                     st.tuples(st.integers(-4, 4), st.integers(-4, 4), st.integers(-4, 4)),
                     st.integers(0, 63))


def free_rigid_body(backend, rot: Rotor, conservation_rtol=1e-6, period_rtol=1e-2):
    """No contact, no gravity: the kinetic energy and the world angular momentum are conserved
    (relative drift <= ``conservation_rtol``; peclet ~1e-12, an implicit-midpoint rotor), and
    the intermediate-axis flip period, from the upward zero crossings of the body angular
    momentum's intermediate component (cubic Hermite, exact derivatives from Euler's
    equations), equals the closed form of Euler's equations
    (:func:`peclet_verify.reference.rotor.free_rotor_period`) within ``period_rtol`` (the
    run takes 400 steps per period; a second-order integrator is ~1e-4 off). Figure: the
    worst error over its allowance."""
    from peclet.core.geom import quat_to_matrix
    from .reference.rotor import crossing_times, period_from_crossings
    name = "free_rigid_body"
    fig = "error / allowed"
    sc = rot.scenario()
    T = rot.reference_period()
    traj, why = run_checked(backend, sc, 1)
    if why:
        return _bad_answer(name, fig, "max", why)
    I = np.asarray(rot.moments, float)
    qs, ws = traj["quaternions"][:, 0], traj["angular_velocities"][:, 0]
    Rs = np.stack([quat_to_matrix(q / np.linalg.norm(q)) for q in qs])
    wb = np.einsum("kji,kj->ki", Rs, ws)            # R^T omega
    Lb = I * wb
    Lw = np.einsum("kij,kj->ki", Rs, Lb)
    E = 0.5 * np.sum(I * wb * wb, axis=1)
    dL = float(np.linalg.norm(Lw - Lw[0], axis=1).max() / np.linalg.norm(Lw[0]))
    dE = float(np.abs(E - E[0]).max() / E[0])
    t = np.asarray(sc.record_steps(), float) * sc.dt
    dLdt = np.cross(Lb, Lb / I)
    ups = crossing_times(t, Lb[:, 1], dLdt[:, 1], direction=+1)
    if len(ups) < 2:
        ratio_p = math.inf
        text_p = (f"the intermediate component of L crossed zero upwards {len(ups)} time(s) in "
                  f"{t[-1]:.4g} s, expected 2 (period {T:.6g} s): no flip")
        Tm = float("nan")
    else:
        Tm = period_from_crossings(ups)
        ratio_p = abs(Tm - T) / T / period_rtol
        text_p = (f"flip period {Tm:.9g} s, Euler's equations {T:.9g} s (rel error "
                  f"{abs(Tm - T) / T:.2e}, tol {period_rtol:g})")
    worst = max(dL / conservation_rtol, dE / conservation_rtol, ratio_p)
    text = (f"{_name(backend)}: angular momentum drift {dL:.2e}, energy drift {dE:.2e} (tol "
            f"{conservation_rtol:g}); {text_p}")
    return _result(name, worst <= 1.0, worst, fig, "max", text, momentum_drift=dL,
                   energy_drift=dE, period=Tm, period_reference=T)
