"""``peclet.packing.pack``: any element, any container, a protocol, a material -> a frozen pack.

World frame (docs/architecture.md §10): y up, gravity -9.81 D / time^2 along y, the floor's top face at
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
from peclet.core.geom import grids
from peclet.core.machine import check_memory, physical_memory
from peclet.core.validation import PecletArgumentError, check_bool, check_int

from . import checkpoint as ckpt
from .containers import Container, parse_container
from .contact import parse_contact
from .elements import ELEMENTS, Element, parse_element
from .freeze import Pack
from .material import Material, as_material
from .threads import set_threads
from .user_shapes import grid_npz_element, is_grid_npz, is_user_file, user_file_element
from .progress import Progress, compile_note, ms_per_step
from .protocols import G, Body, RunState, drive, insert_bodies, new_simulation, parse_protocol

__all__ = ["pack", "resume", "PackResult", "ElementModel", "element_model", "ITERATIONS",
           "COUNT_MAX", "BYTES_PER_ELEMENT", "count_cap", "check_walls", "MAX_SHELL_RESOLUTION"]

#: The most elements one pack takes (the work: at ~0.1 ms per element-step on 2 cores, 10^5
#: elements are ~10 s per step), unless memory caps it lower (:func:`count_cap`).
COUNT_MAX = 100_000

#: Bytes the engine holds per element, an upper estimate: the narrow phase's contact slots
#: (16 per body pair, 64 bytes each, ~8 pairs per element, doubled when the buffer grows)
#: plus the body state and broad-phase lists.
BYTES_PER_ELEMENT = 16 * 1024


def count_cap():
    """(the largest count a pack takes, why): :data:`COUNT_MAX`, or what a quarter of this
    machine's physical memory holds at :data:`BYTES_PER_ELEMENT` if that is fewer."""
    mem = physical_memory()
    why = (f"the cap: {COUNT_MAX} elements for the work (about 0.1 ms per element-step), "
           f"and memory at {BYTES_PER_ELEMENT // 1024} KiB per element in the engine")
    if mem is None:
        return COUNT_MAX, why
    by_mem = int(mem // 4 // BYTES_PER_ELEMENT)
    why += f" (a quarter of {mem / 2 ** 30:.1f} GiB holds {by_mem})"
    return min(COUNT_MAX, by_mem), why

#: The largest marching-cubes lattice (nodes a side) the thin-wall rule of
#: :func:`element_model` builds (scene_particle's own bound).
MAX_SHELL_RESOLUTION = 1024
#: Peak bytes per node of the probe lattice (the field on the lattice, marching cubes' work;
#: measured: 21 B a node from 128^3 to 384^3 nodes).
SHELL_BYTES_PER_NODE = 24

#: Solver sweeps (position, velocity), the page's.
ITERATIONS = (10, 8)

#: ``scene_particle.build`` knobs, the page's (quadrature resolution, marching-cubes lattice,
#: shell probes).
BUILD = dict(n=32, shell_resolution=112, target_shell_points=1200)

ELEMENT_FORMS = (f"one of {sorted(ELEMENTS)} (optionally with parameters, NAME:KEY=V,...), an "
                 "Element, a (builder, root) pair, a path to an .npz holding node_ints, "
                 "node_reals, root or a saved grid (values, spacing, origin), or a mesh "
                 "file (.stl/.obj/.ply[:scale=S,resolution=H])")


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


def element_diameter(el: Element):
    """The element's D: its envelope's outer diameter (rings, cylinders, spheres) or the
    torus centre-line diameter of a saddle (2 R); a user's tree: its bounding ball's."""
    p = el.params
    for key in ("r_outer", "radius", "R"):
        if key in p:
            return 2.0 * float(p[key])
    return 2.0 * float(el.builder.node_bound(el.root)[1])


def resolve_element(value):
    """An Element from the accepted forms (cheap: builds the tree only).

    A library element takes its construction parameters as ``"NAME:KEY=V,KEY=V"`` (the
    command line's ``--element pall_ring:thickness=0.024,n_windows=5``; a triple is written
    ``a/b/c``) or as ``(NAME, {KEY: V})``; every parameter is checked against
    ``elements.PARAMS`` (name, number, range given the others) and the constructor's
    cross-checks, errors naming ``element``, the parameter and its accepted range.
    """
    if isinstance(value, Element):
        return value
    if isinstance(value, str) and value in ELEMENTS:
        return ELEMENTS[value]()
    if is_user_file(value):
        return user_file_element(value, _user_element)
    if (isinstance(value, str) and ":" in value and not value.endswith(".npz")) \
            or (isinstance(value, tuple) and len(value) == 2 and isinstance(value[0], str)
                and isinstance(value[1], dict)):
        kind, params = parse_element(value, "element")
        return ELEMENTS[kind](**params)
    if isinstance(value, (str, os.PathLike)) and str(value).endswith(".npz") \
            and os.path.isfile(value) and is_grid_npz(value):
        return grid_npz_element(value, _user_element)
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
    aligned = grids.quadrature_layout(b, root)
    if aligned is not None:            # a grid leaf: measure it cell by lattice cell
        return Element(b, root, name, {}, aligned[:2], quadrature_n=aligned[2])
    return Element(b, root, name, {}, (c - 1.1 * r, c + 1.1 * r))


_MODELS = {}


#: Most shell probes the thin-wall rule of :func:`element_model` may ask for (a wall thinner
#: than the spacing this allows keeps this many).
MAX_RULE_PROBES = 60_000


def element_model(el: Element, build=None):
    """Measure ``el`` (quadrature, principal frame, shell probes) into an :class:`ElementModel`
    (cached per process by the tree's bits, so an ensemble measures its element once).

    Probe density follows the thinnest wall. With ``t = el.min_feature`` (the thinnest wall or
    web, in the element's length unit; NaN for a user's tree: no rule) and A the shell's
    marching-cubes area, the probes' even-spread spacing ``sqrt(2 A / (sqrt(3) N))``
    (``shell.even_spacing``) must be <= t, so both faces of every wall, and the rim face of
    width t, carry probes (farthest-point thinning leaves the far face of a wall thinner than
    the spacing bare). The page's count (``BUILD``, 1200) is kept whenever it meets the rule
    (the library defaults all do: the page's ring is bit for bit unchanged); otherwise the
    shell is rebuilt with ``N = shell.count_for_spacing(A, t)`` probes (at most
    :data:`MAX_RULE_PROBES`). The marching-cubes lattice likewise gets at least 2 cells across
    t (``shell_resolution >= 2 extent / t``, at most 1024). Knobs given in ``build`` are
    taken as they are.
    """
    from peclet.core.geom.transforms import quat_to_matrix
    from peclet.dem import scene_particle

    from .elements import home_transform

    kw = dict(BUILD, **(build or {}))
    if el.quadrature_n is not None and "n" not in (build or {}):
        kw["n"] = el.quadrature_n
    ni, nr, _, _ = el.builder.encode()
    key = (el.name, int(el.root), ni.tobytes(), nr.tobytes(), tuple(sorted(kw.items())))
    if key in _MODELS:
        return _MODELS[key]
    d = element_diameter(el)
    if el.name == "sphere":
        r = float(el.params["radius"])
        vol = 4.0 / 3.0 * math.pi * r ** 3
        mass = vol
        model = ElementModel("sphere", ni, nr, el.root, _fibonacci_sphere(4000, r), vol, mass,
                             np.full(3, 1.0 / (0.4 * mass * r * r)), r, d, el.root, vol,
                             sphere=True)
    else:
        sp = _build_following_walls(scene_particle, el, kw, build or {})
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


def check_walls(el, resolution=None):
    """The probe lattice (nodes a side) the thin-wall rule of :func:`element_model` builds for
    ``el`` (at least ``resolution``, default the page's): 2 cells across its thinnest wall
    ``el.min_feature`` (D). Raises PecletArgumentError naming the element's parameters when
    that needs more than :data:`MAX_SHELL_RESOLUTION` (capping would build the largest lattice
    and still miss the wall's far face) or more memory than this machine gives a job. Cheap:
    nothing is built."""
    res = int(BUILD["shell_resolution"] if resolution is None else resolution)
    t = float(el.min_feature)
    if not (math.isfinite(t) and t > 0):
        return res
    extent = float(np.max(np.asarray(el.bounds[1]) - np.asarray(el.bounds[0])))
    need = math.ceil(2.0 * extent / t)
    if need > MAX_SHELL_RESOLUTION:
        raise PecletArgumentError(
            f"{el.name} parameters", "walls at least "
            f"{2.0 * extent / MAX_SHELL_RESOLUTION:.3g} D thick (2 cells of the probe "
            f"lattice, at most {MAX_SHELL_RESOLUTION} a side over the element's "
            f"{extent:.3g} D extent)", f"thinnest wall {t:.3g} D",
            f"it needs a {need}^3 lattice")
    res = max(res, need)
    check_memory(f"{el.name} parameters", f"thinnest wall {t:.3g} D",
                 res ** 3 * SHELL_BYTES_PER_NODE,
                 f"the probe lattice of {res}^3 nodes at {SHELL_BYTES_PER_NODE} B a node")
    return res


def _build_following_walls(scene_particle, el, kw, given):
    """``scene_particle.build`` with the thin-wall rule of :func:`element_model`."""
    from peclet.core.geom.shell import count_for_spacing

    t = float(el.min_feature)
    if not (math.isfinite(t) and t > 0):
        return scene_particle.build(el.builder, el.root, bounds=el.bounds, **kw)
    # a second build (more probes) takes the first one's quadrature from the cache: a thin
    # ring's measurement is done once (7.2 s -> 5.7 s for the 0.024 D Pall ring, the same bits)
    kw = dict(kw, cache={})
    if "shell_resolution" not in given:
        kw["shell_resolution"] = check_walls(el, kw["shell_resolution"])
    sp = scene_particle.build(el.builder, el.root, bounds=el.bounds, **kw)
    if "target_shell_points" in given or sp.spacing["even_spacing"] <= t:
        return sp
    need = min(MAX_RULE_PROBES, count_for_spacing(sp.spacing["area"], t))
    if need <= kw["target_shell_points"]:
        return sp
    return scene_particle.build(el.builder, el.root, bounds=el.bounds,
                                **dict(kw, target_shell_points=int(need)))


@dataclass
class PackResult:
    """What :func:`pack` returns: ``pack`` (the frozen state, a ``freeze.Pack``; ``box`` is the
    container's analysis period), ``container`` (bound to the element's D), ``sim`` (the live
    Simulation), ``steps``, ``seconds`` (stepping wall-clock), ``ke`` (kinetic energy after
    every step, mass D^2 / time^2), ``spec`` (JSON-able inputs), ``state`` (the protocol's
    RunState), ``complete`` (False when ``max_steps`` stopped it early), ``element`` (the
    ElementModel), ``first_step_seconds`` (the first step's wall-clock, which holds the
    kernels' compilation on a cold cache; :meth:`ms_per_step` leaves it out)."""

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
    first_step_seconds: float = 0.0

    def ms_per_step(self):
        """Milliseconds per step after the first (whose compilation on a cold cache is not a
        stepping rate); the whole run's average when it took one step."""
        return ms_per_step(self.seconds, self.first_step_seconds, self.steps)

    @property
    def landed(self):
        """The landing rule (``protocols``): no body moved faster than LAND_SPEED D/time when
        the quench started and none was in the air when the run ended (``protocols.in_air``;
        None for a run stopped before the quench; details in ``state.landing``)."""
        rec = self.state.landing if self.state is not None else None
        return None if rec is None else bool(rec["landed"])

    def state_hash(self):
        """SHA-256 (hex) of the positions' then the quaternions' float64 bytes."""
        h = hashlib.sha256()
        h.update(np.ascontiguousarray(self.pack.positions, dtype=np.float64).tobytes())
        h.update(np.ascontiguousarray(self.pack.quaternions, dtype=np.float64).tobytes())
        return h.hexdigest()


def _set_threads(threads):
    """threads.set_threads (the one check and call), None leaving numba's setting."""
    return None if threads is None else set_threads(threads)


def check_run_args(count, seed, threads, progress, max_steps, checkpoint_dir,
                    checkpoint_every, name="count"):
    cap, why = count_cap()
    count = check_int(name, count, 1)
    if count > cap:
        raise PecletArgumentError(name, f"an integer in [1, {cap}]", count, why)
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
         max_steps=None, checkpoint_dir=None, checkpoint_every=None, build=None, contact=None):
    """Pack ``count`` copies of ``element`` into ``container`` by ``protocol``.

    element: a library name (``peclet.packing.ELEMENTS``), with construction parameters as
    ``"pall_ring:thickness=0.024,n_windows=5"`` or ``("pall_ring", {"thickness": 0.024})``
    (``elements.PARAMS``; checked, see ``peclet pack -h``), an Element, a (builder, root) pair
    (authoring frame) or the path of an .npz with node_ints, node_reals, root.
    container: "box:L" (periodic, the page's), "column:N" (diameter N D, floor y = 0),
    "walled:Lx,Lz", a Container, or a (builder, root) tree of the fluid region (its complement
    is the wall). protocol: "page", "rain" or a PageProtocol / RainProtocol. material /
    wall_material: Material (wall: None = material; a wall uses e_n and mu). seed: the
    generator seed (>= 0). threads: Numba threads (None keeps the current). max_steps: stop
    after this many steps in all (the result then has ``complete=False``). checkpoint_dir /
    checkpoint_every: checkpoint every K steps (see :func:`resume`). build: overrides of
    ``scene_particle.build``'s knobs (n, shell_resolution, target_shell_points), taken as
    given; those not given follow the thinnest wall (:func:`element_model`). contact: the
    contact law, None or "impulse" (the default) or Hertz–Mindlin ("hertz", a
    ``contact.HertzContact`` with E in bed units or from Pa, nu and the Rayleigh-time step
    rule; recorded in the spec, so checkpoints and :func:`resume` carry it).
    Returns a :class:`PackResult`.
    """
    count, seed, max_steps, every = check_run_args(count, seed, threads, progress, max_steps,
                                                    checkpoint_dir, checkpoint_every)
    proto = parse_protocol(protocol)
    cont = parse_container(container)
    mat = as_material(material, "material")
    wmat = mat if wall_material is None else as_material(wall_material, "wall_material")
    law = parse_contact(contact)
    for m, name in (() if law is None else ((mat, "material"), (wmat, "wall_material"))):
        law.check_material(m, name)
    if isinstance(element, (str, os.PathLike)) and str(element).endswith(".npz") \
            and not os.path.isfile(element):
        raise PecletArgumentError("element", ELEMENT_FORMS, element,
                                  "it is a directory" if os.path.isdir(element)
                                  else "it does not exist")
    el = resolve_element(element)
    if build is not None and not isinstance(build, dict):
        raise PecletArgumentError("build", "a dict of scene_particle.build knobs", build)
    cont = cont.bound(element_diameter(el))
    # before measuring the element, with its authoring bounding ball for r_b: rain, the
    # enclosure of the insertion zone; page, the element fits and the start cloud's rules
    # (both run again on the measured element)
    c0, r0, _ = el.builder.node_bound(el.root)
    proto.start(dict(container=cont, body=Body(-1, 1.0, np.ones(3),
                                               float(np.linalg.norm(c0) + r0), cont.d),
                     count=count), np.random.default_rng(seed))
    spec = dict(element=el.name, element_params=_jsonable(el.params),
                container=cont.to_spec(), count=count, protocol=proto.to_spec(),
                material=mat.to_dict(), wall_material=wmat.to_dict(), seed=seed,
                iterations=list(ITERATIONS), build=dict(BUILD, **(build or {})))
    if law is not None:                 # the impulse default leaves the spec as it was
        spec["contact"] = law.to_spec()
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
        missing = isinstance(checkpoint_dir, (str, os.PathLike)) \
            and not os.path.exists(checkpoint_dir)
        raise PecletArgumentError("checkpoint_dir", "a peclet pack checkpoint directory",
                                  checkpoint_dir, "it does not exist" if missing else "")
    _, _, max_steps, every = check_run_args(1, 0, threads, progress, max_steps, None, None)
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
        law = parse_contact(spec.get("contact"))
        if law is not None:             # a resumed simulation carries its law (persistence)
            law.configure(sim, model, proto.dt)
        body.shape_id = sid
        if len(P):
            insert_bodies(sim, body, P, Q, V)
        st = RunState()
    else:
        sim, st = resumed
        body.shape_id = 0                  # the run's only shape
        rng.bit_generator.state = st.rng
    ctx["y_top"] = y_top
    total = proto.estimate_steps(spec["count"])
    bar = Progress(total, f"pack {model.name} ", enabled=progress,
                   initial=min(st.step, total), note=compile_note())
    if st.label:
        bar.update(0, st.label)

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
    _warn_landing(st.landing, model.name)
    first = bar.first_seconds if bar.first_seconds is not None else 0.0
    n = sim.num_particles()
    pos = np.array(sim.get_positions(), dtype=np.float64).reshape(n, 3)
    q = np.array(sim.get_quaternions(), dtype=np.float64).reshape(n, 4)
    if n:
        q = q / np.linalg.norm(q, axis=1)[:, None]
    pk = Pack(pos, q, list(cont.period), model.volume, model.node_ints, model.node_reals,
              model.home_root, model.bounding_radius, model.shell, model.mass,
              model.inv_inertia, model.envelope_root, model.envelope_volume, model.axis_home)
    return PackResult(pk, cont, sim, st.step, seconds, st.ke, spec, st, st.done, model,
                      min(first, seconds))


def landing_message(rec):
    """One line saying how a run broke the landing rule (``rec``: ``RunState.landing``)."""
    fall, before = rec.get("fall_time"), rec.get("landing_time")
    if rec["moving"]:
        why = (f"{rec['moving']} of {rec['bodies']} elements moved faster than "
               f"{rec['threshold']:g} D/time (up to {rec['max_speed']:.3g}) when the quench "
               f"started at step {rec['step']}")
    elif not (fall is not None and before is not None and fall > before) \
            and rec.get("in_air"):
        why = (f"{rec['in_air']} of {rec['bodies']} elements were still in the air when the "
               f"run ended at step {rec['air_step']} (no chain of bounding spheres within "
               f"{rec['air_gap']:g} D of one another reaches the floor; the highest "
               f"{rec['air_top']:.3g} D above it)")
    else:
        why = (f"the start cloud's top needs {rec['fall_time']:.3f} time units of free fall, "
               f"more than the {rec['landing_time']:.3f} before the quench (step "
               f"{rec['step']})")
    return (f"the bed did not land: {why}: the quench froze falling elements; give the run "
            "more steps (a larger steps scale) or fewer elements")


def _warn_landing(rec, name):
    if rec is not None and not rec["landed"]:
        import warnings

        from .protocols import LandingWarning

        warnings.warn(f"pack {name}: {landing_message(rec)}", LandingWarning, stacklevel=3)


def _jsonable(x):
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple, np.ndarray)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.generic):
        return x.item()
    return x
