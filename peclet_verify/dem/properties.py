"""DEM certificates: determinism of peclet's own engine (:func:`determinism`, a pour; its
contact-buffer growth is :mod:`peclet_verify.dem.buffers`) and determinism and buffer growth
of any :class:`~peclet_verify.dem.backend.DemBackend` (:func:`determinism_one_thread`,
:func:`determinism_across_threads`, :func:`dem_buffer_growth`: a pour described as a
:class:`~peclet_verify.scenario.Scenario`).
"""
from __future__ import annotations

import hashlib
from typing import Callable, Optional

import numpy as np

from .. import registry as REG
from ..loading import backend_name
from ..scenario import STATE, trajectory_problem
from ..search import NOT_CLAIMED, PropertyResult, bad_answer, make_result, unavailable
from .strategies import Pour, pour_scenario

__all__ = ["state_hash", "reference_pour", "determinism", "run_checked", "trajectory_hash",
           "determinism_one_thread", "determinism_across_threads", "dem_buffer_growth",
           "first_difference", "cross_process"]


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
    return make_result(name, distinct == 1, distinct, fig, "max", text,
                   hashes=hashes, thread_counts=counts)


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


def first_difference(a, b, scenario) -> str:
    """Where two trajectories of ``scenario`` first differ (or that they do not)."""
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


def cross_process(backend) -> str:
    """How the determinism certificate compares ``backend`` across processes: ``"checked: 2
    fresh processes (...)"`` or ``"not checked: <why>"`` (see
    :func:`~peclet_verify.dem.backend.fresh_engines`, whose engines it starts if need be)."""
    from .backend import fresh_engines
    engines, why_not = fresh_engines(backend)
    if engines is None:
        return f"not checked: {backend_name(backend)} cannot be remade in a fresh process: " \
               f"{why_not}"
    return f"checked: {len(engines)} fresh processes ({backend_name(engines[0])})"


def determinism_one_thread(backend, p: Pour, fresh: bool = True) -> PropertyResult:
    """Two runs of the same pour at one thread give the same bytes (every recorded position,
    quaternion, velocity, angular velocity and contact count), and so does a run in each of
    two fresh processes (:func:`~peclet_verify.dem.backend.fresh_engines`): an engine seeded
    once per process (by its pid, or the time at import) is deterministic within a process
    and differs in the next. An engine that cannot be remade in a fresh process is judged on
    the runs in this process, and ``details["cross_process"]`` says why (so does the text).
    ``fresh=False`` skips the fresh processes. Figure: distinct trajectory hashes (1 passes)."""
    from .backend import fresh_engines
    name = "determinism_one_thread"
    fig = REG.figure(name)
    sc = pour_scenario(p)
    runs, labels = [], ["run 1", "run 2"]
    for _ in range(2):
        traj, why = run_checked(backend, sc, 1)
        if why:
            return bad_answer(name, fig, "max", why)
        runs.append(traj)
    cross = "not checked (fresh=False)"
    if fresh:
        engines, cross = fresh_engines(backend)[0], cross_process(backend)
        for k, engine in enumerate(engines or ()):
            traj, why = run_checked(engine, sc, 1)
            if why:
                return bad_answer(name, fig, "max", f"in fresh process {k + 1}: {why}")
            runs.append(traj)
            labels.append(f"fresh process {k + 1}")
    hashes = [trajectory_hash(t) for t in runs]
    distinct = len(set(hashes))
    odd = next((k for k, h in enumerate(hashes) if h != hashes[0]), 1)
    text = (f"{backend_name(backend)}: runs at 1 thread differ: " +
            ", ".join(f"{lab} {h[:16]}" for lab, h in zip(labels, hashes)) +
            f"; {labels[odd]} vs run 1: {first_difference(runs[0], runs[odd], sc)}; "
            f"across processes: {cross}")
    return make_result(name, distinct == 1, distinct, fig, "max", text, hashes=hashes,
                       cross_process=cross)


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
        return bad_answer(name, fig, "max", why)
    hashes = {"1 thread": trajectory_hash(base)}
    first_diff = None
    for t in counts:
        traj, why = run_checked(backend, sc, t)
        if why:
            return bad_answer(name, fig, "max", why)
        hashes[f"{t} threads"] = trajectory_hash(traj)
        if first_diff is None and hashes[f"{t} threads"] != hashes["1 thread"]:
            first_diff = f"{t} threads vs 1: {first_difference(base, traj, sc)}"
    distinct = len(set(hashes.values()))
    if distinct > 1:
        again, why = run_checked(backend, sc, 1)
        if why:
            return bad_answer(name, fig, "max", why)
        if trajectory_hash(again) != hashes["1 thread"]:
            return unavailable(name, f"{backend_name(backend)} is not deterministic at one thread "
                                     "(two one-thread runs differ), so agreement across "
                                     "thread counts cannot be judged; see the one-thread "
                                     "determinism certificate")
    text = (f"{backend_name(backend)}: state hashes differ across thread counts: " +
            "; ".join(f"{k}: {v[:16]}" for k, v in hashes.items()) + f"\n{first_diff}")
    return make_result(name, distinct == 1, distinct, fig, "max", text, hashes=hashes,
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
    (0 passes); ``details`` and the text tell a run that stopped with an error ("refused": the
    user is told) from one that ran on with contacts lost or spheres sunk ("silently wrong")."""
    name = "buffer_growth"
    fig = REG.figure(name)
    ample_sc = pour_scenario(p, capacity=4 * p.n, contact_capacity=64 * 8 * p.n)
    ample, why = run_checked(backend, ample_sc, 1)
    if why:
        return bad_answer(name, fig, "max", why)
    spread = None
    differing, lines = 0, []
    ov = _max_overlap(ample, p.radii)
    if ov > max_overlap:
        differing += 1
        lines.append(f"ample hints: spheres overlap by {ov:.3g} of a radius (> {max_overlap})")
    refused = silent = 0
    for cap, ccap in hints:
        sc = pour_scenario(p, capacity=cap, contact_capacity=ccap)
        traj, why = run_checked(backend, sc, 1)
        if why:
            # an engine that stops with an error refuses the capacity (the user knows); one
            # that runs on with contacts lost is silently wrong: the verdict says which
            differing += 1
            refused += 1
            lines.append(f"REFUSED (the run stopped with an error) at Simulation({cap}), "
                         f"contact capacity {ccap}: {why}")
            continue
        same = trajectory_hash(traj) == trajectory_hash(ample)
        if not same:
            if spread is None:
                again, why = run_checked(backend, ample_sc, 1)
                if why:
                    return bad_answer(name, fig, "max", why)
                spread = max(float(np.abs(again[k] - ample[k]).max()) for k in STATE)
            if spread > 0:
                worst = max(float(np.abs(traj[k] - ample[k]).max()) for k in STATE)
                same = worst <= 4.0 * spread and np.array_equal(traj["contacts"],
                                                                ample["contacts"])
        ov = _max_overlap(traj, p.radii)
        lost = int(np.sum(traj["contacts"] < ample["contacts"]))
        if not same or ov > max_overlap:
            differing += 1
            silent += 1
            lines.append(f"SILENTLY WRONG (it ran on) at Simulation({cap}), contact capacity "
                         f"{ccap}: "
                         f"{first_difference(traj, ample, sc)}; contact counts "
                         f"{traj['contacts'].astype(int).tolist()} vs ample "
                         f"{ample['contacts'].astype(int).tolist()} ({lost} record(s) with "
                         f"fewer contacts); worst overlap {ov:.3g} of a radius")
    text = f"{backend_name(backend)}: " + "\n".join(lines)
    return make_result(name, differing == 0, differing, fig, "max", text,
                       ample_contacts=ample["contacts"].astype(int).tolist(),
                       run_to_run_spread=spread, refused=refused, silently_wrong=silent)
