"""Haff's law: the homogeneous cooling of inelastic spheres (issue 23, item 5).

Protocol. N smooth (mu = 0) spheres of diameter sigma = 1 and mass m = pi/6 (density 1) at
random, non-overlapping positions in a periodic cube at solid fraction phi (default 0.1),
Maxwellian velocities with granular temperature T0 = m <v_x^2> = m (thermal speed 1), no drift,
no gravity, normal restitution e = 0.9, dt = 2e-3 (about 200 steps per mean free time), the
impulse engine. Every ``sample`` steps the temperature T = m <|v - <v>|^2> / 3.

Kinetic theory (Haff 1983; the Enskog collision rate with a Maxwellian, as in Brilliantov &
Poeschel, "Kinetic Theory of Granular Gases", 2004, ch. 7, without the Sonine correction):
the energy lost per collision of normal approach speed g_n is (m/4)(1 - e^2) g_n^2, so

    dT/dt = -A T^(3/2),   A = (4/3) sqrt(pi) n sigma^2 chi (1 - e^2) / sqrt(m),

with n the number density and chi = (1 - phi/2) / (1 - phi)^3 the contact value of the pair
correlation (Carnahan-Starling). Hence T(t) = T0 / (1 + t/t0)^2 with

    t0 = 2 / (A sqrt(T0)).

The fit: least squares of ln T against ln(T0 / (1 + t/t0)^2) over t0 (T0 the measured start)
up to ``--t-end`` (in units of the predicted t0; later the cooling gas clusters and the
homogeneous law no longer holds). Printed: the fitted t0 beside kinetic theory, and T(t)
against the law at a few times.

Run:  python validation/haff.py [--count 2000] [--phi 0.1] [--t-end 2] [--json out.json]
"""
from __future__ import annotations

import math
import os
import sys

import numpy as np
from scipy.optimize import minimize_scalar

from peclet.dem import Simulation

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:           # run as a script: the repository, for the package below
    sys.path.insert(0, ROOT)

import validation as vargs  # noqa: E402  (the scripts' shared argument handling)

SIGMA = 1.0
MASS = math.pi / 6.0


def predicted_t0(phi, e, T0, sigma=SIGMA, m=MASS):
    """Haff's t0 (time) from the Enskog rate (see the module notes)."""
    n = phi / (math.pi / 6.0 * sigma ** 3)
    chi = (1.0 - 0.5 * phi) / (1.0 - phi) ** 3
    A = 4.0 / 3.0 * math.sqrt(math.pi) * n * sigma ** 2 * chi * (1.0 - e * e) / math.sqrt(m)
    return 2.0 / (A * math.sqrt(T0))


def temperature(v, m=MASS):
    dv = v - v.mean(axis=0)
    return m * float((dv * dv).sum()) / (3.0 * len(v))


def gas(count, phi, e, seed, dt=2e-3):
    """The Simulation of the start state (see the module notes); returns (sim, L)."""
    rng = np.random.default_rng(seed)
    L = (count * math.pi / 6.0 / phi) ** (1.0 / 3.0)
    sim = Simulation(count)
    sim.set_domain([0.0] * 3, [L] * 3)
    sim.enable_periodicity(True, True, True)
    sim.set_gravity(0.0, 0.0, 0.0)
    sim.set_material_params(e, 0.0, 0.0)
    sim.add_sphere_shape(0.5 * SIGMA)
    # a jittered cubic lattice (no overlaps at phi <= 0.3), shuffled velocities
    k = int(math.ceil(count ** (1.0 / 3.0)))
    g = (np.arange(k) + 0.5) * (L / k)
    X, Y, Z = np.meshgrid(g, g, g, indexing="ij")
    P = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])[rng.permutation(k ** 3)[:count]]
    P += rng.uniform(-0.2, 0.2, P.shape) * (L / k - SIGMA)
    sim.set_positions(P % L)
    sim.set_shape_ids(np.zeros(count, np.int64))
    sim.set_inv_mass(np.full(count, 1.0 / MASS))
    sim.set_inv_inertia(np.full((count, 3), 1.0 / (0.1 * MASS * SIGMA ** 2)))
    v = rng.normal(size=(count, 3)) / math.sqrt(MASS)   # m <v_x^2> = 1
    v -= v.mean(axis=0)
    sim.set_velocities(v)
    sim.set_dt(dt)
    return sim, L


def run(count=2000, phi=0.1, e=0.9, t_end=2.0, seed=1, sample=50, dt=2e-3, progress=True):
    """Cool the gas to ``t_end`` predicted t0; returns a dict (times, temperatures, the
    predicted and fitted t0)."""
    sim, _ = gas(count, phi, e, seed, dt)
    T0 = temperature(sim.get_velocities())
    t0 = predicted_t0(phi, e, T0)
    steps = int(math.ceil(t_end * t0 / dt))
    ts, Ts = [0.0], [T0]
    it = range(steps)
    if progress:
        from tqdm import tqdm
        it = tqdm(it, desc="haff", unit="step")
    for k in it:
        sim.step()
        if (k + 1) % sample == 0:
            ts.append((k + 1) * dt)
            Ts.append(temperature(sim.get_velocities()))
    t, T = np.array(ts), np.array(Ts)

    def resid(tau):
        return float(np.sum((np.log(T) - np.log(T0 / (1.0 + t / tau) ** 2)) ** 2))

    fit = minimize_scalar(resid, bounds=(0.1 * t0, 10.0 * t0), method="bounded",
                          options={"xatol": 1e-6 * t0})
    return dict(count=count, phi=phi, e=e, T0=T0, t0_theory=t0, t0_fit=float(fit.x),
                rel_error=float(fit.x / t0 - 1.0), times=t.tolist(), temperatures=T.tolist(),
                steps=steps, dt=dt, state_hash=sim.state_hash())


def main(argv=None):
    ap = vargs.ScriptParser(description=__doc__.splitlines()[0])
    # count >= 100 and phi <= 0.3: the start lattice has no overlaps (from 72 spheres on)
    ap.add_argument("--count", type=vargs.integer(100, 1_000_000), default=2000,
                    help="spheres, in [100, 1000000] (default 2000)")
    ap.add_argument("--phi", type=vargs.real(0.0, 0.3, lo_open=True), default=0.1,
                    help="solid fraction in (0, 0.3] (default 0.1)")
    ap.add_argument("--e", type=vargs.real(0.0, 1.0, hi_open=True), default=0.9,
                    help="restitution in [0, 1) (1: no cooling; default 0.9)")
    ap.add_argument("--t-end", type=vargs.real(0.0, 100.0, lo_open=True), default=2.0,
                    help="run time in predicted t0, in (0, 100] (default 2)")
    ap.add_argument("--seed", type=vargs.integer(0, 2 ** 63 - 1), default=1,
                    help="generator seed >= 0 (default 1)")
    ap.add_argument("--json", type=vargs.output_file, default=None,
                    help="write the results here (a file in an existing directory)")
    a = ap.parse_args(argv)
    r = run(a.count, a.phi, a.e, a.t_end, a.seed)
    print(f"Haff's law, {r['count']} spheres, phi {r['phi']}, e {r['e']}, T0 {r['T0']:.4f}, "
          f"{r['steps']} steps of {r['dt']}")
    print(f"t0 kinetic theory (Enskog, Carnahan-Starling chi)  {r['t0_theory']:.4f}")
    print(f"t0 fitted to T(t) = T0 / (1 + t/t0)^2               {r['t0_fit']:.4f}  "
          f"({100 * r['rel_error']:+.2f} %)")
    print("t / t0_theory | T / T0 measured | Haff (theory t0)")
    t, T = np.array(r["times"]), np.array(r["temperatures"])
    for f in (0.25, 0.5, 1.0, 1.5, 2.0):
        if f * r["t0_theory"] <= t[-1]:
            i = int(np.argmin(np.abs(t - f * r["t0_theory"])))
            print(f"{t[i] / r['t0_theory']:13.3f} | {T[i] / r['T0']:15.4f} | "
                  f"{1.0 / (1.0 + t[i] / r['t0_theory']) ** 2:.4f}")
    if a.json:
        from peclet.core.files import write_json
        write_json(a.json, r)
    return 0


if __name__ == "__main__":
    sys.exit(vargs.run(main))
