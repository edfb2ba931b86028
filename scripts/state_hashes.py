"""State hashes of small representative runs, for bit-for-bit restructures of the DEM step.

    python scripts/state_hashes.py OUT.json [NAME ...]

Runs (a few seconds each once compiled) and writes (and prints) per run the SHA-256 of
``Simulation.state_hash()`` and, for the Hertz runs, of every array of ``hertz_contacts()``:

- ``hertz_spheres`` / ``hertz_spheres_parallel``: a pile of 64 spheres on a floor (the
  force and kick kernels serial, then forced parallel);
- ``hertz_rolling`` / ``hertz_rolling_parallel``: the same pile with rolling resistance;
- ``hertz_composed`` / ``hertz_composed_parallel``: CSG two-ball bodies, CSG balls and analytic
  spheres on a floor and on each other (Hertz patches; the patch kernels forced parallel);
- ``hertz_composed_rolling``: the composed scene with rolling resistance;
- ``hertz_conforming`` / ``hertz_conforming_parallel``: Raschig rings in a box (distributed
  contacts; the distributed kernels forced parallel);
- ``stir``, ``drum``, ``grow``: reduced stirred column, drum and growth runs (impulse step);
- ``pack``: the impulse engine's small pack (6 spheres in a column).

Two runs of the same behaviour give byte-identical files; compare them with ``cmp``. Names
on the command line select runs (default all).
"""
import hashlib
import json
import math
import sys

import numpy as np


def _digest(sim, hertz=True):
    h = hashlib.sha256(sim.state_hash().encode())
    if hertz:
        c = sim.hertz_contacts()
        for k in sorted(c):
            h.update(k.encode())
            h.update(np.ascontiguousarray(c[k]).tobytes())
    return h.hexdigest()


def _thresholds(value):
    """Force the Hertz kernels' parallel paths (value 0) or leave the defaults (None)."""
    from peclet.dem import hertz
    names = ("PARALLEL_MIN", "PATCH_PARALLEL_MIN", "DIST_PARALLEL_MIN")
    old = {k: getattr(hertz, k) for k in names}
    if value is not None:
        for k in names:
            setattr(hertz, k, value)
    return old


def _restore(old):
    from peclet.dem import hertz
    for k, v in old.items():
        setattr(hertz, k, v)


def _floor_box(sim, half=(1, 0.1, 1), ctr=(0, -0.1, 0), e=0.6, mu=0.3):
    from peclet.core import geom
    b = geom.SceneBuilder()
    root = b.add_leaf("box", list(half), translation=list(ctr))
    ni, nr, _, _ = b.encode()
    return sim.add_analytic_wall(ni, nr, root, False, e, mu)


def hertz_spheres(rolling=False, steps=300):
    from peclet.dem import Simulation
    rng = np.random.default_rng(3)
    n, r = 64, 0.01
    sim = Simulation(n)
    sim.add_sphere_shape(r)
    g = np.stack(np.meshgrid(np.arange(4), np.arange(4), np.arange(4), indexing="ij"), -1)
    pos = g.reshape(-1, 3) * 2.05 * r + rng.uniform(-2e-4, 2e-4, (n, 3))
    pos[:, 1] += r
    sim.set_positions(pos)
    sim.set_shape_ids(np.zeros(n, np.int64))
    sim.set_inv_mass(np.full(n, 1.0 / (2500 * 4 / 3 * math.pi * r ** 3)))
    sim.set_velocities(rng.uniform(-0.3, 0.3, (n, 3)))
    sim.set_angular_velocities(rng.uniform(-20.0, 20.0, (n, 3)))
    sim.set_domain([-1, -1, -1], [1, 1, 1])
    sim.set_gravity(0, -9.81, 0)
    sim.set_material_params(0.5, 0.0, 0.4)
    _floor_box(sim)
    sim.set_hertz_material(0, 1e7, 0.3)
    if rolling:
        sim.set_rolling_friction(0.2)
    for _ in range(steps // 50):
        sim.step_hertz(50, 1e-4)
    return _digest(sim)


def _composed_scene(rolling=False):
    from peclet.core import geom
    from peclet.dem import Simulation, scene_particle
    r, rho = 0.01, 2500.0
    b = geom.SceneBuilder()
    s1 = b.add_leaf("sphere", [r], translation=[-1.5 * r, 0, 0])
    s2 = b.add_leaf("sphere", [r], translation=[1.5 * r, 0, 0])
    balls = scene_particle.build(b, b.add_union(s1, s2), bounds=([-2.8 * r, -1.1 * r,
                                 -1.1 * r], [2.8 * r, 1.1 * r, 1.1 * r]), n=8,
                                 shell_resolution=40, target_shell_points=600, density=rho)
    b = geom.SceneBuilder()
    ball = scene_particle.build(b, b.add_leaf("sphere", [r]), bounds=([-1.1 * r] * 3,
                                [1.1 * r] * 3), n=8, shell_resolution=32,
                                target_shell_points=400, density=rho)
    rng = np.random.default_rng(5)
    sim = Simulation(8)
    ids = [balls.register(sim), ball.register(sim), sim.add_sphere_shape(r)]
    kinds = [0, 0, 0, 0, 1, 2, 2, 1]
    pos = np.array([[0.0, 1.05 * r, 0.0], [0.0, 3.2 * r, 0.0], [0.0, 1.05 * r, 2.2 * r],
                    [0.3 * r, 3.25 * r, 2.1 * r], [4.2 * r, 1.05 * r, 0.0],
                    [4.3 * r, 3.2 * r, 0.0], [-4.2 * r, 1.05 * r, 0.0],
                    [-4.0 * r, 3.12 * r, 0.2 * r]])
    sim.set_shape_ids([ids[k] for k in kinds])
    sim.set_positions(pos + rng.uniform(-1e-4, 1e-4, pos.shape))
    q = np.concatenate([rng.normal(0.0, 0.02, (8, 3)), np.ones((8, 1))], axis=1)
    sim.set_quaternions(q / np.linalg.norm(q, axis=1)[:, None])
    m = [balls.mass, ball.mass, rho * 4 / 3 * math.pi * r ** 3]
    sim.set_inv_mass([1 / m[k] for k in kinds])
    v = rng.uniform(-0.05, 0.05, (8, 3))
    v[:, 1] -= np.where(pos[:, 1] > 2 * r, 0.3, 0.15)
    sim.set_velocities(v)
    sim.set_domain([-1, -1, -1], [1, 1, 1])
    sim.set_gravity(0, -9.81, 0)
    sim.set_material_params(0.5, 0.0, 0.4)
    _floor_box(sim)
    sim.set_hertz_material(0, 1e8, 0.3)
    if rolling:
        sim.set_rolling_friction(0.1)
    return sim


def hertz_composed(rolling=False, calls=25):
    sim = _composed_scene(rolling)
    for _ in range(calls):
        sim.step_hertz(10, 1e-5)
    return _digest(sim)


def hertz_conforming(calls=20):
    from peclet.dem import Simulation, scene_particle
    from peclet.packing.bed import elements
    r, rho, t = 0.01, 2500.0, 0.0024
    el = elements.raschig_ring(r_outer=r, height=2 * r, thickness=t)
    sp = scene_particle.build(el.builder, el.root, bounds=el.bounds, n=8, shell_resolution=40,
                              target_shell_points=300, density=rho)
    rng = np.random.default_rng(3)
    n = 8
    sim = Simulation(n)
    sid = sp.register(sim)
    sim.set_shape_ids([sid] * n)
    g = np.array([[i % 2, i // 4, (i // 2) % 2] for i in range(n)], float)
    sim.set_positions((g - [0.5, 0.0, 0.5]) * 2.9 * r + [0, 1.5 * r, 0]
                      + rng.uniform(-1e-3, 1e-3, (n, 3)))
    q = rng.normal(size=(n, 4))
    sim.set_quaternions(q / np.linalg.norm(q, axis=1)[:, None])
    sim.set_inv_mass([1 / sp.mass] * n)
    sim.set_inv_inertia([list(1 / sp.principal)] * n)
    v = rng.uniform(-0.05, 0.05, (n, 3))
    v[:, 1] -= np.where(g[:, 1] > 0, 0.5, 0.1)
    sim.set_velocities(v)
    sim.set_domain([-1, -1, -1], [1, 1, 1])
    sim.set_gravity(0, -9.81, 0)
    sim.set_material_params(0.5, 0.0, 0.4)
    h = 3.2 * r
    for ctr, half in (([0, -0.05, 0], [0.1, 0.05, 0.1]), ([-h - 0.05, 0, 0], [0.05, 0.2, 0.1]),
                      ([h + 0.05, 0, 0], [0.05, 0.2, 0.1]), ([0, 0, -h - 0.05], [0.1, 0.2, 0.05]),
                      ([0, 0, h + 0.05], [0.1, 0.2, 0.05])):
        _floor_box(sim, half, ctr, 0.5, 0.4)
    sim.set_hertz_material(0, 1e8, 0.3)
    sim.set_rolling_friction(0.05)
    for _ in range(calls):
        sim.step_hertz(10, 2e-5)
    return _digest(sim)


def stir():
    from peclet.packing.experiments.stir import StirSpec, StirredColumn
    spec = StirSpec(grain_radius=1.0, revolutions=0.25, settle=0.5, frames=3, seed=2).checked()
    col = StirredColumn(spec)
    sim = col.build()
    for _ in range(20):
        sim.step()
    col.turn(spec.omega)
    for _ in range(20):
        sim.step()
    return _digest(sim, hertz=False)


def drum():
    from peclet.packing.experiments.drum import Drum, DrumSpec
    spec = DrumSpec(radius=4, length=3, ends="caps", fill=0.25, froude=0.1, mu=0.5, wall_mu=1.0,
                    revolutions=0.2, warmup=0.0, frames=0, seed=3).checked()
    d = Drum(spec)
    d.build(settle_max=100)
    d.turn(d.omega)
    d.step(50)
    return _digest(d.sim, hertz=False)


def grow():
    from peclet.packing.experiments.grow import GrowSpec, grow as run
    res = run(GrowSpec(count=40, max_steps=100, seed=4), progress=False)
    return hashlib.sha256(repr((res["state_hash"], float(res["phi"]).hex(),
                                res["steps"])).encode()).hexdigest()


def pack():
    from peclet.packing import Material, RainProtocol
    from peclet.packing import pack as run
    proto = RainProtocol(drop=3.0, settle_steps=300, calm_steps=20, quench_steps=20)
    res = run("sphere", "column:2.5", count=6, protocol=proto,
              material=Material(e_n=0.3, e_t=0.0, mu=0.3), seed=7, progress=False)
    return hashlib.sha256(res.state_hash().encode()).hexdigest()


def _parallel(fn, *args, **kw):
    old = _thresholds(0)
    try:
        return fn(*args, **kw)
    finally:
        _restore(old)


RUNS = {
    "hertz_spheres": lambda: hertz_spheres(),
    "hertz_spheres_parallel": lambda: _parallel(hertz_spheres, steps=100),
    "hertz_rolling": lambda: hertz_spheres(rolling=True),
    "hertz_rolling_parallel": lambda: _parallel(hertz_spheres, rolling=True, steps=100),
    "hertz_composed": lambda: hertz_composed(),
    "hertz_composed_parallel": lambda: _parallel(hertz_composed, calls=6),
    "hertz_composed_rolling": lambda: hertz_composed(rolling=True),
    "hertz_conforming": lambda: hertz_conforming(),
    "hertz_conforming_parallel": lambda: _parallel(hertz_conforming, calls=5),
    "stir": stir,
    "drum": drum,
    "grow": grow,
    "pack": pack,
}


def main(argv):
    if not argv or argv[0].startswith("-"):
        print(__doc__)
        return 2
    names = argv[1:] or list(RUNS)
    out = {}
    for name in names:
        out[name] = RUNS[name]()
        print(f"{name:28s} {out[name]}", flush=True)
    with open(argv[0], "w") as f:
        json.dump(out, f, indent=1, sort_keys=True)
        f.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
