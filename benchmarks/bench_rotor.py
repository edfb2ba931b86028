"""Torque-free rotor benchmark: accuracy and cost of peclet.dem.rigid.advance_rotation.

Prints (and writes to benchmarks/results/rotor.json, atomically):
1. the Dzhanibekov flip period of an asymmetric body (moments 1, 2, 3; body omega
   (0.05, 10, 0.05)) against the Landau-Lifshitz closed form and a DOP853 solve, at
   dt = 4e-3 ... 5e-4, with the observed order of convergence;
2. conservation of world angular momentum, energy and |q| over 10 000 steps of dt = 5e-4;
3. the cost of the batch kernel advance_rotations per body at 1 and 2 threads.

Run:  python benchmarks/bench_rotor.py
"""
from __future__ import annotations

import math
import time
from pathlib import Path

import numba
import numpy as np

from peclet.core.geom import transforms
from peclet.dem import rigid
from peclet_verify.reference import rotor

IINV = np.array([1.0, 1.0 / 2.0, 1.0 / 3.0])
Q0 = transforms.quat_normalize(np.array([0.1, -0.2, 0.3, 0.9]))
OMEGA_BODY0 = np.array([0.05, 10.0, 0.05])
DTS = (4e-3, 2e-3, 1e-3, 5e-4)


def flip_period_table():
    L0 = OMEGA_BODY0 / IINV
    T_exact = rotor.free_rotor_period(IINV, L0)
    t_end = 3.3 * T_exact
    T_ivp = rotor.period_from_crossings(
        rotor.euler_reference_crossings(IINV, L0, t_end, component=1, direction=+1))
    w0 = transforms.quat_rotate(Q0, OMEGA_BODY0)
    rows = []
    for dt in DTS:
        n = int(round(t_end / dt))
        _, _, L = rotor.integrate_free_rotor(Q0, w0, IINV, dt, n)
        t = np.arange(n + 1) * dt
        dLdt = np.cross(L, IINV * L)
        ups = rotor.crossing_times(t, L[:, 1], dLdt[:, 1], direction=+1)
        T = rotor.period_from_crossings(ups)
        rows.append({"dt": dt, "steps": n, "crossings": int(ups.size), "period": T,
                     "rel_err_closed_form": (T - T_exact) / T_exact,
                     "rel_err_ivp": (T - T_ivp) / T_ivp})
    for a, b in zip(rows, rows[1:]):
        b["observed_order"] = math.log2(abs(a["rel_err_closed_form"]) / abs(b["rel_err_closed_form"]))
    return {"period_closed_form": T_exact, "period_dop853": T_ivp,
            "closed_form_vs_dop853": (T_ivp - T_exact) / T_exact, "rows": rows}


def conservation(dt=5e-4, n=10_000):
    w0 = transforms.quat_rotate(Q0, OMEGA_BODY0)
    quats, omegas, L_body = rotor.integrate_free_rotor(Q0, w0, IINV, dt, n)
    L0 = rigid.angular_momentum_world(Q0, w0, IINV)
    E0 = rigid.kinetic_energy_rot(Q0, w0, IINV)
    dL = max(np.linalg.norm(rigid.angular_momentum_world(q, w, IINV) - L0)
             for q, w in zip(quats, omegas)) / np.linalg.norm(L0)
    dE = max(abs(rigid.kinetic_energy_rot(q, w, IINV) - E0) for q, w in zip(quats, omegas)) / E0
    dM = np.abs(np.linalg.norm(L_body, axis=1) / np.linalg.norm(L_body[0]) - 1.0).max()
    dq = np.abs(np.linalg.norm(quats, axis=1) - 1.0).max()
    return {"dt": dt, "steps": n, "max_rel_world_L": float(dL), "max_rel_energy": float(dE),
            "max_rel_body_L_norm": float(dM), "max_abs_quat_norm_minus_1": float(dq)}


def batch_timing(n=200_000, steps=5, repeats=3):
    rng = np.random.default_rng(0)
    q0 = rng.normal(size=(n, 4))
    q0 /= np.linalg.norm(q0, axis=1)[:, None]
    w0 = rng.normal(scale=5.0, size=(n, 3))
    iinv = rng.uniform(0.2, 3.0, size=(n, 3))
    rigid.advance_rotations(q0.copy(), w0.copy(), iinv, 1e-4)  # compile outside the timing
    out = {}
    old = numba.get_num_threads()
    try:
        for threads in range(1, numba.config.NUMBA_NUM_THREADS + 1):
            numba.set_num_threads(threads)
            best = math.inf
            for _ in range(repeats):
                q, w = q0.copy(), w0.copy()
                t0 = time.perf_counter()
                for _ in range(steps):
                    rigid.advance_rotations(q, w, iinv, 1e-4)
                best = min(best, (time.perf_counter() - t0) / (steps * n))
            out[str(threads)] = best * 1e9
    finally:
        numba.set_num_threads(old)
    # Per-call cost of the scalar kernel from Python (dispatch + two small allocations).
    qs, ws = q0[0].copy(), w0[0].copy()
    rigid.advance_rotation(qs, ws, iinv[0], 1e-4)
    t0 = time.perf_counter()
    for _ in range(20_000):
        qs, ws = rigid.advance_rotation(qs, ws, iinv[0], 1e-4)
    scalar_us = (time.perf_counter() - t0) / 20_000 * 1e6
    return {"bodies": n, "ns_per_body_by_threads": out, "scalar_call_us_from_python": scalar_us}


def write_json_atomic(path: Path, data) -> None:
    from _report import write_json

    write_json(path, data)


def main():
    period = flip_period_table()
    cons = conservation()
    timing = batch_timing()
    print("Dzhanibekov flip: moments (1, 2, 3), body omega (0.05, 10, 0.05)")
    print(f"  closed form (L&L §37) period  {period['period_closed_form']:.12f}")
    print(f"  DOP853 rtol=atol=1e-12 period {period['period_dop853']:.12f}"
          f"   (rel diff {period['closed_form_vs_dop853']:.2e})")
    print(f"  {'dt':>8} {'steps':>6} {'period':>16} {'err vs closed':>14} {'err vs DOP853':>14}"
          f" {'order':>6}")
    for r in period["rows"]:
        order = f"{r['observed_order']:.3f}" if "observed_order" in r else ""
        print(f"  {r['dt']:8.1e} {r['steps']:6d} {r['period']:16.12f} "
              f"{r['rel_err_closed_form']:14.3e} {r['rel_err_ivp']:14.3e} {order:>6}")
    print(f"Conservation over {cons['steps']} steps of dt = {cons['dt']}:")
    print(f"  max rel |L_world - L0|  {cons['max_rel_world_L']:.2e}")
    print(f"  max rel |E - E0|        {cons['max_rel_energy']:.2e}")
    print(f"  max rel ||L_body|| - 1  {cons['max_rel_body_L_norm']:.2e}")
    print(f"  max | |q| - 1 |         {cons['max_abs_quat_norm_minus_1']:.2e}")
    print(f"Batch advance_rotations, {timing['bodies']} bodies:")
    for th, ns in timing["ns_per_body_by_threads"].items():
        print(f"  {th} thread(s): {ns:7.1f} ns per body per step")
    print(f"  scalar advance_rotation from Python: {timing['scalar_call_us_from_python']:.2f} us/call")
    out = Path(__file__).resolve().parent / "results" / "rotor.json"
    write_json_atomic(out, {"flip_period": period, "conservation": cons, "batch_timing": timing,
                            "numba_threads_cap": numba.config.NUMBA_NUM_THREADS})
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
