"""The DEM sanity scorecard: small closed-form cases, each printed as ours beside the expected.

    python validation/sanity.py [--json validation/results/sanity.json] [--threads 1]

Units: SI-like (metres, seconds, kg), g = 9.81 m/s^2 along -y, the floor's top face at y = 0.
Spheres have unit mass and the inertia of a uniform solid sphere (2/5 m r^2) unless stated.
The engine's conventions (peclet/dem/solver.py): impulse-based, Newton restitution ``e`` on
colliding contacts (approach faster than the resting threshold 2 |g| dt), the Coulomb cone
``|lambda_t| <= mu lambda_n``, Walton tangential restitution ``e_t`` (0 here: a colliding
contact's slip is driven to 0 inside the cone), gaps below the slop (5e-4 x the smallest
bounding radius) count as touching and overlaps up to the slop are left alone. A wall contact
takes the wall's ``e`` and ``mu``, a sphere-sphere contact the body material.

Items (protocol, closed form; the tolerance of each row and why it is what it is is printed and
stored with it):

1. Binary restitution: two spheres (r 0.5 / 0.3, m 1 / 0.4, +2 / -1.5 m/s) head-on, no gravity,
   e = 0, 0.25, 0.5, 0.75, 1: separation / approach speed = e.
2. Drop bounce: a sphere (r 0.5) released at rest 1 m above a box wall (a plane) and above a
   CSG floor (two slabs united, minus a notch away from the impact: top face flat), e = 0.5 and
   0.9: first rebound apex / drop height = e^2. Plus a phase sweep: the same drop from 8
   heights 1 + k |v| dt / 8 (the impact's phase within the step), the worst ratio.
3. Slide to roll: a solid sphere launched sliding (v0 = 3 m/s, omega 0) on a floor with
   mu = 0.2, 0.5: it rolls at v = 5/7 v0 from t = 2 v0 / (7 mu g).
4. Static column: 6 spheres (d 1) stacked touching on the floor, 1 s: no centre moves (drift),
   spacing = d (no sinking), at rest.
5. Spin with friction: (a) topspin omega0 r = 3 m/s set down at v = 0: rolls at 2/7 omega0 r
   from t = 2 omega0 r / (7 mu g); (b) a draw shot v0 = 1 m/s with backspin omega0 r = 5 m/s:
   returns at (5 v0 - 2 omega0 r) / 7 = -5/7 m/s; (c) spin about the vertical: the contact is
   a point on the spin axis, which has no velocity, and the model has no torsional (spinning)
   friction, so omega stays omega0 and the centre does not move.
6. Deep bed: 5 x 5 x 40 spheres of diameter 2 on a square lattice (pitch 2) inside 4 snug box
   walls (touching the lattice) on a floor, 1 s: at rest, layer spacing 2, bottom centres at 1,
   top centres at 79 (40 layers x 2 - 1: the top does not sink), no lateral drift.
7. Incline: a cube (side 1, a box-leaf CSG particle through ``peclet.dem.scene_particle``) on a
   plane (a box wall) inclined at 20 deg (tan = 0.364), released at rest, 1 s: it sticks for
   mu = 0.5, 0.4 (tan < mu: no creep after 0.1 s, and a total slip below the free slide of the
   first 3 steps, where the friction starts cold) and slides for mu = 0.33, 0.2 (tan > mu),
   with the kinetic acceleration a = g (sin theta - mu cos theta) (fitted over t >= 0.1 s).

Writes ``validation/results/sanity.json`` (atomically) unless ``--json`` names another file.
Run single-threaded by default (the engine's state is bitwise the same at any thread count;
these cases are too small to gain from threads on a shared machine).
"""
from __future__ import annotations

import math
import os
import sys
import time
from contextlib import contextmanager

import numpy as np

from peclet.core import geom
from peclet.core.files import write_json
from peclet.core.geom.transforms import matrix_to_quat
from peclet.dem import Simulation, scene_particle

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:           # run as a script: the repository, for the package below
    sys.path.insert(0, ROOT)

import validation as vargs  # noqa: E402  (the scripts' shared argument handling)

G = 9.81
#: The engine's default solver sweeps (position, velocity), used by every case.
ITERS = (10, 8)
#: The engine's slop: gaps below this fraction of the smallest bounding radius count as
#: touching, and overlaps up to it are tolerated (peclet.dem.simulation.SLOP_FRACTION).
SLOP_FRACTION = 5e-4
HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_JSON = os.path.join(HERE, "results", "sanity.json")


# ---------------------------------------------------------------------------------- helpers
def row(item, case, protocol, expected, ours, tol, basis, error=None, unit="", **extra):
    """One line of the scorecard; ``error`` defaults to |ours - expected|."""
    ours = float(ours)
    expected = float(expected)
    err = abs(ours - expected) if error is None else float(error)
    return dict(item=item, case=case, protocol=protocol, expected=expected, ours=ours,
                error=err, tol=float(tol), passed=bool(err <= tol), unit=unit,
                tol_basis=basis, **extra)


def proto(mu=None, e=None, dt=None, extra=""):
    parts = []
    if mu is not None:
        parts.append(f"mu={mu:g}")
    if e is not None:
        parts.append(f"e={e:g}")
    if dt is not None:
        parts.append(f"dt={dt:g}")
    parts.append(f"it={ITERS[0]}/{ITERS[1]}")
    if extra:
        parts.append(extra)
    return " ".join(parts)


def new_sim(gravity=True):
    sim = Simulation(1)
    sim.set_solver_iterations(*ITERS)
    if gravity:
        sim.set_gravity(0.0, -G, 0.0)
    return sim


def box_wall(sim, half, centre, rotation=None, e=0.5, mu=0.5):
    """A solid box wall (half-extents ``half`` at ``centre``, optional quaternion)."""
    b = geom.SceneBuilder()
    r = b.add_leaf("box", list(half), translation=list(centre), rotation=rotation)
    ni, nr, _, _ = b.encode()
    return sim.add_analytic_wall(ni, nr, r, False, e, mu)


def floor(sim, e, mu, half=50.0):
    """The plane y = 0: the top face of a box 2 m thick."""
    return box_wall(sim, (half, 1.0, half), (0.0, -1.0, 0.0), e=e, mu=mu)


def csg_floor(sim, e, mu):
    """A CSG floor with a flat top at y = 0: two slabs (x < 0.3 and x > 0.3) united, minus a
    notch cut into the top at x = 6 (far from the impact at x = 0)."""
    b = geom.SceneBuilder()
    left = b.add_leaf("box", [10.0, 1.0, 20.0], translation=[-9.7, -1.0, 0.0])
    right = b.add_leaf("box", [10.0, 1.0, 20.0], translation=[10.3, -1.0, 0.0])
    notch = b.add_leaf("box", [0.5, 0.5, 20.0], translation=[6.0, 0.0, 0.0])
    root = b.add_difference(b.add_union(left, right), notch)
    ni, nr, _, _ = b.encode()
    return sim.add_analytic_wall(ni, nr, root, False, e, mu)


def one_sphere(sim, r, pos, vel=(0, 0, 0), omega=(0, 0, 0)):
    sim.add_sphere_shape(r)
    sim.set_positions([pos])
    sim.set_shape_ids([0])
    sim.set_inv_mass([1.0])
    sim.set_inv_inertia([[2.5 / r ** 2] * 3])      # solid sphere, unit mass
    sim.set_velocities([vel])
    sim.set_angular_velocities([omega])


@contextmanager
def numba_threads(n):
    """Run with ``n`` Numba threads (None: leave as is); restores the previous count."""
    if n is None:
        yield
        return
    import numba
    old = numba.get_num_threads()
    numba.set_num_threads(min(int(n), numba.config.NUMBA_NUM_THREADS))
    try:
        yield
    finally:
        numba.set_num_threads(old)


# ---------------------------------------------------------------------------------- 1
def binary_restitution(e, dt=1e-3, steps=200):
    """Two spheres head-on without gravity; returns (separation / approach, momentum error)."""
    sim = new_sim(gravity=False)
    sim.set_material_params(e, 0.0, 0.5)
    sim.add_sphere_shape(0.5)
    sim.add_sphere_shape(0.3)
    sim.set_positions([[0.0, 0.0, 0.0], [1.2, 0.0, 0.0]])
    sim.set_shape_ids([0, 1])
    sim.set_inv_mass([1.0, 2.5])
    v0 = np.array([[2.0, 0.0, 0.0], [-1.5, 0.0, 0.0]])
    sim.set_velocities(v0)
    m = np.array([1.0, 0.4])
    for _ in range(steps):                          # contact after ~ (1.2 - 0.8) / 3.5 s
        sim.step(dt)
    v = sim.get_velocities()
    ratio = (v[1, 0] - v[0, 0]) / (v0[0, 0] - v0[1, 0])
    dp = float(np.abs((m[:, None] * (v - v0)).sum(axis=0)).max())
    return float(ratio), dp


def item_binary(es=(0.0, 0.25, 0.5, 0.75, 1.0)):
    rows = []
    for e in es:
        ratio, dp = binary_restitution(e)
        rows.append(row(1, f"binary restitution e={e:g}", proto(0.5, e, 1e-3, "no g"), e,
                        ratio, 1e-6, "one two-body contact: the impulse solve is exact; "
                        "1e-6 leaves room for round-off only", momentum_error=dp))
    return rows


# ---------------------------------------------------------------------------------- 2
def drop_apex(e, h0=1.0, r=0.5, dt=2e-4, surface="plane", mu=0.5):
    """Release a sphere ``h0`` above the floor (bottom to top face); returns
    (first apex / h0, rebound / impact speed, gap at the rebound step, impact speed)."""
    sim = new_sim()
    one_sphere(sim, r, (0.0, r + h0, 0.0))
    (floor if surface == "plane" else csg_floor)(sim, e, mu)
    apex, t_max = None, 2.0 * math.sqrt(2 * h0 / G) * (1 + e) + 0.1
    v_in, v_out, gap_at = 0.0, None, None
    for _ in range(int(t_max / dt)):
        vy_before = float(sim.get_velocities()[0, 1])
        sim.step(dt)
        vy = float(sim.get_velocities()[0, 1])
        y = float(sim.get_positions()[0, 1]) - r
        if v_out is None:
            if vy > 0.0:
                v_out, gap_at, v_in = vy, y - vy * dt, -vy_before
                apex = y
        else:
            apex = max(apex, y)
            if vy < 0.0:
                break
    if v_out is None:
        return 0.0, 0.0, float("nan"), 0.0
    v_drop = math.sqrt(2 * G * h0)
    return apex / h0, v_out / v_drop, gap_at, v_in


def drop_tolerance(h0, dt):
    # the impact is resolved within one step's travel |v| dt of the surface (the speculative
    # contact stops the sphere short of it), and the semi-implicit Euler apex is within half a
    # step's travel on the way up and down: |ratio - e^2| <= 2 |v| dt / h0, |v| = sqrt(2 g h0)
    return 2.0 * math.sqrt(2 * G * h0) * dt / h0


def item_drop(es=(0.5, 0.9), surfaces=("plane", "csg"), h0=1.0, dt=2e-4, phases=8,
              phase_e=0.7):
    rows = []
    tol = drop_tolerance(h0, dt)
    basis = ("the impact happens within one step's travel |v| dt of the floor and the "
             "discrete apex within |v| dt / 2 twice: tol = 2 |v| dt / h0")
    for surface in surfaces:
        for e in es:
            ratio, vr, gap, vin = drop_apex(e, h0, dt=dt, surface=surface)
            name = "plane (box wall)" if surface == "plane" else "CSG floor (union - notch)"
            rows.append(row(2, f"drop on {name} e={e:g}", proto(0.5, e, dt, f"h0={h0:g}"),
                            e * e, ratio, tol, basis, speed_ratio=vr, rebound_gap=gap))
    if phases:
        vdt = math.sqrt(2 * G * h0) * dt
        worst, all_ratios = None, []
        for k in range(phases):
            hk = h0 + k * vdt / phases
            ratio, vr, gap, vin = drop_apex(phase_e, hk, dt=dt, surface="plane")
            all_ratios.append(ratio)
            if worst is None or abs(ratio - phase_e ** 2) > abs(worst[0] - phase_e ** 2):
                worst = (ratio, hk, vr)
        ok = sum(abs(x - phase_e ** 2) <= tol for x in all_ratios)
        rows.append(row(2, f"drop on plane e={phase_e:g}, worst of {phases} impact phases "
                        f"({ok}/{phases} within tol)",
                        proto(0.5, phase_e, dt, f"h0={h0:g}+k|v|dt/{phases}"), phase_e ** 2,
                        worst[0], tol, basis, worst_h0=worst[1], ratios=all_ratios,
                        phases_within_tol=ok))
    return rows


# ---------------------------------------------------------------------------------- 3, 5
def roll_out(v0, w0, mu, r=0.5, dt=1e-3, t_end=None):
    """A solid sphere resting on the floor with centre velocity (v0, 0, 0) and angular
    velocity ``w0`` (3,); runs until ``t_end``. Returns (final v (3,), final omega (3,),
    time at which the slip (contact-point speed) first fell below 1e-9 m/s or None, final
    position (3,))."""
    sim = new_sim()
    one_sphere(sim, r, (0.0, r, 0.0), (v0, 0.0, 0.0), w0)
    floor(sim, 0.0, mu, half=100.0)
    t_roll = None
    for k in range(int(round(t_end / dt))):
        sim.step(dt)
        if t_roll is None:
            v = sim.get_velocities()[0]
            w = sim.get_angular_velocities()[0]
            slip = v + np.cross(w, [0.0, -r, 0.0])
            if np.linalg.norm(slip[[0, 2]]) < 1e-9:
                t_roll = (k + 1) * dt
    return (sim.get_velocities()[0], sim.get_angular_velocities()[0], t_roll,
            sim.get_positions()[0])


def _roll_rows(item, label, v0, w0r, mu, r=0.5, dt=1e-3):
    """Rows for a sphere on the floor with v0 forward and w0r = omega0 r of topspin (> 0:
    spinning the way it would roll forward)."""
    vf = (5.0 * v0 + 2.0 * w0r) / 7.0
    t_star = 2.0 * abs(v0 - w0r) / (7.0 * mu * G)  # slip |v - omega r| decays at 7/2 mu g
    w0 = (0.0, 0.0, -w0r / r)
    v, w, t_roll, x = roll_out(v0, w0, mu, r, dt, t_end=t_star + 0.3)
    p = proto(mu, 0.0, dt)
    rows = [row(item, f"{label}: final v", p, vf, v[0], 1e-9 * max(1.0, abs(v0), abs(w0r)),
                "while sliding the friction impulse is exactly mu m g dt per step, and the "
                "step that stops the slip lands on v = omega r: exact to round-off", unit="m/s",
                omega_r=float(-w[2] * r), height_error=float(x[1] - r)),
            row(item, f"{label}: roll from t", p, t_star,
                t_roll if t_roll is not None else float("inf"), dt,
                "the slip stops within the step that crosses t*: one dt", unit="s")]
    return rows


def item_slide_to_roll(mus=(0.2, 0.5), v0=3.0):
    rows = []
    for mu in mus:
        rows += _roll_rows(3, f"slide to roll v0={v0:g} mu={mu:g}", v0, 0.0, mu)
    return rows


def spin_vertical(w0=20.0, mu=0.5, r=0.5, dt=1e-3, t_end=1.0):
    v, w, _, x = roll_out(0.0, (0.0, w0, 0.0), mu, r, dt, t_end)
    return float(w[1]), float(np.linalg.norm(x[[0, 2]])), float(np.linalg.norm(v))


def item_spin(mu=0.5):
    rows = _roll_rows(5, "topspin w0r=3 set down", 0.0, 3.0, mu)
    rows += _roll_rows(5, "draw shot v0=1 backspin w0r=5", 1.0, -5.0, mu)
    w, drift, speed = spin_vertical(mu=mu)
    rows.append(row(5, "vertical spin w0=20: omega after 1 s", proto(mu, 0.0, 1e-3), 20.0, w,
                    1e-9, "the contact point lies on the spin axis (no slip) and the model has "
                    "no torsional friction: omega is untouched", unit="rad/s",
                    drift=drift, speed=speed))
    rows.append(row(5, "vertical spin w0=20: centre drift", proto(mu, 0.0, 1e-3), 0.0, drift,
                    1e-9, "no tangential slip, hence no friction impulse: no motion",
                    unit="m"))
    return rows


# ---------------------------------------------------------------------------------- 4
def column(n=6, r=0.5, e=0.5, mu=0.3, dt=1e-3, steps=1000):
    """``n`` spheres stacked touching on the floor; returns positions before and after, and
    the final max speed."""
    sim = new_sim()
    sim.add_sphere_shape(r)
    x0 = np.array([[0.0, r + 2 * r * k, 0.0] for k in range(n)])
    sim.set_positions(x0)
    sim.set_shape_ids(np.zeros(n, int))
    sim.set_material_params(e, 0.0, mu)
    floor(sim, e, mu)
    for _ in range(steps):
        sim.step(dt)
    return x0, sim.get_positions(), float(np.abs(sim.get_velocities()).max())


def item_column(n=6, r=0.5, e=0.5, mu=0.3, dt=1e-3, steps=1000):
    x0, x, vmax = column(n, r, e, mu, dt, steps)
    slop = SLOP_FRACTION * r
    p = proto(mu, e, dt, f"{steps} steps")
    drift = np.linalg.norm(x - x0, axis=1)
    spacing = np.diff(x[:, 1])
    return [
        row(4, f"column of {n}: max centre drift", p, 0.0, drift.max(), n * slop,
            f"each of the {n} contacts may settle into the tolerated overlap (the slop, "
            f"{SLOP_FRACTION:g} r): tol = {n} slop", unit="m"),
        row(4, f"column of {n}: max |spacing - d|", p, 2 * r, spacing[
            np.argmax(np.abs(spacing - 2 * r))], slop, "at most one slop per contact",
            unit="m"),
        row(4, f"column of {n}: lateral drift", p, 0.0, np.abs(x[:, [0, 2]]).max(), 1e-12,
            "an exactly vertical stack has no lateral force: round-off only", unit="m"),
        row(4, f"column of {n}: max speed at 1 s", p, 0.0, vmax, 0.1 * G * dt,
            "at rest: below a tenth of one step's gravity increment g dt", unit="m/s"),
    ]


# ---------------------------------------------------------------------------------- 6
def deep_bed(nx=5, ny=40, d=2.0, e=0.3, mu=0.3, dt=1e-3, steps=1000):
    """``nx`` x ``nx`` x ``ny`` spheres of diameter ``d`` on a square lattice (pitch d) in
    four snug box walls (faces at 0 and nx d) on the floor. Returns (initial positions,
    final positions (layer-major: ny x nx^2 x 3), max speed, kinetic energy per sphere)."""
    r = 0.5 * d
    sim = new_sim()
    sim.add_sphere_shape(r)
    X, Y, Z = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nx), indexing="ij")
    order = np.argsort(Y.ravel(), kind="stable")   # bottom layer first
    P = (np.column_stack([X.ravel(), Y.ravel(), Z.ravel()]) * d + r)[order]
    sim.set_positions(P)
    sim.set_shape_ids(np.zeros(len(P), int))
    sim.set_material_params(e, 0.0, mu)
    w, hgt = nx * d, ny * d + 10.0
    floor(sim, e, mu)
    for c in ((-1.0, 0.0), (w + 1.0, 0.0)):           # faces at x = 0 and x = w
        box_wall(sim, (1.0, hgt / 2, w / 2 + 2), (c[0], hgt / 2, w / 2), e=e, mu=mu)
    for c in (-1.0, w + 1.0):                        # faces at z = 0 and z = w
        box_wall(sim, (w / 2 + 2, hgt / 2, 1.0), (w / 2, hgt / 2, c), e=e, mu=mu)
    for _ in range(steps):
        sim.step(dt)
    v = sim.get_velocities()
    ke = 0.5 * float((v ** 2).sum()) / len(P)       # unit masses; rotation adds ~0
    return P, sim.get_positions(), float(np.abs(v).max()), ke


def item_deep_bed(nx=5, ny=40, d=2.0, e=0.3, mu=0.3, dt=1e-3, steps=1000):
    P, x, vmax, ke = deep_bed(nx, ny, d, e, mu, dt, steps)
    r = 0.5 * d
    slop = SLOP_FRACTION * r
    y = x[:, 1].reshape(ny, nx * nx)
    p = proto(mu, e, dt, f"{steps} steps")
    sp = np.diff(y, axis=0)
    worst = sp.ravel()[np.argmax(np.abs(sp - d))]
    top = y[-1]
    top_worst = top[np.argmax(np.abs(top - (ny * d - r)))]
    lat = np.abs(x[:, [0, 2]] - P[:, [0, 2]]).max()
    size = f"{nx}x{nx}x{ny} d={d:g}"
    return [
        row(6, f"deep bed {size}: max |layer spacing - d|", p, d, worst, slop,
            "at most one slop (tolerated overlap) per contact", unit="m"),
        row(6, f"deep bed {size}: bottom centres", p, r, y[0][np.argmax(np.abs(y[0] - r))],
            slop, "one wall contact: one slop", unit="m"),
        row(6, f"deep bed {size}: top centres (no sinking)", p, ny * d - r, top_worst,
            ny * slop, f"{ny} contacts below the top layer, at most a slop each", unit="m"),
        row(6, f"deep bed {size}: lateral drift", p, 0.0, lat, slop,
            "snug lattice, vertical contacts only: below one slop", unit="m"),
        row(6, f"deep bed {size}: max speed at the end", p, 0.0, vmax, 0.1 * G * dt,
            "at rest: below a tenth of one step's gravity increment g dt", unit="m/s",
            kinetic_energy_per_sphere=ke),
    ]


# ---------------------------------------------------------------------------------- 7
_CUBE = {}


def cube_particle(half=0.5):
    """A cube of side 2 ``half`` as a CSG particle (one box leaf) through scene_particle
    (measured mass properties, principal frame, marching-cubes shell probes); cached."""
    if half not in _CUBE:
        b = geom.SceneBuilder()
        c = b.add_leaf("box", [half] * 3)
        lo, hi = [-1.2 * half] * 3, [1.2 * half] * 3
        _CUBE[half] = scene_particle.build(b, c, bounds=(lo, hi), n=16, shell_resolution=48,
                                           target_shell_points=600)
    return _CUBE[half]


def incline(mu, theta_deg=20.0, t_end=1.0, dt=1e-3, half=0.5):
    """A cube resting on a plane inclined at ``theta_deg`` (slope descending towards -x), wall
    and body friction ``mu``, e = 0. Returns (times (k,), displacement down the slope (k,),
    max |omega| over the run)."""
    th = math.radians(theta_deg)
    sp = cube_particle(half)
    sim = new_sim()
    sid = sp.register(sim)
    c, s = math.cos(th), math.sin(th)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    q = matrix_to_quat(R)
    box_wall(sim, (20.0, 1.0, 20.0), R @ [0.0, -1.0, 0.0], rotation=q, e=0.0, mu=mu)
    Rb = R @ geom.quat_to_matrix(sp.quat)           # home -> world: incline o authoring
    x0 = R @ (np.array([0.0, half, 0.0]) + sp.com)
    sim.set_positions([x0])
    sim.set_shape_ids([sid])
    sim.set_quaternions([matrix_to_quat(Rb)])
    sim.set_inv_mass([1.0 / sp.mass])
    sim.set_inv_inertia([sp.inv_inertia_unit])
    sim.set_material_params(0.0, 0.0, mu)
    down = R @ np.array([-1.0, 0.0, 0.0])
    ts, ds, wmax = [], [], 0.0
    for k in range(int(round(t_end / dt))):
        sim.step(dt)
        ts.append((k + 1) * dt)
        ds.append(float((sim.get_positions()[0] - x0) @ down))
        wmax = max(wmax, float(np.abs(sim.get_angular_velocities()).max()))
    return np.array(ts), np.array(ds), wmax


def slide_acceleration(ts, ds, t_from=0.1):
    """Least-squares a of d = d0 + v0 t + a t^2 / 2 over t >= t_from."""
    m = ts >= t_from
    A = np.column_stack([np.ones(m.sum()), ts[m], 0.5 * ts[m] ** 2])
    return float(np.linalg.lstsq(A, ds[m], rcond=None)[0][2])


def item_incline(theta_deg=20.0, sticks=(0.5, 0.4), slides=(0.33, 0.2), dt=1e-3, t_end=1.0,
                 settle=0.1):
    rows = []
    th = math.radians(theta_deg)
    tan = f"tan={math.tan(th):.3f}"
    # the PGS starts cold (no warm start at first contact), so the friction of the 4-point
    # manifold converges over the first few steps: allow the free-slide distance of 3 steps
    slip_tol = 0.5 * G * math.sin(th) * (3 * dt) ** 2
    for mu in sticks:
        ts, ds, wmax = incline(mu, theta_deg, t_end, dt)
        k = int(np.searchsorted(ts, settle - 1e-12))
        p = proto(mu, 0.0, dt, "cube")
        rows.append(row(7, f"incline {theta_deg:g} deg, {tan} < mu={mu:g}: sticks, creep "
                        f"{settle:g}-{t_end:g} s", p, 0.0, ds[-1] - ds[k], 1e-9,
                        "static friction inside the cone, warm-started, holds exactly: "
                        "round-off only", unit="m", max_omega=wmax))
        rows.append(row(7, f"incline {theta_deg:g} deg, {tan} < mu={mu:g}: total slip",
                        p, 0.0, ds[-1], slip_tol, "cold start of the friction (no warm start "
                        "in the first step): at most the free slide of 3 steps, "
                        "g sin(theta) (3 dt)^2 / 2", unit="m"))
    for mu in slides:
        ts, ds, wmax = incline(mu, theta_deg, t_end, dt)
        a_exp = G * (math.sin(th) - mu * math.cos(th))
        a = slide_acceleration(ts, ds, settle)
        rows.append(row(7, f"incline {theta_deg:g} deg, {tan} > mu={mu:g}: slides, "
                        "a = g(sin - mu cos)", proto(mu, 0.0, dt, "cube"), a_exp, a,
                        1e-6 * a_exp, "kinetic friction is exactly mu lambda_n per step and "
                        f"the fit (t >= {settle:g} s) is exact for constant a: round-off and "
                        "settling only, 1e-6 relative", unit="m/s^2", slid=float(ds[-1]),
                        max_omega=wmax))
    return rows


# ---------------------------------------------------------------------------------- main
ITEMS = [("binary restitution", item_binary), ("drop bounce", item_drop),
         ("slide to roll", item_slide_to_roll), ("static column", item_column),
         ("spin with friction", item_spin), ("deep bed", item_deep_bed),
         ("incline stick/slip + kinetic slide", item_incline)]


def _fmt(x):
    if x == 0.0:
        return "0"
    if not math.isfinite(x):
        return str(x)
    if abs(x) >= 1e-3 and abs(x) < 1e4:
        return f"{x:.6g}"
    return f"{x:.3e}"


def table(rows):
    head = ("#", "case", "protocol", "expected", "ours", "error", "tol", "verdict")
    body = [(str(r["item"]), r["case"], r["protocol"], _fmt(r["expected"]), _fmt(r["ours"]),
             _fmt(r["error"]), _fmt(r["tol"]), "PASS" if r["passed"] else "FAIL")
            for r in rows]
    w = [max(len(h), *(len(b[i]) for b in body)) for i, h in enumerate(head)]
    line = lambda cells: "  ".join(c.ljust(w[i]) if i < 3 else c.rjust(w[i])  # noqa: E731
                                   for i, c in enumerate(cells))
    out = [line(head), "  ".join("-" * x for x in w)]
    out += [line(b) for b in body]
    return "\n".join(out)


def run(threads=1, progress=True):
    rows, seconds = [], {}
    with numba_threads(threads):
        for name, fn in ITEMS:
            t = time.perf_counter()
            rows += fn()
            seconds[name] = time.perf_counter() - t
            if progress:
                print(f"  {name}: {seconds[name]:.1f} s", file=sys.stderr, flush=True)
    return rows, seconds


def main(argv=None):
    ap = vargs.ScriptParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", type=vargs.output_file, default=DEFAULT_JSON, metavar="FILE",
                    help="where to write the scorecard (default validation/results/sanity.json)")
    ap.add_argument("--threads", type=vargs.threads, default=1,
                    help="Numba threads, in [1, NUMBA_NUM_THREADS] (default 1; the results do "
                    "not depend on it)")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    rows, seconds = run(a.threads)
    text = table(rows)
    n_pass = sum(r["passed"] for r in rows)
    print(text)
    print(f"\n{n_pass}/{len(rows)} PASS ({time.perf_counter() - t0:.0f} s). Units: m, s, "
          f"kg, g = {G} m/s^2; error = |ours - expected|.")
    for r in rows:
        if not r["passed"]:
            print(f"FAIL {r['case']}: ours {r['ours']:.6g}, expected {r['expected']:.6g}, "
                  f"error {r['error']:.3g} > tol {r['tol']:.3g} ({r['tol_basis']})")
    write_json(a.json, dict(units="SI: m, s, kg; g = 9.81 m/s^2 along -y",
                            solver_iterations=dict(position=ITERS[0], velocity=ITERS[1]),
                            rows=rows, seconds=seconds, passed=n_pass, total=len(rows),
                            table=text))
    print(f"wrote {a.json}")
    return 0 if n_pass == len(rows) else 1


if __name__ == "__main__":
    sys.exit(vargs.run(main))
