"""DEM certificates: determinism and contact-buffer growth, of peclet's own engine
(:func:`determinism`, :func:`buffer_growth`: a pour and a scene shape's contacts) and of any
:class:`~peclet_verify.dem_backends.DemBackend` (:func:`determinism_one_thread`,
:func:`determinism_across_threads`, :func:`dem_buffer_growth`: a pour described as a
:class:`~peclet_verify.family_wire.Scenario`).
"""
from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from typing import Callable, Optional

import numpy as np

from .. import registry as REG
from ..backends import backend_name
from ..family_wire import STATE, trajectory_problem
from ..reference.contacts import brute_force_contacts
from ..strategies import Pour, TreeRecipe, pour_scenario, surface_points
from .core import (NOT_CLAIMED, PropertyResult, _bad_answer, _encode, _result, _rng,
                   unavailable)

__all__ = ["state_hash", "reference_pour", "determinism", "buffer_growth",
           "brute_force_contacts", "run_checked", "trajectory_hash", "determinism_one_thread",
           "determinism_across_threads", "dem_buffer_growth"]


def state_hash(arrays) -> str:
    """sha256 of the bytes of a sequence (or dict, by sorted key) of arrays."""
    if isinstance(arrays, dict):
        arrays = [arrays[k] for k in sorted(arrays)]
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(str(a.dtype).encode() + str(a.shape).encode() + a.tobytes())
    return h.hexdigest()


def reference_pour(state, steps: int = 20):
    """A short pour of spheres (radius 0.25) from ``state`` on a floor with peclet.dem;
    returns the final (positions, quaternions, velocities, angular velocities)."""
    from peclet.dem import Simulation
    import numpy as _np
    n = state.n
    sim = Simulation(n)
    lo = state.positions.min(axis=0) - 1.0
    hi = state.positions.max(axis=0) + 1.0
    sim.set_domain(tuple(lo), tuple(hi))
    sim.set_gravity(0.0, -9.81, 0.0)
    sim.set_material_params(0.3, 0.0, 0.5)
    shape = sim.add_sphere_shape(0.25)
    sim.set_positions(state.positions)
    sim.set_shape_ids(_np.full(n, shape, _np.int32))
    sim.set_quaternions(state.quaternions)
    sim.set_velocities(state.velocities)
    sim.set_angular_velocities(state.angular_velocities)
    sim.set_inv_mass(_np.ones(n))
    sim.set_inv_inertia(_np.full((n, 3), 1.0 / (0.4 * 0.25 ** 2)))
    for _ in range(steps):
        sim.step(1e-3)
    return [_np.asarray(sim.get_positions()), _np.asarray(sim.get_quaternions()),
            _np.asarray(sim.get_velocities()), _np.asarray(sim.get_angular_velocities())]


def determinism(state, pour: Optional[Callable] = None, threads=(1, 2)) -> PropertyResult:
    """``pour(state)`` gives bitwise the same state twice at one thread and at every thread
    count in ``threads`` (numba.set_num_threads; counts above the pool size are dropped).
    Figure: the number of distinct state hashes (1 passes)."""
    import numba
    name = "determinism"
    fig = REG.figure(name)
    pour = pour or reference_pour
    cap = numba.config.NUMBA_NUM_THREADS
    counts = [t for t in threads if 1 <= t <= cap]
    before = numba.get_num_threads()
    hashes = {}
    try:
        numba.set_num_threads(counts[0])
        runs = [(f"{counts[0]} thread(s), run {i + 1}", counts[0]) for i in range(2)]
        runs += [(f"{t} thread(s)", t) for t in counts[1:]]
        for label, t in runs:
            numba.set_num_threads(t)
            hashes[label] = state_hash(pour(state))
    except (ImportError, AttributeError, NotImplementedError) as exc:
        return unavailable(name, f"pour not available: {exc}")
    finally:
        numba.set_num_threads(before)
    distinct = len(set(hashes.values()))
    text = "state hashes differ: " + "; ".join(f"{k}: {v[:16]}" for k, v in hashes.items())
    return _result(name, distinct == 1, distinct, fig, "max", text,
                   hashes=hashes, thread_counts=counts)


# ---------------------------------------------------------------------------- buffer growth
_BUFFER_CHILD = r"""
import json, sys
import numpy as np
from peclet_verify.properties.dem import _buffer_growth_inprocess
args = json.loads(sys.stdin.read())
print(json.dumps(_buffer_growth_inprocess(**args)))
"""


def buffer_growth(recipe: TreeRecipe, capacities, state, engine: str = "reference",
                  n_probes: int = 64, timeout: float = 600.0) -> PropertyResult:
    """Contacts found under every contact capacity in ``capacities`` (applied in order with
    ``set_contact_capacity``) equal the contacts at ample capacity, and the touching pairs
    equal the brute-force reference (:func:`brute_force_contacts`); nothing is written out of
    bounds. Runs in a subprocess with ``NUMBA_BOUNDSCHECK=1`` (read at import), so an
    out-of-bounds write is an IndexError there rather than silent corruption.

    ``engine`` is ``"reference"`` (peclet.dem.Simulation) or ``"module:factory"`` with
    ``factory(node_ints, node_reals, root, probes, radius, state) -> engine`` exposing
    ``set_contact_capacity(n)`` and ``detect_contacts()``. Figure: number of contact sets
    that differ from the reference.
    """
    b, root, ni, nr = _encode(recipe)
    c, r, _ = b.node_bound(root)
    rng = _rng("probes", ni.tobytes(), nr.tobytes())
    probes = surface_points(b, root, c + rng.uniform(-r, r, (n_probes, 3)), iterations=12)
    args = dict(node_ints=ni.tolist(), node_reals=nr.tolist(), root=int(root),
                probes=probes.tolist(), radius=float(np.max(np.linalg.norm(probes, axis=1))),
                positions=np.asarray(state.positions).tolist(),
                quaternions=np.asarray(state.quaternions).tolist(),
                capacities=[int(x) for x in capacities], engine=engine)
    env = dict(os.environ, NUMBA_BOUNDSCHECK="1")
    proc = subprocess.run([sys.executable, "-c", _BUFFER_CHILD], input=json.dumps(args),
                          capture_output=True, text=True, env=env, timeout=timeout)
    name = "buffer_growth"
    fig = REG.figure(name)
    if proc.returncode != 0 or not proc.stdout.strip():
        return _result(name, False, float("inf"), fig, "max",
                       f"child crashed (exit {proc.returncode}):\n{proc.stderr[-2000:]}")
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    if out.get("unavailable"):
        return unavailable(name, out["unavailable"])
    return _result(name, out["ok"], out["differing"], fig, "max",
                   out["text"], reference_pairs=out["reference_contacts"],
                   engine_contacts=out.get("engine_contacts"))


class _DemEngine:
    """peclet.dem.Simulation set up with one scene shape at the given state."""

    def __init__(self, ni, nr, root, probes, radius, positions, quaternions):
        from peclet.dem import Simulation
        n = len(positions)
        self.sim = Simulation(n)
        lo = np.min(positions, axis=0) - 4 * radius
        hi = np.max(positions, axis=0) + 4 * radius
        self.sim.set_domain(tuple(lo), tuple(hi))
        shape = self.sim.add_scene_shape(ni, nr, root, probes, radius)
        self.sim.set_positions(positions)
        self.sim.set_shape_ids(np.full(n, shape, np.int32))
        self.sim.set_quaternions(quaternions)

    def set_contact_capacity(self, n):
        self.sim.set_contact_capacity(n)

    def detect_contacts(self):
        return self.sim.detect_contacts()


def _contact_rows(contacts):
    """Normalise an engine's contacts to sorted rows (a, b, point[3], normal[3], depth
    [, feature])."""
    def col(key):
        v = contacts[key] if isinstance(contacts, dict) else getattr(contacts, key)
        return np.asarray(v, dtype=np.float64)
    a, b = col("body_a"), col("body_b")
    cols = [a, b, col("point").reshape(len(a), 3), col("normal").reshape(len(a), 3),
            col("depth")]
    has_feature = "feature" in contacts if isinstance(contacts, dict) else \
        hasattr(contacts, "feature")
    if has_feature:
        cols.append(col("feature"))
    rows = np.column_stack(cols) if len(a) else np.zeros((0, 9 + has_feature))
    order = np.lexsort(rows.T[::-1]) if len(rows) else np.zeros(0, int)
    return rows[order]


def _buffer_growth_inprocess(node_ints, node_reals, root, probes, radius, positions,
                             quaternions, capacities, engine):
    ni = np.asarray(node_ints, np.int32)
    nr = np.asarray(node_reals, np.float64)
    probes = np.asarray(probes)
    pos = np.asarray(positions, float)
    quat = np.asarray(quaternions, float)
    try:
        if engine == "reference":
            make = _DemEngine
        else:
            mod, attr = engine.split(":")
            make = getattr(__import__(mod, fromlist=[attr]), attr)
        eng = make(ni, nr, root, probes, radius, pos, quat)
        eng.set_contact_capacity
        eng.detect_contacts
    except (ImportError, AttributeError, NotImplementedError) as exc:
        return {"unavailable": f"engine {engine!r} not available: {type(exc).__name__}: {exc}"}
    from peclet.core.geom import SceneBuilder
    ref = {tuple(sorted(c[:2])) for c in
           brute_force_contacts(SceneBuilder.decode(ni, nr), root, probes, pos, quat)}
    def detect(cap):
        eng.set_contact_capacity(int(cap))
        return _contact_rows(eng.detect_contacts())

    ample_cap = max(4 * len(probes) * len(pos) * max(len(pos) - 1, 1), 16)
    differing, text = 0, ""
    try:
        ample = detect(ample_cap)
    except IndexError as exc:
        return {"ok": False, "differing": 1, "reference_contacts": len(ref),
                "text": f"out-of-bounds write at ample capacity {ample_cap} "
                        f"(NUMBA_BOUNDSCHECK=1): {exc}"}
    # speculative contacts (depth <= 0: still apart) are not penetrations
    got_pairs = {tuple(sorted((int(x), int(y)))) for x, y in ample[ample[:, 8] > 0, :2]}
    if got_pairs != ref:
        differing += 1
        text += (f"at ample capacity the touching pairs {sorted(got_pairs)} differ from the "
                 f"brute-force reference {sorted(ref)}\n")
    for cap in capacities:
        try:
            rows = detect(cap)
        except IndexError as exc:
            return {"ok": False, "differing": differing + 1, "reference_contacts": len(ref),
                    "text": text + f"out-of-bounds write at capacity {cap} (NUMBA_BOUNDSCHECK=1)"
                                   f": {exc}"}
        if rows.shape != ample.shape or not np.array_equal(rows, ample):
            differing += 1
            text += (f"capacity {cap}: {len(rows)} contacts, at ample capacity {len(ample)}"
                     " (contacts lost or changed)\n")
    return {"ok": differing == 0, "differing": differing, "text": text,
            "reference_contacts": len(ref), "engine_contacts": int(len(ample))}


# ---------------------------------------------------------------------------- any DEM backend
def run_checked(backend, scenario, threads=1, n_bodies=None):
    """(trajectory, None) or (None, why): the backend's run, its answer checked first (an
    exception, None, a missing record, a wrong shape, NaN or inf is a ``why``)."""
    n = scenario.meta.get("n_bodies") if n_bodies is None else n_bodies
    try:
        traj = backend.run(scenario, threads)
    except Exception as exc:  # the engine's failure is the certificate's failure
        text = f"{type(exc).__name__}: {exc}".strip()
        return None, f"{backend_name(backend)} run at {threads} thread(s) raised {text[-1500:]}"
    why = trajectory_problem(traj, scenario, int(n))
    if why:
        return None, f"{backend_name(backend)} at {threads} thread(s): {why}"
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


def determinism_one_thread(backend, p: Pour) -> PropertyResult:
    """Two runs of the same pour at one thread give the same bytes (every recorded position,
    quaternion, velocity, angular velocity and contact count). Figure: distinct trajectory
    hashes (1 passes)."""
    name = "determinism_one_thread"
    fig = REG.figure(name)
    sc = pour_scenario(p)
    runs = []
    for _ in range(2):
        traj, why = run_checked(backend, sc, 1)
        if why:
            return _bad_answer(name, fig, "max", why)
        runs.append(traj)
    hashes = [trajectory_hash(t) for t in runs]
    distinct = len(set(hashes))
    text = (f"{backend_name(backend)}: two runs at 1 thread differ: run 1 {hashes[0][:16]}, run 2 "
            f"{hashes[1][:16]}; {_first_difference(runs[0], runs[1], sc)}")
    return _result(name, distinct == 1, distinct, fig, "max", text,
                   hashes=hashes)


def determinism_across_threads(backend, p: Pour) -> PropertyResult:
    """The pour at every thread count the backend runs (``thread_counts``) gives the bytes of
    the one-thread run. A backend with ``thread_determinism = False`` does not claim it: status
    "not claimed". Needs a backend with a count above 1 ("unavailable" otherwise) and one that
    is deterministic at one thread (if the one-thread run does not reproduce, this certificate
    cannot judge and is "unavailable"; the one-thread certificate fails instead)."""
    name = "determinism_across_threads"
    fig = REG.figure(name)
    if not getattr(backend, "thread_determinism", True):
        return PropertyResult(name, False, 0, float("nan"), fig,
                              f"{backend_name(backend)} declares thread_determinism = False: "
                              "results are not claimed identical across thread counts",
                              NOT_CLAIMED)
    counts = [int(t) for t in getattr(backend, "thread_counts", (1, 2)) if int(t) > 1]
    if not counts:
        return unavailable(name, f"{backend_name(backend)} runs one thread only (thread_counts "
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
            return unavailable(name, f"{backend_name(backend)} is not deterministic at one thread "
                                     "(two one-thread runs differ), so agreement across "
                                     "thread counts cannot be judged; see the one-thread "
                                     "determinism certificate")
    text = (f"{backend_name(backend)}: state hashes differ across thread counts: " +
            "; ".join(f"{k}: {v[:16]}" for k, v in hashes.items()) + f"\n{first_diff}")
    return _result(name, distinct == 1, distinct, fig, "max", text, hashes=hashes,
                   thread_counts=[1] + counts)


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


def dem_buffer_growth(backend, p: Pour, hints, max_overlap=0.1) -> PropertyResult:
    """The pour under capacity hints that force growth (``Simulation(capacity)`` with fewer
    particles than the pour has, a contact-capacity hint of a few contacts) gives the same
    trajectory as under ample hints (bit for bit; for an engine that does not reproduce its own
    ample run, within 4 x its run-to-run spread), the same contact counts (no contact lost),
    no crash, and no sphere pair overlapping by more than ``max_overlap`` of the smaller
    radius at any record (a dropped contact lets spheres sink into each other; peclet's
    tolerated overlap is 5e-4 of a radius). Figure: the number of hint pairs whose run differs
    (0 passes)."""
    name = "buffer_growth"
    fig = REG.figure(name)
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
    text = f"{backend_name(backend)}: " + "\n".join(lines)
    return _result(name, differing == 0, differing, fig, "max", text,
                   ample_contacts=ample["contacts"].astype(int).tolist(),
                   run_to_run_spread=spread)
