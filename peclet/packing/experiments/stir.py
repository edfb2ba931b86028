"""The stirred column: grains mixed by a pitched-blade impeller (issue 22, item 4).

Geometry (upstream's stirred-column page; lengths in the page's units, gravity 9.81 along -y).
The column is a capsule of radius R = 20 around the y axis whose cylinder runs from y = 0 to
H = 24 (a dome above), cut flat at the floor y = 0: the tree ``capsule ∩ {y > 0}``, an
inverted wall (the outside is solid). The impeller, one rigid wall turning at omega = 1.5
rad/time about the y axis: four boxes of half-extents 7.4 (radial) x 0.35 x 1.8, centred at
radius 1.2 + 7.4 = 8.6 and height 3.5, each pitched 45 degrees about its own radial axis, so
the tips reach radius 16 (tip speed 24); a hub (a cylinder of radius 1.2 and half-height 1.3)
and a shaft (a capsule of radius 1 from the hub to the dome). Grains: spheres of radius 0.4,
restitution 0.2, friction 0.5 (grains, column and impeller alike), dt 2e-3.

Protocol (:class:`StirredColumn`). Fill: the ``count`` lowest sites of a cubic lattice of
spacing 2.25 r inside the column, clear of the wall and the impeller by 0.25 r, jittered by
+-0.1 r (no overlaps); the default count 22,121 (the page's) at r = 0.4, and for another r the
count that fills the same height (22,121 (0.4 / r)^3). Settle ``settle`` time units with the
impeller still (default 2: the loose lattice, packing fraction 0.37, collapses by about a third
of its height); then the impeller turns ``revolutions`` times.

Measurements (read the state only: a run's bits do not depend on them).

- Lacey's mixing index, M = (S0^2 - S^2) / (S0^2 - SR^2), of two species labelled after the
  settle: the lower and upper halves of the bed by height (ties by index). S^2 is the variance
  of the upper species' share over the 40 fixed bins (5 equal-area annuli out to R, times 8
  equal slabs from the floor to the settled bed's top; a grain above the top counts in the top
  slab), weighted by the bins' grain counts; S0^2 = p (1 - p) (segregated), SR^2 = S0^2 / n
  with n the mean grains per occupied bin (random). 0: segregated, 1: randomly mixed.
  Sampled every 1/20 revolution.
- escaped: grains whose centre is outside the column (its tree > 0 after inversion) or inside
  the impeller; must stay 0.
- the minimum over grains of the walls' signed distance at the grain centre (> 0: every centre
  outside every wall's solid) and the clearance (that minus the radius: < 0 is the deepest
  overlap with a wall).
- the peak grain speed over the tip speed omega * 16.

Outputs: ``results.json``, ``lacey.png`` (the mixing index against revolutions),
``snapshot.png`` (a vertical slice through the axis at the start and the end, grains coloured
by species) and the ParaView series ``stir.pvd`` + ``frames/``.

Checkpoints and resume, as the drum's (:mod:`peclet.packing.bed.checkpoint`, the format pack
runs use too): with ``checkpoint_every`` K, :func:`run_stir` keeps ``checkpoint/`` in the
output directory (after the fill, every K steps, at the end of the settle and with
``max_steps``), each step's ``sim.npz`` (the bitwise :meth:`Simulation.save`), ``state.json``
(step, clock, angle, samples, the settled bed's top) and ``arrays.npz`` (the species, the
frames kept so far), written whole then renamed; :func:`resume_stir` finishes the run bit for
bit as the uninterrupted run would, and refuses stated parameters that differ from the run's.
"""
from __future__ import annotations

import json
import math
import os
import sys
import time
from dataclasses import asdict, dataclass

import numpy as np

from peclet.core import geom
from peclet.core.files import write_json
from peclet.core.geom.transforms import quats_to_matrices
from peclet.core.spec import Float, Int, Spec, field
from peclet.core.validation import PecletArgumentError

from ..bed import checkpoint as ckpt
from .series import (Phase, check_work, fresh_checkpoint, grains_mesh, relocate, reopen,
                     run_phases, turning_clock, write_series)

__all__ = ["StirSpec", "StirredColumn", "lacey", "run_stir", "resume_stir", "checkpoint_dir",
           "read_checkpoint", "same_spec", "OUTPUTS", "OUTPUT_DIRS", "PAGE_COUNT"]

G = 9.81
#: The page's grain count at its grain radius 0.4.
PAGE_COUNT = 22_121
PAGE_RADIUS = 0.4
#: Impeller (see the module notes).
BLADES = 4
BLADE_HALF = (7.4, 0.35, 1.8)
HUB_RADIUS = 1.2
HUB_HALF_HEIGHT = 1.3
SHAFT_RADIUS = 1.0
IMPELLER_Y = 3.5
PITCH_DEG = 45.0
TIP_RADIUS = HUB_RADIUS + 2.0 * BLADE_HALF[0]
#: Lacey bins: annuli x slabs.
ANNULI, SLABS = 5, 8
#: Samples per revolution.
SAMPLES_PER_REV = 20

OUTPUTS = ("results.json", "lacey.png", "snapshot.png", "stir.pvd", "frames", "checkpoint")
OUTPUT_DIRS = ("frames", "checkpoint")
#: The checkpoint directory inside a run's output directory and its kind.
CHECKPOINT = ckpt.CHECKPOINT
_KIND = "peclet stir checkpoint"
_WHAT = "a stir run's output directory or its checkpoint/ (written by peclet stir)"


@dataclass(frozen=True)
class StirSpec(Spec):
    """A stirred-column run (see the module notes). ``count`` None: the page's fill height
    (22,121 grains at ``grain_radius`` 0.4). :meth:`checked` (from :class:`~peclet.core.spec.
    Spec`) checks every field as declared here (PecletArgumentError naming ``names[field]``)
    and resolves ``count``."""

    radius: float = field(20.0, Float(TIP_RADIUS + 1.0, 1e3))
    height: float = field(24.0, Float(2.0 * (IMPELLER_Y + 2.0), 1e3))
    grain_radius: float = field(PAGE_RADIUS, Float(0.05, 2.0))
    count: int | None = field(None, Int(1, 500_000, if_none=lambda c: int(round(
        PAGE_COUNT * (PAGE_RADIUS / c.value("grain_radius")) ** 3))))
    e: float = field(0.2, Float(0.0, 1.0))
    mu: float = field(0.5, Float(0.0, 10.0))
    dt: float = field(2e-3, Float(0.0, 0.02, lo_open=True))
    omega: float = field(1.5, Float(0.0, 100.0, lo_open=True))
    revolutions: float = field(5.0, Float(0.0, 100.0, lo_open=True))
    settle: float = field(2.0, Float(0.0, 100.0))
    seed: int = field(1, Int(0, 2 ** 63 - 1))
    frames: int = field(20, Int(0, 10_000))


def _balanced_union(b, parts):
    while len(parts) > 1:
        parts = [b.add_union(parts[j], parts[j + 1]) if j + 1 < len(parts) else parts[j]
                 for j in range(0, len(parts), 2)]
    return parts[0]


def build_trees(spec):
    """(builder, column root, impeller root) in the world frame at rest."""
    b = geom.SceneBuilder()
    R, H = spec.radius, spec.height
    cap = b.add_leaf("capsule", [R, 0.5 * H], translation=[0.0, 0.5 * H, 0.0])
    floor = b.add_leaf("half_space", [0.0, -1.0, 0.0, 0.0])          # phi = -y: y > 0 inside
    column = b.add_intersection(cap, floor)
    top = H + R
    shaft_half = 0.5 * (top - IMPELLER_Y)
    parts = [b.add_leaf("capsule", [SHAFT_RADIUS, shaft_half],
                        translation=[0.0, IMPELLER_Y + shaft_half, 0.0]),
             b.add_leaf("cone", [HUB_RADIUS, HUB_RADIUS, HUB_HALF_HEIGHT],
                        translation=[0.0, IMPELLER_Y, 0.0])]
    hp = 0.5 * math.radians(PITCH_DEG)
    rc = HUB_RADIUS + BLADE_HALF[0]
    for k in range(BLADES):
        ph = 2.0 * math.pi * k / BLADES
        # pitch about the blade's radial (x) axis, then turn the blade to azimuth ph about y
        c, s = math.cos(0.5 * ph), math.sin(0.5 * ph)
        q = [c * math.sin(hp), s * math.cos(hp), -s * math.sin(hp), c * math.cos(hp)]
        parts.append(b.add_leaf("box", list(BLADE_HALF),
                                translation=[rc * math.cos(ph), IMPELLER_Y, -rc * math.sin(ph)],
                                rotation=q))
    return b, column, _balanced_union(b, parts)


def _lattice(spec, b, impeller, rng):
    """The ``count`` lowest jittered lattice sites clear of both walls (None if too few)."""
    r = spec.grain_radius
    s = 2.25 * r
    clear = 1.25 * r
    g = np.arange(-spec.radius + clear, spec.radius - clear + 1e-12, s)
    ys = np.arange(clear, spec.height, s)
    X, Y, Z = np.meshgrid(g, ys, g, indexing="ij")
    P = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])
    P = P[P[:, 0] ** 2 + P[:, 2] ** 2 <= (spec.radius - clear) ** 2]
    P = P[b.eval_root(impeller, P) > clear]
    P = P[np.lexsort((P[:, 2], P[:, 0], P[:, 1]))]
    if len(P) < spec.count:
        return None
    P = P[:spec.count].copy()
    P += rng.uniform(-0.1 * r, 0.1 * r, P.shape)
    return P


class StirredColumn:
    """The stirred column of a checked :class:`StirSpec`: :meth:`build` fills and settles it,
    :meth:`schedule` gives the phases, :meth:`measure` reads the state."""

    def __init__(self, spec):
        self.spec = spec
        self.builder, self.column, self.impeller = build_trees(spec)
        self.sim = None

    def check_room(self, name="count", omega_name="omega"):
        """Refuse (before any work) a count the start lattice cannot hold and an impeller so
        slow its run cannot finish (:func:`~peclet.packing.experiments.series.check_work`)."""
        check_work(self.schedule(), self.spec.count or PAGE_COUNT, omega_name,
                   self.spec.omega)
        if _lattice(self.spec, self.builder, self.impeller, np.random.default_rng(0)) is None:
            raise PecletArgumentError(name, "a count the column holds on its start lattice",
                                      self.spec.count)

    def build(self):
        """The simulation with the filled column (impeller at rest); returns it."""
        from peclet.dem import Simulation

        spec, r = self.spec, self.spec.grain_radius
        rng = np.random.default_rng(spec.seed)
        P = _lattice(spec, self.builder, self.impeller, rng)
        if P is None:
            raise PecletArgumentError("count", "a count the column holds on its start "
                                      "lattice", spec.count)
        n = len(P)
        R, H = spec.radius, spec.height
        sim = Simulation(n)
        sim.set_domain([-R - 2.0, -2.0, -R - 2.0], [R + 2.0, H + R + 2.0, R + 2.0])
        sim.set_gravity(0.0, -G, 0.0)
        sim.set_material_params(spec.e, 0.0, spec.mu)
        sim.set_solver_iterations(10, 8)
        sim.add_sphere_shape(r)
        ni, nr, _, _ = self.builder.encode()
        self.column_wall = sim.add_analytic_wall(ni, nr, self.column, True, spec.e, spec.mu)
        self.impeller_wall = sim.add_analytic_wall(ni, nr, self.impeller, False, spec.e,
                                                   spec.mu)
        m = 4.0 / 3.0 * math.pi * r ** 3
        sim.set_positions(P)
        sim.set_shape_ids(np.zeros(n, np.int64))
        sim.set_inv_mass(np.full(n, 1.0 / m))
        sim.set_inv_inertia(np.full((n, 3), 1.0 / (0.4 * m * r * r)))
        sim.set_dt(spec.dt)
        self.sim = sim
        return sim

    def schedule(self):
        """[Phase]: settle (impeller still), stir."""
        spec = self.spec
        per_rev = 2.0 * math.pi / spec.omega / spec.dt
        return [Phase("settle", 0.0, int(math.ceil(spec.settle / spec.dt))),
                Phase("stir", spec.omega, int(math.ceil(spec.revolutions * per_rev)))]

    def turn(self, omega):
        self.sim.set_wall_velocity(self.impeller_wall, angular=(0.0, float(omega), 0.0))

    def step(self):
        self.sim.step(self.spec.dt)

    def label(self):
        """Fix the species (lower / upper half by height) and the Lacey bins' slab top from
        the current (settled) state."""
        X = self.sim.get_positions()
        n = len(X)
        order = np.lexsort((np.arange(n), X[:, 1]))
        self.species = np.zeros(n, np.int8)
        self.species[order[n // 2:]] = 1
        self.bed_top = float(X[:, 1].max() + self.spec.grain_radius)

    def wall_distances(self, X):
        """(column distance, impeller distance) at world points X: each wall's signed
        distance with its solid negative (the column's tree inverted), the impeller's tree
        read at its current pose."""
        b = self.builder
        d_col = -b.eval_root(self.column, X)
        t, q = self.sim.get_wall_transform(self.impeller_wall)
        Rm = quats_to_matrices(q[None, :])[0]
        d_imp = b.eval_root(self.impeller, (X - t) @ Rm)       # R^T (p - t), row-wise
        return d_col, d_imp

    def measure(self):
        """One sample of the current state (see the module notes)."""
        sim, spec = self.sim, self.spec
        X = sim.get_positions()
        V = sim.get_velocities()
        d_col, d_imp = self.wall_distances(X)
        d = np.minimum(d_col, d_imp)
        speed = np.sqrt((V * V).sum(1))
        return dict(lacey=lacey(X, self.species, spec.radius, self.bed_top),
                    escaped=int(np.count_nonzero((d_col <= 0.0) | (d_imp <= 0.0))),
                    min_wall_sdf=float(d.min()),
                    min_clearance=float(d.min() - spec.grain_radius),
                    peak_speed=float(speed.max()))


def lacey(X, species, radius, top, annuli=ANNULI, slabs=SLABS):
    """Lacey's mixing index of the two ``species`` (0/1 per grain) over ``annuli`` equal-area
    annuli (out to ``radius`` about the y axis) times ``slabs`` equal slabs of [0, ``top``]
    (grains beyond the outer annulus or the top slab count in the outermost / top one).
    Returns NaN when one species is absent (the index is undefined)."""
    n = len(X)
    p = float(np.mean(species))
    if n == 0 or p in (0.0, 1.0):
        return math.nan
    rho2 = (X[:, 0] ** 2 + X[:, 2] ** 2) / (radius * radius)
    ia = np.clip(np.floor(rho2 * annuli).astype(np.int64), 0, annuli - 1)
    js = np.clip(np.floor(X[:, 1] / top * slabs).astype(np.int64), 0, slabs - 1)
    b = ia * slabs + js
    cnt = np.bincount(b, minlength=annuli * slabs).astype(np.float64)
    up = np.bincount(b, weights=species.astype(np.float64), minlength=annuli * slabs)
    occ = cnt > 0
    frac = up[occ] / cnt[occ]
    s2 = float(np.sum(cnt[occ] * (frac - p) ** 2) / n)
    s0 = p * (1.0 - p)
    sr = s0 / (n / np.count_nonzero(occ))
    return (s0 - s2) / (s0 - sr)


# ---------------------------------------------------------------------------- the run
def run_stir(spec, out=None, progress=True, figures=True, threads=None, previous=(),
             checkpoint_every=None, max_steps=None, keep_checkpoint=False):
    """Run a stirred column (``spec`` a :class:`StirSpec`, checked here); returns the results
    dict and with ``out`` writes the outputs there (see the module notes).

    ``checkpoint_every`` (steps, needs ``out``): keep ``out/checkpoint/`` (see the module
    notes); :func:`resume_stir` finishes an interrupted run bit for bit. The earlier run's
    outputs ``previous`` are removed when such a run starts and the checkpoint when it ends
    (unless ``keep_checkpoint``). ``max_steps``: stop after this many steps in all (needs
    ``checkpoint_every``) and return ``{"complete": False, "steps_done": k, "checkpoint":
    path}``."""
    if threads is not None:
        from ..bed.threads import set_threads
        set_threads(threads)
    spec = spec.checked()
    every, max_steps = ckpt.check_every(out, checkpoint_every, max_steps)
    col = StirredColumn(spec)           # build() refuses a count the lattice cannot hold
    t0 = time.perf_counter()
    cdir, previous = fresh_checkpoint(out, previous, every, "stir")
    col.build()
    st = dict(k=0, t=0.0, t_begin=col.sim.time, angle=0.0, samples=[], frames=[], seconds=0.0,
              run=ckpt.new_run(), checkpoint_every=every)
    if cdir is not None:
        st["seconds"] = time.perf_counter() - t0
        _checkpoint_write(cdir, col, st)
    return _stir(col, st, out, progress, figures, previous, every, max_steps, cdir,
                 keep_checkpoint, t0)


def resume_stir(path, out=None, progress=True, figures=True, threads=None, previous=(),
                checkpoint_every=None, max_steps=None, keep_checkpoint=False, given=None,
                names=None):
    """Finish the stir run checkpointed in ``path`` (a run's output directory or its
    ``checkpoint/``), bit for bit as the uninterrupted run would, and return its results
    dict; ``out`` (default: the run's own directory) takes the outputs. ``given``: a dict of
    :class:`StirSpec` fields the caller states: one that differs from the run's is refused,
    the error naming ``names[field]``. ``checkpoint_every`` None: as the run had it. The other
    arguments as :func:`run_stir`'s."""
    from peclet.dem import Simulation

    r = reopen(path, out, given, names, threads, checkpoint_every, max_steps,
               checkpoint_dir, read_checkpoint, same_spec)
    saved, st, arrays, out, every, max_steps = (r.spec, r.state, r.arrays, r.out, r.every,
                                                r.max_steps)
    t0 = time.perf_counter()
    col = StirredColumn(saved)
    col.sim = Simulation.load(r.sim_path)
    col.column_wall, col.impeller_wall = int(st["column_wall"]), int(st["impeller_wall"])
    if "species" in arrays:
        col.species, col.bed_top = arrays["species"], float(st["bed_top"])
    st["frames"] = [dict(t=float(t), X=X, V=V, angle=float(a)) for t, X, V, a in
                    zip(*(arrays[f"frames_{k}"] for k in ("t", "X", "V", "angle")))] \
        if "frames_t" in arrays else []
    cdir = relocate(out, r.cdir, previous, every, lambda c: _checkpoint_write(c, col, st))
    return _stir(col, st, out, progress, figures, (), every, max_steps, cdir,
                 keep_checkpoint, t0 - st["seconds"])


class _Stop(Exception):
    """max_steps reached (the checkpoint is written)."""


def _stir(col, st, out, progress, figures, previous, every, max_steps, cdir, keep_checkpoint,
          t0):
    """Run the column from the state ``st`` (step k, clock, angle, what was observed so far)
    to the end of its schedule, observing and checkpointing; returns the results."""
    from ..bed.progress import Progress, ms_per_step

    spec, sim = col.spec, col.sim
    sched = col.schedule()
    total = sum(ph.steps for ph in sched)
    ends = set(np.cumsum([ph.steps for ph in sched]).tolist())
    bar = Progress(total, desc="stir", enabled=progress, initial=min(st["k"], total))
    settle_steps = sched[0].steps
    per_rev = sched[1].steps / max(spec.revolutions, 1e-300)
    every_sample = max(1, int(round(per_rev / SAMPLES_PER_REV)))
    frame_at = {settle_steps + max(1, int(round(sched[1].steps * i / max(spec.frames - 1, 1))))
                for i in range(spec.frames)} if spec.frames else set()
    samples, frames, first = st["samples"], st["frames"], [None]
    stop_at = max_steps

    def observe(k, t, angle, phase):
        if k == 1:
            first[0] = time.perf_counter() - t0
        if k == settle_steps:
            col.label()
        if phase.name == "stir" and (k - settle_steps) % every_sample == 0 or \
                k == settle_steps:
            s = col.measure()
            s.update(t=t, revolutions=angle / (2.0 * math.pi))
            samples.append(s)
        if k in frame_at or k == settle_steps and spec.frames:
            frames.append(dict(t=t, X=sim.get_positions(), V=sim.get_velocities(),
                               angle=angle))
        if every is not None and (k % every == 0 or k in ends or k == stop_at):
            st.update(k=k, t=t, angle=angle, seconds=time.perf_counter() - t0)
            _checkpoint_write(cdir, col, st)
        if k == stop_at:
            raise _Stop

    if settle_steps == 0 and st["k"] == 0:
        col.label()
    if stop_at is not None and st["k"] >= stop_at:
        bar.close()
        return dict(complete=False, steps_done=st["k"], checkpoint=cdir)
    try:
        run_phases(sched, spec.dt, col.step, col.turn, turning_clock(sim, st), observe,
                   bar,
                   start=(st["k"], st["angle"]))
    except _Stop:
        bar.close()
        return dict(complete=False, steps_done=stop_at, checkpoint=cdir)
    except KeyboardInterrupt:
        bar.close()
        if cdir is not None and os.path.isfile(os.path.join(cdir, ckpt.POINTER)):
            with open(os.path.join(cdir, ckpt.POINTER)) as fh:
                k = json.load(fh).get("step")
            print(f"stir: interrupted; the checkpoint at step {k} of {total} resumes it "
                  f"(peclet stir --resume {os.path.dirname(cdir)})", file=sys.stderr)
        raise
    bar.close()
    seconds = time.perf_counter() - t0
    tip = spec.omega * TIP_RADIUS
    res = dict(spec=asdict(spec), grains=spec.count, tip_speed=tip, steps=total,
               settle_steps=settle_steps, sample_every=every_sample,
               lacey_start=samples[0]["lacey"] if samples else math.nan,
               lacey_end=samples[-1]["lacey"] if samples else math.nan,
               escaped_max=max((s["escaped"] for s in samples), default=0),
               min_wall_sdf=min((s["min_wall_sdf"] for s in samples), default=math.nan),
               min_clearance=min((s["min_clearance"] for s in samples), default=math.nan),
               peak_speed_over_tip=max((s["peak_speed"] for s in samples),
                                       default=math.nan) / tip if tip else math.nan,
               state_hash=sim.state_hash(), seconds=seconds,
               ms_per_step=ms_per_step(seconds, first[0] or 0.0, total),
               samples=samples)
    if out is not None:
        _write(out, res, col, frames, figures, previous)
        if cdir is not None and not keep_checkpoint:
            ckpt.remove(cdir, own=())
    return res


# ---------------------------------------------------------------------------- checkpoints
def checkpoint_dir(path, name="path"):
    """The checkpoint directory of a stir run at ``path`` (its output directory or the
    ``checkpoint/`` in it); PecletArgumentError naming ``name`` if there is none."""
    return ckpt.find(path, name, _WHAT)


def _checkpoint_write(cdir, col, st):
    state = dict(t=st["t"], t_begin=st["t_begin"], angle=st["angle"], seconds=st["seconds"],
                 checkpoint_every=st.get("checkpoint_every"), column_wall=col.column_wall,
                 impeller_wall=col.impeller_wall, samples=st["samples"],
                 bed_top=getattr(col, "bed_top", None))
    arrays = {}
    if getattr(col, "species", None) is not None:
        arrays["species"] = col.species
    if st["frames"]:
        arrays.update(frames_t=np.array([f["t"] for f in st["frames"]], np.float64),
                      frames_angle=np.array([f["angle"] for f in st["frames"]], np.float64),
                      frames_X=np.stack([f["X"] for f in st["frames"]]),
                      frames_V=np.stack([f["V"] for f in st["frames"]]))
    ckpt.write_loop_step(cdir, _KIND, asdict(col.spec), st["run"], st["k"], col.sim, state,
                         arrays)


def read_checkpoint(cdir, name="path"):
    """(checked spec, state dict, arrays dict, path of ``sim.npz``) of the latest step of the
    checkpoint directory ``cdir``; anything else: PecletArgumentError naming ``name``."""
    return ckpt.read_loop_step(cdir, _KIND, "stir", name, _WHAT,
                               lambda d: StirSpec(**d).checked())


def same_spec(saved, given, names=None):
    """Refuse ``given`` (a dict of :class:`StirSpec` fields) unless the run's checked spec
    ``saved`` has them: the error names the first differing field (``names[field]``)."""
    nm = lambda f: (names or {}).get(f, f)  # noqa: E731
    base = asdict(saved)
    unknown = set(given) - set(base)
    if unknown:
        raise PecletArgumentError("given", "StirSpec fields", sorted(unknown))
    new = asdict(StirSpec(**dict(base, **given)).checked(names))
    for k in base:
        if base[k] != new[k]:
            raise PecletArgumentError(nm(k), f"the resumed run's {getattr(saved, k)!r} (a "
                                      "resumed run keeps its parameters: leave the option "
                                      "out, or start a new run)", given.get(k, new[k]))


def _write(out, res, col, frames, figures, previous):
    from peclet.core.outputs import clear_outputs

    os.makedirs(out, exist_ok=True)
    clear_outputs(out, previous)
    files = ["results.json"]
    if frames:
        _write_frames(out, col, frames)
        files += ["stir.pvd", "frames/"]
    if figures:
        _lacey_figure(os.path.join(out, "lacey.png"), res)
        _snapshot_figure(os.path.join(out, "snapshot.png"), col, frames)
        files += ["lacey.png", "snapshot.png"]
    res["files"] = files
    write_json(os.path.join(out, "results.json"), res)


def _write_frames(out, col, frames):
    spec = col.spec
    th = np.linspace(0.0, 2.0 * np.pi, 97)[:-1]
    rims = [np.column_stack([spec.radius * np.cos(th), np.full(96, y),
                             spec.radius * np.sin(th)]) for y in (0.0, spec.height)]
    r = np.full(spec.count, spec.grain_radius)

    def mesh_of(f):
        X, V = f["X"], f["V"]
        a = f["angle"]
        tips = [np.array([[0.0, IMPELLER_Y, 0.0],
                          [TIP_RADIUS * math.cos(a + ph), IMPELLER_Y,
                           -TIP_RADIUS * math.sin(a + ph)]])
                for ph in 2.0 * np.pi * np.arange(BLADES) / BLADES]
        return grains_mesh(X, {"radius": r, "velocity": V, "speed": np.sqrt((V * V).sum(1)),
                               "species": col.species.astype(np.int32)}, rims + tips)

    write_series(out, "stir", frames, mesh_of)


def _lacey_figure(path, res):
    from peclet.core.figures import save_png, subplots

    s = res["samples"]
    fig, ax = subplots(figsize=(6, 3.2))
    ax.plot([x["revolutions"] for x in s], [x["lacey"] for x in s], "-", color="C0")
    ax.set_xlabel("impeller revolutions")
    ax.set_ylabel("Lacey mixing index")
    ax.set_ylim(-0.05, 1.05)
    ax.set_title(f"{res['grains']} grains, omega {res['spec']['omega']:g}: "
                 f"{res['lacey_start']:.3f} -> {res['lacey_end']:.3f}", fontsize=10)
    fig.tight_layout()
    save_png(fig, path, dpi=110)


def _snapshot_figure(path, col, frames):
    from peclet.core.figures import save_png, subplots
    from matplotlib.collections import PatchCollection
    from matplotlib.patches import Circle

    spec = col.spec
    pick = [frames[0], frames[-1]] if frames else []
    fig, axes = subplots(1, max(1, len(pick)), figsize=(4.0 * max(1, len(pick)), 3.6),
                             squeeze=False)
    for ax, f in zip(axes[0], pick):
        X = f["X"]
        sl = np.nonzero(np.abs(X[:, 2]) < spec.grain_radius)[0]    # grains the plane z = 0 cuts
        rr = np.sqrt(np.maximum(spec.grain_radius ** 2 - X[sl, 2] ** 2, 0.0))
        pc = PatchCollection([Circle((x, y), r) for (x, y), r in zip(X[sl, :2], rr)],
                             cmap="coolwarm")
        pc.set_array(col.species[sl].astype(float))
        pc.set_clim(0, 1)
        ax.add_collection(pc)
        ax.plot([-spec.radius, -spec.radius, spec.radius, spec.radius],
                [spec.height, 0, 0, spec.height], "k-", lw=1)
        ax.set_xlim(-1.05 * spec.radius, 1.05 * spec.radius)
        ax.set_ylim(-1.0, spec.height + 1.0)
        ax.set_aspect("equal")
        ax.set_title(f"t = {f['t']:.2f}, rev {f['angle'] / (2 * math.pi):.2f} (slice z = 0; "
                     "blue: lower half at the start)", fontsize=8)
    fig.tight_layout()
    save_png(fig, path, dpi=110)
