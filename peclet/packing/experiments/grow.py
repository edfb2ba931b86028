"""Growth to jamming: a dense, isotropic bed in a periodic cube (issue 23, item 4).

Lubachevsky–Stillinger style: bodies start at random in a dilute periodic cube (envelope fraction
``phi_start``) and the packing fraction phi rises at a relative rate gamma (d ln phi / dt) with a thermostat on the motion,
until the bed jams. peclet grows the bodies by shrinking the cube instead: in a triply
periodic box, enlarging every body by s about its centre and scaling the box by 1/s are the
same configuration up to a change of unit, and the shrinking box keeps the element's shape
(its probes, distance grid, pruned programs) built once. Each step: positions are mapped
affinely into the box scaled by (1 + gamma dt)^(-1/3), then the impulse engine steps (no
gravity; the pair material ``e_n``, ``mu``, default 0.5 and 0: frictionless spheres jam at
random close packing), then a velocity-rescaling thermostat pulls the translational and
rotational temperature back towards T (relaxation time ``tau``): the heat that compression
pumps in is taken out, as LS's event-driven rescaling does.

Overlap-driven slow-down. Every ``check_every`` steps the largest overlap (the engine's
penetration depth, in D) is read: above ``overlap_hi`` the compression pauses and gamma is
halved; while paused and still above ``overlap_lo``, gamma shrinks by 10 % a check; below
``overlap_lo`` the compression resumes and gamma grows by 10 % (up to the starting rate). The
bed is jammed when gamma has fallen below ``gamma_min`` (the compression can no longer proceed
without overlaps the position solve cannot remove). Then the bed is quenched (velocities
zeroed, overlaps relaxed); a bed of spheres is opened until no overlap exceeds
``FINAL_OVERLAP`` (1e-4 D), a bed of composed elements is measured as it jammed (their contacts
rest on probes, and the position solve leaves about 1e-3 D of overlap in it).

Measurements: phi (N V / L^3, V the element's volume), the mean coordination Z of the engine's
contacts with a gap below ``gap`` D (default 1e-3 D; the pairs of bodies, each pair once per
body, across the periodic faces too), the rattlers (Z < 4 for frictionless spheres: d + 1 in
3-D), and for the centres the pair correlation g(r) (minimum images, bins of 0.01 D) with its
first peak's position and height.

Units: lengths in the element's diameter D, time such that the thermal speed sqrt(T) is 1
D/time by default; a body's mass is its volume (density 1).
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass

import numpy as np

from peclet.core.spec import Float, Int, Spec, Text, field

__all__ = ["GrowSpec", "grow", "pair_correlation", "periodic_coordination", "FINAL_OVERLAP",
           "write_outputs", "table", "OUTPUTS"]

#: What a growth run writes into its output directory.
OUTPUTS = ("results.json", "grown.npz", "grow.png")

#: A jammed bed of spheres is opened until no two overlap by more than this (D).
FINAL_OVERLAP = 1e-4


@dataclass(frozen=True)
class GrowSpec(Spec):
    """A growth run (see the module notes); :meth:`checked` (from :class:`~peclet.core.spec.
    Spec`) checks every field as declared here (PecletArgumentError naming ``names[field]``)."""

    check_first = ("element", "overlap_lo")

    element: str = field("sphere", Text("'sphere' or a library element name"))
    count: int = field(500, Int(2, 100_000))
    phi_start: float = field(0.15, Float(0.0, 0.4, lo_open=True))
    rate: float = field(0.5, Float(0.0, 10.0, lo_open=True))
    temperature: float = field(1.0, Float(0.0, 1e3, lo_open=True))
    tau: float = field(0.05, Float(0.0, 1e3, lo_open=True))
    e_n: float = field(0.5, Float(0.0, 1.0))
    mu: float = field(0.0, Float(0.0, 10.0))
    dt: float = field(2e-3, Float(0.0, 0.05, lo_open=True))
    overlap_hi: float = field(2e-3, Float("overlap_lo", 0.1, lo_open=True))
    overlap_lo: float = field(5e-4, Float(0.0, 0.1, lo_open=True))
    gamma_min: float = field(1e-4, Float(0.0, "rate", lo_open=True))
    check_every: int = field(10, Int(1, 10_000))
    max_steps: int = field(200_000, Int(1, 10 ** 8))
    gap: float = field(1e-3, Float(0.0, 0.1, lo_open=True))
    seed: int = field(1, Int(0, 2 ** 63 - 1))


def _envelope(model):
    """The element's envelope volume (its solid volume when it has no envelope)."""
    env = float(model.envelope_volume)
    return env if np.isfinite(env) and env > 0.0 else float(model.volume)


def _start(sim, model, spec, rng):
    """Random positions (uniform in the cube) and orientations, overlaps relaxed."""
    n = spec.count
    d = model.d
    L = (n * _envelope(model) / spec.phi_start) ** (1.0 / 3.0)
    sim.set_domain([0.0, 0.0, 0.0], [L, L, L])
    P = rng.uniform(0.0, L, size=(n, 3))
    Q = rng.normal(size=(n, 4)) if not model.sphere else np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    Q /= np.linalg.norm(Q, axis=1)[:, None]
    sim.set_positions(P)
    sim.set_shape_ids(np.zeros(n, np.int64))
    sim.set_quaternions(Q)
    sim.set_inv_mass(np.full(n, 1.0 / model.mass))
    sim.set_inv_inertia(np.tile(np.asarray(model.inv_inertia, float), (n, 1)))
    sim.relax(200)
    v = rng.normal(size=(n, 3)) * math.sqrt(spec.temperature) * d
    v -= v.mean(axis=0)                                   # no drift of the whole bed
    sim.set_velocities(v)
    return L


def _thermostat(sim, model, spec, lam_cap=2.0):
    """Velocity rescaling towards the temperature T (per degree of freedom: m <v_i^2> = T m
    D^2 / time^2 with the default unit mass scale), relaxation time tau; translation and
    rotation rescaled by the same factor (capped at ``lam_cap``)."""
    v = sim.get_velocities()
    n = len(v)
    t_now = float((v * v).sum()) / (3.0 * n) / (model.d * model.d)
    if t_now <= 0.0:
        return
    lam2 = 1.0 + spec.dt / spec.tau * (spec.temperature / t_now - 1.0)
    lam = min(math.sqrt(max(lam2, 0.0)), lam_cap)
    sim.set_velocities(v * lam)
    if not model.sphere:
        sim.set_angular_velocities(sim.get_angular_velocities() * lam)


def _compress(sim, L_old, L_new):
    f = L_new / L_old
    sim.set_positions(np.minimum(sim.get_positions() * f, np.nextafter(L_new, 0.0)))
    sim.set_domain([0.0, 0.0, 0.0], [L_new, L_new, L_new])


def periodic_coordination(sim, d, gap):
    """(Z per body (N,), pairs (k, 2)): bodies whose engine gap is below ``gap`` * ``d``
    (each unordered pair once in ``pairs``, counted for both bodies in Z; across periodic faces
    too, since the engine's detection uses minimum images)."""
    c = sim.detect_contacts()
    n = sim.num_particles()
    touch = (c["depth"] > -gap * d) & (c["body_b"] >= 0)
    a, b = c["body_a"][touch], c["body_b"][touch]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    pairs = np.unique(np.column_stack([lo, hi]), axis=0) if len(lo) else np.zeros((0, 2),
                                                                                   np.int64)
    z = np.bincount(pairs.ravel(), minlength=n) if len(pairs) else np.zeros(n, np.int64)
    return z, pairs


def pair_correlation(P, L, r_max, dr):
    """g(r) of centres ``P`` in a periodic cube of side ``L`` (minimum images), bins of ``dr``
    up to ``r_max`` (< L / 2). Returns (bin centres, g)."""
    n = len(P)
    edges = np.arange(0.0, r_max + dr, dr)
    hist = np.zeros(len(edges) - 1)
    for i in range(n - 1):
        dxyz = P[i + 1:] - P[i]
        dxyz -= L * np.round(dxyz / L)
        r = np.sqrt((dxyz * dxyz).sum(axis=1))
        hist += np.histogram(r, bins=edges)[0]
    rho = n / L ** 3
    shell = 4.0 / 3.0 * math.pi * (edges[1:] ** 3 - edges[:-1] ** 3)
    g = 2.0 * hist / (n * rho * shell)
    return 0.5 * (edges[1:] + edges[:-1]), g


def grow(spec, progress=True, threads=None):
    """Grow ``spec.count`` bodies to jamming (``spec`` a :class:`GrowSpec`, checked here).
    Returns a dict: phi, z_mean, z_mean_no_rattlers, rattlers, box, steps, jammed, the g(r)
    first peak, the phi(t) history, and ``sim`` (the quenched Simulation) and ``model``."""
    from peclet.dem import Simulation

    from ..bed.progress import Progress

    if threads is not None:
        from ..bed.threads import set_threads
        set_threads(threads)
    spec = spec.checked()
    from ..bed.api import resolve_element, element_model

    model = element_model(resolve_element(spec.element))
    d = model.d
    rng = np.random.default_rng(spec.seed)
    sim = Simulation(spec.count)
    sim.enable_periodicity(True, True, True)
    sim.set_gravity(0.0, 0.0, 0.0)
    sim.set_material_params(spec.e_n, 0.0, spec.mu)
    sim.set_solver_iterations(10, 8)
    model.register(sim)
    L = _start(sim, model, spec, rng)
    sim.set_dt(spec.dt)
    vol = spec.count * model.volume
    env = spec.count * _envelope(model)
    gamma = spec.rate
    history = []
    bar = Progress(spec.max_steps, desc=f"grow {model.name}", enabled=progress)
    t0 = time.perf_counter()
    step, jammed, paused = 0, False, False
    while step < spec.max_steps:
        if not paused:
            L_new = L * (1.0 + gamma * spec.dt) ** (-1.0 / 3.0)
            if L_new <= 2.0 * (2.0 * model.bounding_radius) * 1.05:
                break                              # the cube no longer holds the images apart
            _compress(sim, L, L_new)
            L = L_new
        sim.step()
        _thermostat(sim, model, spec)
        step += 1
        if step % spec.check_every == 0:
            ov = sim.compute_overlaps() / d
            if ov > spec.overlap_hi:
                gamma *= 0.5
                paused = True
            elif ov < spec.overlap_lo:
                paused = False
                gamma = min(gamma * 1.1, spec.rate)
            elif paused:
                # the bed holds overlaps the position solve cannot bring below overlap_lo
                # at this density: that too is the compression failing
                gamma *= 0.9
            history.append((step * spec.dt, vol / L ** 3, gamma, ov))
            bar.update(spec.check_every, label=f"phi {vol / L ** 3:.4f}")
            if gamma < spec.gamma_min:
                jammed = True
                break
    bar.close()
    # quench: no motion, overlaps relaxed; measured in the final cube
    sim.set_velocities(np.zeros((spec.count, 3)))
    sim.set_angular_velocities(np.zeros((spec.count, 3)))
    sim.relax(100)
    # the compression stops with overlaps up to overlap_hi; for spheres (exact contacts) open
    # the cube in small steps until they are below FINAL_OVERLAP (phi is then a packing
    # fraction of bodies that do not overlap, to that tolerance). A composed element's
    # contacts rest on a few probes and the position solve leaves ~1e-3 D in a jammed bed:
    # opening the cube that far would open every contact beyond the gap of Z, so its bed is
    # measured as jammed, with its largest overlap reported.
    for _ in range(200 if model.sphere else 0):
        ov = sim.compute_overlaps() / d
        if ov <= FINAL_OVERLAP:
            break
        L_new = L * (1.0 + 0.5 * ov * d / L)
        _compress(sim, L, L_new)
        L = L_new
        sim.relax(20)
    z, pairs = periodic_coordination(sim, d, spec.gap)
    rattler = z < 4
    P = sim.get_positions()
    r, g = pair_correlation(P / d, L / d, min(3.0, 0.49 * L / d), 0.01)
    k = int(np.argmax(g))
    return dict(spec=asdict(spec), element=model.name, phi=vol / L ** 3, f_env=env / L ** 3,
                box=L / d,
                steps=step, jammed=jammed, z_mean=float(z.mean()),
                z_mean_no_rattlers=float(z[~rattler].mean()) if np.any(~rattler) else 0.0,
                rattlers=int(rattler.sum()), max_overlap=sim.compute_overlaps() / d,
                g_peak_r=float(r[k]), g_peak=float(g[k]), g_r=r.tolist(), g=g.tolist(),
                count=spec.count,
                history=[dict(t=t, phi=p, gamma=gm, overlap=o) for t, p, gm, o in history],
                seconds=time.perf_counter() - t0, state_hash=sim.state_hash(), sim=sim,
                model=model)


def write_outputs(res, out, previous=(), figures=True):
    """``results.json``, ``grown.npz`` (the jammed bed: positions, quaternions (x, y, z, w),
    the cube's side, the element's flat tree) and ``grow.png`` (phi against time, g(r)) into
    ``out``, each atomically."""
    import os

    from peclet.core.files import atomic_write, write_json
    from peclet.core.outputs import clear_outputs

    os.makedirs(out, exist_ok=True)
    clear_outputs(out, previous)
    sim, model = res["sim"], res["model"]
    arrays = dict(positions=sim.get_positions(), quaternions=sim.get_quaternions(),
                  box=np.array([res["box"] * model.d] * 3), node_ints=model.node_ints,
                  node_reals=model.node_reals, root=np.int64(model.home_root),
                  volume=np.float64(model.volume), d=np.float64(model.d))

    def npz(tmp):
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)
    atomic_write(os.path.join(out, "grown.npz"), npz)
    files = ["results.json", "grown.npz"]
    if figures:
        _figure(os.path.join(out, "grow.png"), res)
        files.append("grow.png")
    body = {k: v for k, v in res.items() if k not in ("sim", "model")}
    body["files"] = files
    write_json(os.path.join(out, "results.json"), body)


def _figure(path, res):
    from peclet.core.figures import save_png, subplots

    h = res["history"]
    fig, (a1, a2) = subplots(1, 2, figsize=(9, 3.4))
    a1.plot([x["t"] for x in h], [x["phi"] for x in h], "-", color="C0")
    a1.set_xlabel("time")
    a1.set_ylabel("packing fraction phi")
    a1.set_title(f"{res['count']} {res['element']}: phi {res['phi']:.4f}, Z {res['z_mean']:.2f}",
                 fontsize=9)
    a2.plot(res["g_r"], res["g"], "-", color="C1", lw=0.8)
    a2.set_xlabel("r / D")
    a2.set_ylabel("g(r)")
    a2.set_title(f"first peak {res['g_peak']:.1f} at r = {res['g_peak_r']:.3f} D", fontsize=9)
    fig.tight_layout()
    save_png(fig, path, dpi=110)


def table(res):
    """A growth run's results as a text table."""
    rows = [("element", res["element"]), ("bodies", res["count"]),
            ("jammed", f"{res['jammed']} after {res['steps']} steps"),
            ("packing fraction phi", f"{res['phi']:.4f}"),
            ("envelope fraction f_env", f"{res['f_env']:.4f}"),
            (f"mean coordination (gap {res['spec']['gap']:g} D)",
             f"{res['z_mean']:.3f} ({res['z_mean_no_rattlers']:.3f} without the "
             f"{res['rattlers']} rattlers, Z < 4)"),
            ("g(r) first peak", f"{res['g_peak']:.1f} at {res['g_peak_r']:.3f} D"),
            ("largest overlap", f"{res['max_overlap']:.1e} D"),
            ("cube side", f"{res['box']:.4f} D"), ("seconds", f"{res['seconds']:.1f}")]
    w = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{w}}  {v}" for k, v in rows)
