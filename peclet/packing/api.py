"""``peclet.packing.pack``: any element, any container, a protocol, a material -> a frozen pack.

World frame (DESIGN.md §8): y up, gravity -9.81 D / time^2 along y, the floor's top face at
y = 0; lengths of container specs and protocols in element diameters D (the element's envelope
outer diameter: 1 for the library's defaults). Quaternions (x, y, z, w), active, home
(principal) frame -> world.

>>> from peclet.packing import pack, Material
>>> res = pack("sphere", "column:5", count=60, protocol="rain",
...            material=Material(e_n=0.3, e_t=0.0, mu=0.3), seed=1, progress=False)
>>> res.pack.positions.shape
(60, 3)

Every argument is checked (PecletArgumentError naming it) before the element is measured or a
step is taken. A run with ``checkpoint_dir`` writes a checkpoint every ``checkpoint_every``
steps; :func:`resume` finishes it bit for bit as the uninterrupted run would.
"""
from __future__ import annotations

import hashlib
import math
import os
import time
from dataclasses import dataclass, field

import numpy as np

from peclet.core import geom
from peclet.core.validation import PecletArgumentError, check_bool, check_int

from . import checkpoint as ckpt
from .containers import Container, parse_container
from .elements import ELEMENTS, Element
from .freeze import Pack
from .material import Material, as_material
from .pipeline_checks import set_threads
from .progress import Progress
from .protocols import G, Body, RunState, drive, insert_bodies, new_simulation, parse_protocol

__all__ = ["pack", "resume", "PackResult", "ElementModel", "element_model", "ITERATIONS"]

#: Solver sweeps (position, velocity), the page's.
ITERATIONS = (10, 8)

#: ``scene_particle.build`` knobs, the page's (quadrature resolution, marching-cubes lattice,
#: shell probes).
BUILD = dict(n=32, shell_resolution=112, target_shell_points=1200)

ELEMENT_FORMS = (f"one of {sorted(ELEMENTS)}, an Element, a (builder, root) pair or a path "
                 "to an .npz holding node_ints, node_reals, root")


@dataclass
class ElementModel:
    """An element measured for the DEM: its tree (flat encoding; ``home_root`` the solid in
    its home frame, centred on the centre of mass, principal axes), shell probes (M, 3) in the
    home frame, volume, mass (density 1), inverse principal moments (3,), bounding radius
    about the centre of mass, diameter D, the envelope in the home frame (-1 if none), the
    element's axis in the home frame, and whether it is a sphere (the DEM's exact path)."""

    name: str
    node_ints: np.ndarray
    node_reals: np.ndarray
    home_root: int
    shell: np.ndarray
    volume: float
    mass: float
    inv_inertia: np.ndarray
    bounding_radius: float
    d: float
    envelope_root: int = -1
    envelope_volume: float = math.nan
    axis_home: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))
    sphere: bool = False

    @property
    def inv_inertia_unit(self):
        """``inv_inertia`` under ``scene_particle``'s name (so ``pour.pour`` takes a model)."""
        return self.inv_inertia

    def register(self, sim):
        """Add the shape to ``sim``; returns its id (spheres: the DEM's exact sphere)."""
        if self.sphere:
            return sim.add_sphere_shape(self.bounding_radius)
        return sim.add_scene_shape(self.node_ints, self.node_reals, self.home_root, self.shell,
                                   self.bounding_radius)

    def arrays(self):
        """The model as a dict of arrays (``element.npz`` of a checkpoint)."""
        return {k: np.asarray(getattr(self, k)) for k in self.__dataclass_fields__}

    @classmethod
    def from_arrays(cls, z):
        kw = {}
        for k, f in cls.__dataclass_fields__.items():
            v = z[k]
            kw[k] = v if v.ndim else v.item()
        kw["name"] = str(kw["name"])
        return cls(**kw)


def _fibonacci_sphere(n, r):
    i = np.arange(n) + 0.5
    y = 1.0 - 2.0 * i / n
    t = np.pi * (3.0 - np.sqrt(5.0)) * i
    s = np.sqrt(1.0 - y * y)
    return r * np.column_stack([s * np.cos(t), y, s * np.sin(t)])


def _diameter(el: Element):
    """The element's D: its envelope's outer diameter (rings, cylinders, spheres) or the
    torus centre-line diameter of a saddle (2 R); a user's tree: its bounding ball's."""
    p = el.params
    for key in ("r_outer", "radius", "R"):
        if key in p:
            return 2.0 * float(p[key])
    return 2.0 * float(el.builder.node_bound(el.root)[1])


def _resolve_element(value):
    """An Element from the accepted forms (cheap: builds the tree only)."""
    if isinstance(value, Element):
        return value
    if isinstance(value, str) and value in ELEMENTS:
        return ELEMENTS[value]()
    if isinstance(value, (str, os.PathLike)) and str(value).endswith(".npz") \
            and os.path.isfile(value):
        try:
            with np.load(value, allow_pickle=False) as z:
                b = geom.SceneBuilder.decode(z["node_ints"], z["node_reals"])
                return _user_element(b, int(z["root"]), os.path.basename(str(value)))
        except PecletArgumentError:
            raise
        except Exception:
            raise PecletArgumentError("element", ELEMENT_FORMS, value,
                                      "not a flat-encoding .npz") from None
    if isinstance(value, tuple) and len(value) == 2 and isinstance(value[0], geom.SceneBuilder):
        return _user_element(value[0], value[1], "custom")
    raise PecletArgumentError("element", ELEMENT_FORMS, value)


def _user_element(b, root, name):
    try:
        root = check_int("element root", root, 0, b.num_nodes() - 1)
        c, r, _ = b.node_bound(root)
    except PecletArgumentError:
        raise
    except Exception:
        raise PecletArgumentError("element", ELEMENT_FORMS, (b, root)) from None
    if not (np.isfinite(r) and r > 0):
        raise PecletArgumentError("element", "a bounded solid", name, f"bounding radius {r}")
    c = np.asarray(c, float)
    return Element(b, root, name, {}, (c - 1.1 * r, c + 1.1 * r))


_MODELS = {}


def element_model(el: Element, build=None):
    """Measure ``el`` (quadrature, principal frame, shell probes) into an :class:`ElementModel`
    (cached per process by the tree's bits, so an ensemble measures its element once)."""
    from peclet.core.geom.transforms import quat_to_matrix
    from peclet.dem import scene_particle

    from .elements import home_transform

    kw = dict(BUILD, **(build or {}))
    ni, nr, _, _ = el.builder.encode()
    key = (el.name, int(el.root), ni.tobytes(), nr.tobytes(), tuple(sorted(kw.items())))
    if key in _MODELS:
        return _MODELS[key]
    d = _diameter(el)
    if el.name == "sphere":
        r = float(el.params["radius"])
        vol = 4.0 / 3.0 * math.pi * r ** 3
        mass = vol
        model = ElementModel("sphere", ni, nr, el.root, _fibonacci_sphere(4000, r), vol, mass,
                             np.full(3, 1.0 / (0.4 * mass * r * r)), r, d, el.root, vol,
                             sphere=True)
    else:
        sp = scene_particle.build(el.builder, el.root, bounds=el.bounds, **kw)
        b = geom.SceneBuilder.decode(sp.node_ints, sp.node_reals)
        env = -1
        tq, qq, sq = home_transform(b, el.root, sp.home_root)
        axis = quat_to_matrix(qq) @ np.asarray(el.axis, float)
        if el.envelope_root is not None:
            env = b.add_reframed(el.envelope_root, translation=tq, rotation=qq, scale=sq)
        ni, nr, _, _ = b.encode()
        model = ElementModel(el.name, ni, nr, sp.home_root, sp.shell, float(sp.volume),
                             float(sp.mass), np.asarray(sp.inv_inertia_unit, float),
                             float(sp.bounding_radius), d, env,
                             math.nan if el.envelope_volume is None else el.envelope_volume,
                             axis)
    _MODELS[key] = model
    return model


@dataclass
class PackResult:
    """What :func:`pack` returns: ``pack`` (the frozen state, a ``freeze.Pack``; ``box`` is the
    container's analysis period), ``container`` (bound to the element's D), ``sim`` (the live
    Simulation), ``steps``, ``seconds`` (stepping wall-clock), ``ke`` (kinetic energy after
    every step, mass D^2 / time^2), ``spec`` (JSON-able inputs), ``state`` (the protocol's
    RunState), ``complete`` (False when ``max_steps`` stopped it early), ``element`` (the
    ElementModel)."""

    pack: Pack
    container: Container
    sim: object
    steps: int
    seconds: float
    ke: list
    spec: dict
    state: RunState
    complete: bool
    element: ElementModel

    def state_hash(self):
        """SHA-256 (hex) of the positions' then the quaternions' float64 bytes."""
        h = hashlib.sha256()
        h.update(np.ascontiguousarray(self.pack.positions, dtype=np.float64).tobytes())
        h.update(np.ascontiguousarray(self.pack.quaternions, dtype=np.float64).tobytes())
        return h.hexdigest()


def _set_threads(threads):
    """pipeline_checks.set_threads (the one check and call), None leaving numba's setting."""
    return None if threads is None else set_threads(threads)


def _check_run_args(count, seed, threads, progress, max_steps, checkpoint_dir,
                    checkpoint_every):
    count = check_int("count", count, 1)
    seed = check_int("seed", seed, 0)
    check_bool("progress", progress)
    if threads is not None:
        import numba
        check_int("threads", threads, 1, int(numba.config.NUMBA_NUM_THREADS))
    if max_steps is not None:
        max_steps = check_int("max_steps", max_steps, 0)
    if checkpoint_every is not None:
        checkpoint_every = check_int("checkpoint_every", checkpoint_every, 1)
        if checkpoint_dir is None:
            raise PecletArgumentError("checkpoint_dir", "a directory when checkpoint_every is "
                                      "given", None)
    if checkpoint_dir is not None:
        p = os.fspath(checkpoint_dir)
        if os.path.exists(p) and not os.path.isdir(p):
            raise PecletArgumentError("checkpoint_dir", "a directory", p, "it is a file")
        if ckpt.is_checkpoint(p):
            raise PecletArgumentError("checkpoint_dir", "a directory without a checkpoint "
                                      "(use resume() to finish one)", p)
    return count, seed, max_steps, checkpoint_every


def pack(element="pall_ring", container="box:3.5", count=48, protocol="page",
         material=Material(), wall_material=None, seed=5, threads=None, progress=True,
         max_steps=None, checkpoint_dir=None, checkpoint_every=None, build=None):
    """Pack ``count`` copies of ``element`` into ``container`` by ``protocol``.

    element: a library name (``peclet.packing.ELEMENTS``), an Element, a (builder, root) pair
    (authoring frame) or the path of an .npz with node_ints, node_reals, root.
    container: "box:L" (periodic, the page's), "column:N" (diameter N D, floor y = 0),
    "walled:Lx,Lz", a Container, or a (builder, root) tree of the fluid region (its complement
    is the wall). protocol: "page", "rain" or a PageProtocol / RainProtocol. material /
    wall_material: Material (wall: None = material; a wall uses e_n and mu). seed: the
    generator seed (>= 0). threads: Numba threads (None keeps the current). max_steps: stop
    after this many steps in all (the result then has ``complete=False``). checkpoint_dir /
    checkpoint_every: checkpoint every K steps (see :func:`resume`). build: overrides of
    ``scene_particle.build``'s knobs (n, shell_resolution, target_shell_points).
    Returns a :class:`PackResult`.
    """
    count, seed, max_steps, every = _check_run_args(count, seed, threads, progress, max_steps,
                                                    checkpoint_dir, checkpoint_every)
    proto = parse_protocol(protocol)
    cont = parse_container(container)
    mat = as_material(material, "material")
    wmat = mat if wall_material is None else as_material(wall_material, "wall_material")
    el = _resolve_element(element)
    if build is not None and not isinstance(build, dict):
        raise PecletArgumentError("build", "a dict of scene_particle.build knobs", build)
    cont = cont.bound(_diameter(el))
    if proto.kind == "rain":   # enclosure of the insertion zone, before measuring the element
        c0, r0, _ = el.builder.node_bound(el.root)
        proto.start(dict(container=cont, body=Body(-1, 1.0, np.ones(3),
                                                   float(np.linalg.norm(c0) + r0),
                                                   cont.d), count=count), None)
    spec = dict(element=el.name, element_params=_jsonable(el.params),
                container=cont.to_spec(), count=count, protocol=proto.to_spec(),
                material=mat.to_dict(), wall_material=wmat.to_dict(), seed=seed,
                iterations=list(ITERATIONS), build=dict(BUILD, **(build or {})))
    _set_threads(threads)
    model = element_model(el, build)
    if checkpoint_dir is not None:
        ckpt.init(checkpoint_dir, spec, model.arrays())
        ckpt.mark_started(checkpoint_dir)
    return _run(model, cont, proto, mat, wmat, spec, seed, progress, max_steps,
                checkpoint_dir, every, None)


def resume(checkpoint_dir, progress=True, max_steps=None, threads=None, checkpoint_every=None):
    """Finish the run checkpointed in ``checkpoint_dir`` (bit for bit as the uninterrupted run
    would); keeps checkpointing there every ``checkpoint_every`` steps (None: as before).
    Returns a :class:`PackResult`."""
    if checkpoint_dir is None or not ckpt.is_checkpoint(checkpoint_dir):
        raise PecletArgumentError("checkpoint_dir", "a peclet pack checkpoint directory",
                                  checkpoint_dir)
    _, _, max_steps, every = _check_run_args(1, 0, threads, progress, max_steps, None, None)
    if checkpoint_every is not None:
        every = check_int("checkpoint_every", checkpoint_every, 1)
    spec, arrays, sim, state, ke = ckpt.read(checkpoint_dir)
    if every is None:
        every = spec.get("checkpoint_every")
    _set_threads(threads)
    model = ElementModel.from_arrays(arrays)
    cont = parse_container(spec["container"]).bound(model.d)
    proto = parse_protocol(spec["protocol"])
    mat, wmat = Material(**spec["material"]), Material(**spec["wall_material"])
    resumed = None if sim is None else (sim, RunState.from_json(state, ke))
    return _run(model, cont, proto, mat, wmat, spec, int(spec["seed"]), progress, max_steps,
                checkpoint_dir, every, resumed)


def _run(model, cont, proto, mat, wmat, spec, seed, progress, max_steps, cdir, every, resumed):
    d = model.d
    body = Body(-1, model.mass, model.inv_inertia, model.bounding_radius, d)
    ctx = dict(container=cont, body=body, count=spec["count"])
    spec = dict(spec, checkpoint_every=every)
    rng = np.random.default_rng(seed)
    # the start is drawn again on a resume (cheap, deterministic): it sizes the domain
    P, Q, V, top = proto.start(ctx, np.random.default_rng(seed) if resumed else rng)
    # the page's domain top (60 D) unless the start cloud is taller; rain: a bound no layer
    # can reach (protocols.RainProtocol.top_bound)
    y_top = proto.top_bound(ctx) if top is None else max(60.0 * d, top + 2.0 * d)
    if resumed is None:
        sim, sid = new_simulation(model.register, cont, mat, wmat, ITERATIONS, G * d, proto.dt,
                                  y_top, spec["count"])
        body.shape_id = sid
        if len(P):
            insert_bodies(sim, body, P, Q, V)
        st = RunState()
    else:
        sim, st = resumed
        body.shape_id = 0                  # the run's only shape
        rng.bit_generator.state = st.rng
    ctx["y_top"] = y_top
    bar = Progress(proto.estimate_steps(spec["count"]), f"pack {model.name} ",
                   enabled=progress)
    bar.update(st.step, st.label or None)

    def on_step(s):
        bar.update(1, s.label)
        if every and cdir is not None and s.step % every == 0 and not s.done:
            s.rng = rng.bit_generator.state
            ckpt.write(cdir, sim, s)

    t0 = time.perf_counter()
    try:
        drive(sim, proto, ctx, st, rng, max_steps, on_step)
    finally:
        bar.close()
    seconds = time.perf_counter() - t0
    n = sim.num_particles()
    pos = np.array(sim.get_positions(), dtype=np.float64).reshape(n, 3)
    q = np.array(sim.get_quaternions(), dtype=np.float64).reshape(n, 4)
    if n:
        q = q / np.linalg.norm(q, axis=1)[:, None]
    pk = Pack(pos, q, list(cont.period), model.volume, model.node_ints, model.node_reals,
              model.home_root, model.bounding_radius, model.shell, model.mass,
              model.inv_inertia, model.envelope_root, model.envelope_volume, model.axis_home)
    return PackResult(pk, cont, sim, st.step, seconds, st.ke, spec, st, st.done, model)


def _jsonable(x):
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple, np.ndarray)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.generic):
        return x.item()
    return x
