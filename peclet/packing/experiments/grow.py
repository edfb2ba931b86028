"""Growth to jamming or to a target fraction, in a periodic cube (issue 23, item 4) or in a
closed box or column (issue 41, item 5).

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

Containers (:mod:`~peclet.packing.experiments.grow_containers`): the periodic cube above, or
``box:AxBxC`` / ``column:N``, closed by walls that the same compression moves inward by their
poses (growing the bodies in a fixed container is, up to a change of unit, the same as mapping
the centres affinely and shrinking the container: the shape is built once); the gate, the
thermostat and the stop are the same for every container, and body-wall overlaps gate the
rate as body-body ones do. ``target_phi`` (an envelope fraction of the container's current
volume) stops the compression there: the container is shrunk exactly to it, the bed is stepped
on until its largest overlap is below ``overlap_lo``, then quenched (no opening: phi is the
target). Without it the run stops at jamming, as before.

Overlap-driven slow-down. Every ``check_every`` steps the largest overlap (the engine's
penetration depth, in D) is read: above ``overlap_hi`` the compression pauses and gamma is
halved; while paused and still above ``overlap_lo``, gamma shrinks by 10 % a check; below
``overlap_lo`` the compression resumes and gamma grows by 10 % (up to the starting rate). The
bed is jammed when gamma has fallen below ``gamma_min`` (the compression can no longer proceed
without overlaps the position solve cannot remove). Then the bed is quenched (velocities
zeroed, overlaps relaxed); a bed of spheres is opened until no overlap exceeds
``FINAL_OVERLAP`` (1e-4 D), a bed of composed elements is measured as it jammed (their contacts
rest on probes, and the position solve leaves about 1e-3 D of overlap in it).

Measurements: phi (N V / V_container, V the element's volume), f_env (with the envelope
volume), the mean coordination Z of the engine's contacts with a gap below ``gap`` D (default
1e-3 D; the pairs of bodies, each pair once per body, across the periodic faces too), the
bodies touching a wall, the largest body-body and body-wall overlaps, the rattlers (Z < 4 for
frictionless spheres: d + 1 in 3-D), and in the periodic cube the pair correlation g(r) of the
centres (minimum images, bins of 0.01 D) with its first peak's position and height (a walled
bed's g(r) would be biased by its walls: not computed).

Units: lengths in the element's diameter D, time such that the thermal speed sqrt(T) is 1
D/time by default; a body's mass is its volume (density 1).
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass

import numpy as np

from peclet.core.spec import Custom, Float, Int, Spec, Text, field
from peclet.core.validation import PecletArgumentError, check_float

from .grow_containers import make_container, parse_grow_container

__all__ = ["GrowSpec", "grow", "pair_correlation", "periodic_coordination", "FINAL_OVERLAP",
           "write_outputs", "table", "OUTPUTS"]

#: What a growth run writes into its output directory.
OUTPUTS = ("results.json", "grown.npz", "grow.png")

#: A jammed bed of spheres is opened until no two overlap by more than this (D).
FINAL_OVERLAP = 1e-4


def _container_rule(arg, value, ctx):
    parse_grow_container(value, arg)
    return value


def _wall_rule(own):
    """The check of a wall material field: refused with the periodic cube (it has no walls),
    else the body-body ``own`` field's value when None."""
    def rule(arg, value, ctx):
        if ctx.value("container") == "periodic":
            if value is not None:
                raise PecletArgumentError(arg, "left out with the periodic cube (a periodic "
                                          "cube has no walls)", value)
            return None
        if value is None:
            return ctx.value(own)
        return check_float(arg, value, 0.0, 1.0 if own == "e_n" else 10.0)
    return rule


@dataclass(frozen=True)
class GrowSpec(Spec):
    """A growth run (see the module notes); :meth:`checked` (from :class:`~peclet.core.spec.
    Spec`) checks every field as declared here (PecletArgumentError naming ``names[field]``).
    ``container``: "periodic", "box:AxBxC" or "column:N" (D); ``target_phi``: None (grow to
    jamming) or the envelope fraction to stop at; ``wall_e_n``, ``wall_mu``: the walls'
    restitution and friction (default the bodies' ``e_n``, ``mu``; walled containers only)."""

    check_first = ("element", "overlap_lo")

    element: str = field("sphere", Text("a library element name (NAME:KEY=V,...), a mesh file "
                                        "or an .npz (a grid or a flat encoding)"))
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
    container: str = field("periodic", Custom(_container_rule))
    target_phi: float = field(None, Float(0.0, 1.0, lo_open=True, hi_open=True, if_none=None))
    wall_e_n: float = field(None, Custom(_wall_rule("e_n")))
    wall_mu: float = field(None, Custom(_wall_rule("mu")))


def _envelope(model):
    """The element's envelope volume (its solid volume when it has no envelope)."""
    env = float(model.envelope_volume)
    return env if np.isfinite(env) and env > 0.0 else float(model.volume)


def _start(sim, model, spec, rng, cont):
    """Random positions (uniform in the container) and orientations, overlaps relaxed."""
    n = spec.count
    d = model.d
    L, P = cont.place(sim, rng)
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


def largest_overlaps(sim, d):
    """(largest body-body, largest body-wall) penetration depth of the current contacts, in
    ``d`` (0 when none overlaps)."""
    c = sim.detect_contacts()
    out = []
    for sel in (c["body_b"] >= 0, c["body_b"] < 0):
        depth = c["depth"][sel]
        out.append(max(0.0, float(depth.max())) / d if len(depth) else 0.0)
    return tuple(out)


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
    """Grow ``spec.count`` bodies to jamming or to ``spec.target_phi`` in ``spec.container``
    (``spec`` a :class:`GrowSpec`, checked here). Returns a dict: phi, f_env, z_mean,
    z_mean_no_rattlers, rattlers, wall_contacts, max_overlap (and its body-body and body-wall
    parts, in D), container (kind, sizes in D, scale), box (the periodic cube's side, D; None
    in a walled container), steps, jammed, target_reached, the g(r) first peak (periodic),
    the phi(t) history, and ``sim`` (the quenched Simulation) and ``model``."""
    from peclet.dem import Simulation

    from ..bed.progress import Progress

    if threads is not None:
        from ..bed.threads import set_threads
        set_threads(threads)
    spec = spec.checked()
    from ..bed.api import resolve_element, element_model

    try:
        model = element_model(resolve_element(spec.element))
    except PecletArgumentError as exc:
        if exc.argument not in ("element", "path", "mesh", "phi"):
            raise
        raise PecletArgumentError("element", "an element grow can build", spec.element,
                                  str(exc)) from None
    cont = make_container(spec, model, _envelope(model))
    d = model.d
    rng = np.random.default_rng(spec.seed)
    sim = Simulation(spec.count)
    if cont.periodic:
        sim.enable_periodicity(True, True, True)
    sim.set_gravity(0.0, 0.0, 0.0)
    sim.set_material_params(spec.e_n, 0.0, spec.mu)
    sim.set_solver_iterations(10, 8)
    model.register(sim)
    L = _start(sim, model, spec, rng, cont)
    sim.set_dt(spec.dt)
    vol = spec.count * model.volume
    env = spec.count * _envelope(model)
    L_stop = None if spec.target_phi is None else cont.size_at(env, spec.target_phi)
    gamma = spec.rate
    history = []
    bar = Progress(spec.max_steps, desc=f"grow {model.name}", enabled=progress)
    t0 = time.perf_counter()
    step, jammed, paused, reached = 0, False, False, False
    while step < spec.max_steps:
        if not (paused or reached):
            L_new = L * (1.0 + gamma * spec.dt) ** (-1.0 / 3.0)
            if L_stop is not None and L_new <= L_stop:
                L_new, reached = L_stop, True            # exactly the target, then no more
            if cont.too_small(L_new):
                break                              # the container no longer holds the bodies
            cont.resize(sim, L, L_new)
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
            history.append((step * spec.dt, vol / cont.volume(L), gamma, ov))
            bar.update(spec.check_every, label=f"phi {vol / cont.volume(L):.4f}")
            if reached and ov < spec.overlap_lo:
                break                              # at the target, its overlaps relaxed
            if gamma < spec.gamma_min:
                jammed = True
                break
    bar.close()
    # quench: no motion, overlaps relaxed; measured in the final container
    sim.set_velocities(np.zeros((spec.count, 3)))
    sim.set_angular_velocities(np.zeros((spec.count, 3)))
    sim.relax(100)
    # the compression stops with overlaps up to overlap_hi; for spheres (exact contacts) open
    # the container in small steps until they are below FINAL_OVERLAP (phi is then a packing
    # fraction of bodies that do not overlap, to that tolerance), unless it stopped at the
    # target (whose phi is the point). A composed element's contacts rest on a few probes and
    # the position solve leaves ~1e-3 D in a jammed bed: opening the container that far would
    # open every contact beyond the gap of Z, so its bed is measured as jammed, with its
    # largest overlap reported.
    for _ in range(200 if model.sphere and not reached else 0):
        ov = sim.compute_overlaps() / d
        if ov <= FINAL_OVERLAP:
            break
        L_new = cont.opened(L, ov, d)
        cont.resize(sim, L, L_new)
        L = L_new
        sim.relax(20)
    out = _measure(sim, model, spec, cont, L)
    out.update(steps=step, jammed=jammed, target_reached=reached, phi=vol / cont.volume(L),
               f_env=env / cont.volume(L),
               history=[dict(t=t, phi=p, gamma=gm, overlap=o) for t, p, gm, o in history],
               seconds=time.perf_counter() - t0, state_hash=sim.state_hash(), sim=sim,
               model=model)
    return out


def _measure(sim, model, spec, cont, L):
    """The quenched bed's coordination, overlaps, container and (periodic) g(r)."""
    d = model.d
    z, pairs = periodic_coordination(sim, d, spec.gap)
    rattler = z < 4
    c = sim.detect_contacts()
    walled = (c["depth"] > -spec.gap * d) & (c["body_b"] < 0)
    ov_pairs, ov_walls = largest_overlaps(sim, d)
    out = dict(spec=asdict(spec), element=model.name, count=spec.count,
               container=cont.describe(L, d), box=L / d if cont.periodic else None,
               z_mean=float(z.mean()),
               z_mean_no_rattlers=float(z[~rattler].mean()) if np.any(~rattler) else 0.0,
               rattlers=int(rattler.sum()),
               wall_contacts=int(len(np.unique(c["body_a"][walled]))),
               max_overlap=sim.compute_overlaps() / d, max_overlap_pairs=ov_pairs,
               max_overlap_walls=ov_walls, g_peak_r=None, g_peak=None, g_r=[], g=[])
    if cont.periodic:
        P = sim.get_positions()
        r, g = pair_correlation(P / d, L / d, min(3.0, 0.49 * L / d), 0.01)
        k = int(np.argmax(g))
        out.update(g_peak_r=float(r[k]), g_peak=float(g[k]), g_r=r.tolist(), g=g.tolist())
    return out


def write_outputs(res, out, previous=(), figures=True):
    """``results.json``, ``grown.npz`` (the bed: positions, quaternions (x, y, z, w), the
    periodic cube's sides ``box`` or, walled, ``container_kind`` and ``container_size`` (the
    final inner sizes, world: a box's three sides, a column's diameter and height; centred
    on the origin), the element's flat tree) and ``grow.png`` (phi against time; g(r) or, walled,
    the overlap against time) into ``out``, each atomically."""
    import os

    from peclet.core.files import atomic_write, write_json
    from peclet.core.outputs import clear_outputs

    os.makedirs(out, exist_ok=True)
    clear_outputs(out, previous)
    sim, model = res["sim"], res["model"]
    arrays = dict(positions=sim.get_positions(), quaternions=sim.get_quaternions(),
                  node_ints=model.node_ints, node_reals=model.node_reals,
                  root=np.int64(model.home_root), volume=np.float64(model.volume),
                  d=np.float64(model.d))
    if res["box"] is not None:
        arrays["box"] = np.array([res["box"] * model.d] * 3)
    else:
        arrays.update(container_kind=np.array(res["container"]["kind"]),
                      container_size=np.array(res["container"]["size"]) * model.d)

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
    if res["g_peak"] is not None:
        a2.plot(res["g_r"], res["g"], "-", color="C1", lw=0.8)
        a2.set_xlabel("r / D")
        a2.set_ylabel("g(r)")
        a2.set_title(f"first peak {res['g_peak']:.1f} at r = {res['g_peak_r']:.3f} D",
                     fontsize=9)
    else:
        a2.semilogy([x["t"] for x in h], [max(x["overlap"], 1e-9) for x in h], "-",
                    color="C1", lw=0.8)
        a2.set_xlabel("time")
        a2.set_ylabel("largest overlap / D")
        a2.set_title(res["container"]["label"], fontsize=9)
    fig.tight_layout()
    save_png(fig, path, dpi=110)


def table(res):
    """A growth run's results as a text table."""
    target = res["spec"]["target_phi"]
    stop = (f"target phi {target:g} {'reached' if res['target_reached'] else 'NOT reached'}"
            if target is not None else f"jammed {res['jammed']}")
    rows = [("element", res["element"]), ("bodies", res["count"]),
            ("container", res["container"]["label"]),
            ("stop", f"{stop} after {res['steps']} steps"),
            ("packing fraction phi", f"{res['phi']:.4f}"),
            ("envelope fraction f_env", f"{res['f_env']:.4f}"),
            (f"mean coordination (gap {res['spec']['gap']:g} D)",
             f"{res['z_mean']:.3f} ({res['z_mean_no_rattlers']:.3f} without the "
             f"{res['rattlers']} rattlers, Z < 4)")]
    if res["g_peak"] is not None:
        rows.append(("g(r) first peak", f"{res['g_peak']:.1f} at {res['g_peak_r']:.3f} D"))
    else:
        rows.append(("bodies touching a wall", f"{res['wall_contacts']}"))
    rows += [("largest overlap", f"{res['max_overlap']:.1e} D (body-body "
              f"{res['max_overlap_pairs']:.1e}, body-wall {res['max_overlap_walls']:.1e})")]
    if res["box"] is not None:
        rows.append(("cube side", f"{res['box']:.4f} D"))
    else:
        rows.append(("growth factor (bodies in the start container)",
                     f"{1.0 / res['container']['scale']:.4f}"))
    rows.append(("seconds", f"{res['seconds']:.1f}"))
    w = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{w}}  {v}" for k, v in rows)
