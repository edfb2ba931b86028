"""A rotating drum: the dynamic angle of repose, the flow regime, snapshots (issue 22, item 4).

Geometry and units. Lengths in element diameters D (a sphere's mean diameter, a library
element's D), gravity 9.81 D/time^2 along -y, the drum's axis along z through the origin.
The drum is a closed cylinder of radius R and length L (an inverted ``cone`` leaf, turned from
its native y axis onto z), or with ``ends="periodic"`` a cylinder much longer than the periodic
cell [-L/2, L/2) in z (no end caps: a slice of a long drum). The drum turns counter-clockwise
seen from +z at omega = sqrt(Fr g / R) (``froude``), or at ``rpm`` for a grain of ``grain_mm``
millimetres (Fr = omega^2 R_m / g with R_m = R * grain_mm / 1000 m): the bed climbs the +x side,
so the free surface rises towards +x and the dynamic angle is atan of its slope.

Wall: ``ribs`` boxes along the axis (default one per 1.25 D of circumference, 0.25 D high,
0.2 D wide) make it rough: frictional spheres, which cannot resist rolling, otherwise roll on
a smooth wall like a ball bearing and the bed slips (measured: the wall layer turned at
0.6-0.9 omega with wall friction 1.0; with the ribs at 0.99 omega). ``ribs=0``: smooth.

Protocol (:class:`Drum`). Fill: ``count`` grains (from ``fill``, the bed's share of the drum's
volume at a packing fraction of 0.52 for spheres (a thin drum packs loosely) or 0.55 of the
envelope for elements; the measured fill is reported) on a jittered
lattice in the drum's lower part (the lowest lattice sites), random orientations; ``relax``
removes the overlaps; settle (until the kinetic energy per grain is below 1e-4 m g D, at most
4000 steps). Turn: ``spinup`` degrees at Fr = 1e-2 (optional: a slow run then starts from a
sheared, inclined bed instead of the flat settled one), ``warmup`` revolutions at the target
speed, then ``revolutions`` measured. The wall turns by ``Simulation.set_wall_velocity`` (the
pose advances every step); nothing else acts on the grains.

Measurement (:func:`measure`, every ``sample_every`` steps, reading the state only, so the run's
bits do not depend on it). Grains in the axial window (caps: farther than 1 D from either cap
when L > 3 D; periodic: all) are binned in columns of width 1 D along x. In each column the bed
is the run of grains climbing from the lowest one while the vertical gap between neighbours
stays <= 1.5 D; its top (centre + radius of the last grain) is the column's surface point.
Surface points within 1.5 D of the drum's wall are dropped, and the rest (at least 4) fitted by
a line: the angle. A cubic through the same points gives the surface's S-shape: its largest
departure from the line (``s_shape``, in R). Per sample also: ``airborne`` (the share of grains
above their column's bed, more than 1.5 D from the wall: in free flight), ``flowing`` (the share
moving relative to the drum's rigid rotation by more than 0.1 sqrt(g D)), ``corotating`` (the
share whose angular velocity about the axis is within 10 % of omega) and ``coverage`` (the
share of 36 angular sectors holding a grain within 2.5 D of the wall; reported only) and
``high`` (the share of grains above y = R / 2: none in a tumbling bed of fill <= 0.5, a third
of a ring on the wall).

Regime (:func:`classify`, over the measured samples), first match wins (a bed of fewer than
:data:`MIN_GRAINS` grains has no free surface to classify: :meth:`Drum.check_room` refuses
such a fill, and :func:`classify` given the grain count calls it "undetermined"):

- centrifuging: corotating >= 0.9 and high >= 0.15 (the bed turns with the drum and is
  carried over the top: a ring stuck to the wall);
- cataracting: airborne >= 0.01 (grains thrown off the bed);
- slumping: >= 20 % of the samples at rest in the drum (flowing < 0.02): the bed turns as a
  body, then avalanches;
- cascading: mean s_shape >= 0.035 R (a curved, S-shaped surface);
- rolling: a steady flat surface.

Mellmann's map (Powder Technol. 118 (2001) 251-270, Table 1; fill > 0.1, wall friction
above the slip limit) gives the Froude ranges :data:`MELLMANN`: slumping 1e-5..1e-3,
rolling 1e-4..1e-2, cascading 1e-3..1e-1, cataracting 0.1..1, centrifuging >= 1.

Results: ``results.json``, ``snapshots.png`` (cross-sections at a few times, grains coloured by
speed, the fitted surface), ``angle.png`` (angle against revolutions), and a ParaView time
series ``drum.pvd`` indexing ``frames/frame_NNNN.vtu`` (grain centres as vertices with radius,
velocity, speed, speed relative to the drum, shape id; plus the drum's rim circles as lines).
Every file is written atomically (:mod:`peclet.core.files`).

Checkpoints and resume. With ``checkpoint_every`` K, :func:`run_drum` keeps
``checkpoint/`` in the output directory, in the run-checkpoint format pack runs use
(:mod:`peclet.packing.bed.checkpoint`: ``spec.json``, ``ckpt-<k>/`` with ``run.json``,
``checkpoint.json``): after the settle, every K turning steps and at each phase's end it writes
``ckpt-<k>/`` (``sim.npz``, the bitwise :meth:`Simulation.save`; ``state.json``, the loop's
step, clock, angle and the samples so far; ``arrays.npz``, the grain radii and the frames and
snapshots kept so far) into a temporary directory renamed into place, then replaces
``checkpoint.json`` and removes the older step: an interrupt at any moment leaves a complete
checkpoint. A checkpoint of the earlier drum format (``step-<k>/``, the spec in
``checkpoint.json``) is still read, and a run resumed from it goes on in the shared format. :func:`resume_drum`
loads it and goes on from step k (:func:`~peclet.packing.experiments.series.run_phases` with ``start``):
the results, the state hash included, are those of the uninterrupted run. It refuses a
directory that is not a drum run's, parts of two runs, and stated parameters that differ
from the run's.

The phase loop (turn the wall at each phase's speed, count steps, keep the angle) and the
ParaView writer are shared with the stirred column (:mod:`peclet.packing.experiments.series`); the pour
protocols' kick/quench/settle base (:mod:`peclet.packing.bed.protocols`) does not fit a run whose
only driver is a turning wall, so the drum does not subclass it.
"""
from __future__ import annotations

import json
import math
import os
import sys
import time
from dataclasses import asdict

import numpy as np

from peclet.core import geom
from peclet.core.validation import PecletArgumentError

from ..bed import checkpoint as ckpt
from .regimes import (MELLMANN, MIN_GRAINS, SURFACE_POINTS, angle_stats,  # noqa: F401 (API)
                      classify, expected_regimes, measure)
from .drum_output import write_outputs
from .drum_spec import (ENDS, RIB_HALF_WIDTH, RIB_HEIGHT, RIB_SPACING,  # noqa: F401 (API)
                        DrumSpec, froude_of_rpm, rpm_of_froude)
from .series import (Phase, check_work, fresh_checkpoint, relocate, reopen,
                     run_phases, turning_clock)

__all__ = ["DrumSpec", "Drum", "measure", "classify", "MELLMANN", "MIN_GRAINS", "G",
           "froude_of_rpm",
           "rpm_of_froude", "run_drum", "resume_drum", "checkpoint_dir", "read_checkpoint",
           "same_spec", "OUTPUTS",
           "add_drum_wall"]

from .regimes import G  # noqa: E402 (the one value, re-exported)


#: Spin-up Froude number (a rolling bed).
SPINUP_FROUDE = 1e-2

#: What a run writes into its output directory.
OUTPUTS = ("results.json", "snapshots.png", "angle.png", "drum.pvd", "frames", "checkpoint")
OUTPUT_DIRS = ("frames", "checkpoint")
#: The checkpoint directory inside a run's output directory, its pointer file and kind.
CHECKPOINT = ckpt.CHECKPOINT
POINTER = ckpt.POINTER
_KIND = "peclet drum checkpoint"
_WHAT = "a drum run's output directory or its checkpoint/ (written by peclet drum)"



def _grains(spec):
    """(register(sim) -> shape ids, radii of the classes (D), bounding radius r_b, volume per
    grain (mean, D^3), envelope volume per grain, mass per class, inv inertia per class (k, 3),
    name)."""
    if spec.element == "sphere":
        p = spec.polydispersity
        radii = [0.5] if p == 0.0 else [0.5 * (1 - p), 0.5, 0.5 * (1 + p)]
        vols = [4.0 / 3.0 * math.pi * r ** 3 for r in radii]
        inv_i = [np.full(3, 1.0 / (0.4 * v * r * r)) for r, v in zip(radii, vols)]
        reg = lambda sim: [sim.add_sphere_shape(r) for r in radii]  # noqa: E731
        v = float(np.mean(vols))
        return dict(register=reg, radii=np.array(radii), r_b=max(radii), volume=v, envelope=v,
                    mass=np.array(vols), inv_inertia=np.array(inv_i), d=1.0, name="sphere")
    from ..bed.api import resolve_element, element_model

    m = element_model(resolve_element(spec.element))
    d = float(m.d)
    env = m.envelope_volume if np.isfinite(m.envelope_volume) else m.volume
    return dict(register=lambda sim: [m.register(sim)], radii=np.array([m.bounding_radius / d]),
                r_b=m.bounding_radius / d, volume=m.volume / d ** 3, envelope=env / d ** 3,
                mass=np.array([m.mass]), inv_inertia=np.array([m.inv_inertia]), d=d,
                name=m.name)


def _lattice(spec, r_b, count, rng):
    """Jittered lattice sites in the drum's lower part: the ``count`` lowest of a cubic
    lattice of spacing 2.04 r_b inside the drum (clear of the wall by r_b), jittered by
    +-0.15 of the spacing in x and y (``relax`` then removes overlaps)."""
    R, L = spec.radius, spec.length
    s = 2.04 * r_b
    rin = R - r_b - 0.02
    if spec.ends == "periodic":
        nz = max(1, int(math.floor(L / s)))
        zs = -0.5 * L + (np.arange(nz) + 0.5) * (L / nz)
    else:
        half = 0.5 * L - r_b - 0.02
        if half < 0:
            zs = np.array([0.0])
        else:
            nz = int(math.floor(2 * half / s)) + 1
            zs = np.linspace(-half, half, nz) if nz > 1 else np.array([0.0])
    g = np.arange(-rin, rin + 1e-12, s)
    X, Y, Z = np.meshgrid(g, g, zs, indexing="ij")
    P = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])
    P = P[P[:, 0] ** 2 + P[:, 1] ** 2 <= rin * rin]
    order = np.lexsort((P[:, 2], P[:, 0], P[:, 1]))
    P = P[order]
    if len(P) < count:
        return None
    P = P[:count].copy()
    P[:, :2] += rng.uniform(-0.15 * s, 0.15 * s, size=(count, 2))
    return P


def add_drum_wall(sim, spec, d):
    """Add the drum (inverted cylinder along z) to ``sim``; returns the wall index."""
    R, L = spec.radius * d, spec.length * d
    half = 0.5 * L if spec.ends == "caps" else 4.0 * L + 2.0 * R
    b = geom.SceneBuilder()
    s = math.sqrt(0.5)
    root = b.add_leaf("cone", [R, R, half], rotation=[s, 0.0, 0.0, s])   # y -> z
    k = spec.ribs
    if k:
        ribs = []
        for i in range(k):
            ph = 2.0 * math.pi * (i + 0.5) / k
            ribs.append(b.add_leaf("box", [RIB_HEIGHT * d, RIB_HALF_WIDTH * d, half],
                                   translation=[R * math.cos(ph), R * math.sin(ph), 0.0],
                                   rotation=[0.0, 0.0, math.sin(0.5 * ph),
                                             math.cos(0.5 * ph)]))
        while len(ribs) > 1:                     # a balanced union
            ribs = [b.add_union(ribs[j], ribs[j + 1]) if j + 1 < len(ribs) else ribs[j]
                    for j in range(0, len(ribs), 2)]
        root = b.add_difference(root, ribs[0])
    ni, nr, _, _ = b.encode()
    return sim.add_analytic_wall(ni, nr, root, True, spec.wall_e, spec.wall_mu)


def grain_count(spec, grains):
    """Grains for the fill: fill * drum volume * packing fraction / grain volume."""
    phi = 0.52 if spec.element == "sphere" else 0.55
    vol = math.pi * spec.radius ** 2 * spec.length
    return max(1, int(round(spec.fill * vol * phi / grains["envelope"])))


class Drum:
    """The drum run of a checked :class:`DrumSpec`: :meth:`build` (a settled bed in a resting
    drum), then :meth:`advance` phase by phase; :meth:`schedule` gives the phases' steps."""

    def __init__(self, spec):
        self.spec = spec
        self.grains = _grains(spec)
        self.count = grain_count(spec, self.grains)
        self.d = self.grains["d"]
        om = spec.omega
        if spec.dt is not None:
            self.dt = spec.dt
        else:
            base = 4e-3 if spec.element == "sphere" else 2e-3
            self.dt = min(base, 0.05 / (om * spec.radius))
        self.omega = om        # g = 9.81 D/time^2 in world lengths: omega and dt keep
        self.sim = None
        self.wall = None

    # ------------------------------------------------------------------ setup
    def check_room(self, name="fill", length_name="length", speed_name="froude",
                   speed_given=None):
        """Refuse (before any work) a drum shorter than a grain, a fill of fewer than
        :data:`MIN_GRAINS` grains (no bed to classify), a fill its start lattice cannot hold,
        and a speed so slow the run's turning steps cannot finish
        (:func:`~peclet.packing.experiments.series.check_work`; the error names ``speed_name`` and shows
        ``speed_given``, default the Froude number)."""
        check_work(self.schedule(), self.count, speed_name,
                   self.spec.froude if speed_given is None else speed_given)
        if self.spec.ends == "caps" and self.spec.length < 2.0 * self.grains["r_b"] + 0.05:
            raise PecletArgumentError(length_name, f"at least a grain's bounding diameter "
                                      f"+ 0.05 D ({2.0 * self.grains['r_b'] + 0.05:.3g} D)",
                                      self.spec.length)
        if self.count < MIN_GRAINS:
            raise PecletArgumentError(
                name, f"a fill of at least {MIN_GRAINS} grains (a bed with a free surface: its "
                f"fit takes {SURFACE_POINTS} column tops 1 D wide, each over a grain beneath "
                "it)", self.spec.fill,
                f"{self.count} grain{'s' if self.count != 1 else ''} in a drum of radius "
                f"{self.spec.radius:g} D and length {self.spec.length:g} D: no regime to "
                "classify; fill more, or a larger drum")
        rng = np.random.default_rng(0)
        if _lattice(self.spec, self.grains["r_b"], self.count, rng) is None:
            raise PecletArgumentError(name, "a fill the drum holds on its start lattice",
                                      self.spec.fill, f"{self.count} grains do not fit")

    def build(self, settle_max=4000):
        """The simulation with the settled bed (returns it; also ``self.sim``)."""
        from peclet.dem import Simulation

        spec, gr, d = self.spec, self.grains, self.d
        rng = np.random.default_rng(spec.seed)
        P = _lattice(spec, gr["r_b"], self.count, rng)
        if P is None:
            raise PecletArgumentError("fill", "a fill the drum holds on its start lattice",
                                      spec.fill, f"{self.count} grains do not fit")
        n = len(P)
        cls = rng.integers(0, len(gr["radii"]), n)
        Q = rng.normal(size=(n, 4)) if spec.element != "sphere" else \
            np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
        Q /= np.linalg.norm(Q, axis=1)[:, None]
        sim = Simulation(n + 8)
        R, L = spec.radius * d, spec.length * d
        if spec.ends == "periodic":
            sim.set_domain([-R - 2 * d, -R - 2 * d, -0.5 * L], [R + 2 * d, R + 2 * d, 0.5 * L])
            sim.enable_periodicity(False, False, True)
        else:
            sim.set_domain([-R - 2 * d, -R - 2 * d, -0.5 * L - 2 * d],
                           [R + 2 * d, R + 2 * d, 0.5 * L + 2 * d])
        sim.set_gravity(0.0, -G * d, 0.0)
        sim.set_material_params(spec.e, 0.0, spec.mu)
        sim.set_solver_iterations(10, 8)
        sids = np.asarray(gr["register"](sim), np.int32)
        self.wall = add_drum_wall(sim, spec, d)
        sim.set_positions(P * d)
        sim.set_shape_ids(sids[cls])
        sim.set_quaternions(Q)
        sim.set_inv_mass(1.0 / gr["mass"][cls])
        sim.set_inv_inertia(gr["inv_inertia"][cls])
        sim.set_dt(self.dt)
        sim.relax(50)
        self.radii = gr["radii"][cls] * d if spec.element == "sphere" else \
            np.full(n, 0.5 * d)
        mg = float(np.mean(gr["mass"][cls])) * G * d * d
        steps = 0
        while steps < settle_max:
            for _ in range(50):
                sim.step(self.dt)
            steps += 50
            if steps >= 100 and sim.kinetic_energy() / (n * mg) < 1e-4:
                break
        self.settle_steps = steps
        self.sim = sim
        return sim

    # ------------------------------------------------------------------ schedule
    def schedule(self):
        """[:class:`~peclet.packing.experiments.series.Phase`]: spin-up (if any), warm-up, measure."""
        spec, out = self.spec, []
        if spec.spinup > 0:
            om_s = max(self.omega, math.sqrt(SPINUP_FROUDE * G / spec.radius))
            out.append(Phase("spinup", om_s, int(math.ceil(math.radians(spec.spinup) / om_s
                                                           / self.dt))))
        per_rev = 2.0 * math.pi / self.omega / self.dt
        out.append(Phase("warmup", self.omega, int(math.ceil(spec.warmup * per_rev))))
        out.append(Phase("measure", self.omega,
                         max(1, int(math.ceil(spec.revolutions * per_rev)))))
        return out

    def sample_every(self):
        """Steps between samples: 1/90 revolution, at most 0.25 time units, at least 1."""
        t_rev = 2.0 * math.pi / self.omega
        return max(1, int(round(min(t_rev / 90.0, 0.25) / self.dt)))

    def turn(self, omega):
        self.sim.set_wall_velocity(self.wall, angular=(0.0, 0.0, float(omega)))

    def step(self, k=1):
        for _ in range(k):
            self.sim.step(self.dt)

    def turned(self):
        """Angle the drum has turned by (rad), from its pose."""
        _, q = self.sim.get_wall_transform(self.wall)
        return 2.0 * math.atan2(q[2], q[3])


# ---------------------------------------------------------------------------- measurement
def run_drum(spec, out=None, progress=True, figures=True, threads=None, previous=(),
             checkpoint_every=None, max_steps=None, keep_checkpoint=False):
    """Run a drum (``spec`` a :class:`DrumSpec`, checked here) and return its results dict;
    with ``out`` write the outputs there (see the module notes).

    ``checkpoint_every`` (steps, needs ``out``): write ``out/checkpoint/`` every K turning
    steps and at every phase boundary (the settled bed, each phase's end), each one whole or
    not at all; :func:`resume_drum` finishes an interrupted run bit for bit as the
    uninterrupted run would. The earlier run's outputs ``previous`` are removed when such a
    run starts (its checkpoint takes their place) and the checkpoint when it ends (unless
    ``keep_checkpoint``). ``max_steps``: stop after this many turning steps in all (needs
    ``checkpoint_every``) and return ``{"complete": False, "steps_done": k, "checkpoint":
    path}``."""
    if threads is not None:
        from ..bed.threads import set_threads
        set_threads(threads)
    spec = spec.checked()
    every, max_steps = ckpt.check_every(out, checkpoint_every, max_steps)
    drum = Drum(spec)
    drum.check_room()
    t0 = time.perf_counter()
    cdir, previous = fresh_checkpoint(out, previous, every, "drum")
    drum.build()
    st = dict(k=0, t=0.0, t_begin=drum.sim.time, angle=0.0, samples=[], frames=[], snaps=[],
              seconds=0.0, run=ckpt.new_run(), checkpoint_every=every)
    st["seconds"] = time.perf_counter() - t0
    if cdir is not None:
        _checkpoint_write(cdir, spec, drum, st)
    return _turn(drum, st, out, progress, figures, previous, every, max_steps, cdir,
                 keep_checkpoint, time.perf_counter() - st["seconds"])


def resume_drum(path, out=None, progress=True, figures=True, threads=None, previous=(),
                checkpoint_every=None, max_steps=None, keep_checkpoint=False, given=None,
                names=None):
    """Finish the drum run checkpointed in ``path`` (a run's output directory or its
    ``checkpoint/``), bit for bit as the uninterrupted run would, and return its results
    dict; ``out`` (default: the run's own directory) takes the outputs. ``given``: a dict of
    :class:`DrumSpec` fields the caller states (e.g. the options given on the command line):
    each is checked, and one that differs from the run's is refused (a resumed run keeps its
    parameters), the error naming ``names[field]``. ``checkpoint_every`` None: as the run had
    it. The other arguments as :func:`run_drum`'s. PecletArgumentError naming ``path`` (or
    ``names["resume"]``) if it is not a drum run's checkpoint."""
    r = reopen(path, out, given, names, threads, checkpoint_every, max_steps,
               checkpoint_dir, read_checkpoint, same_spec)
    saved, st, arrays, out, every, max_steps = (r.spec, r.state, r.arrays, r.out, r.every,
                                                r.max_steps)
    from peclet.dem import Simulation

    t0 = time.perf_counter()
    drum = Drum(saved)
    drum.sim = Simulation.load(r.sim_path)
    drum.wall = int(st["wall"])
    drum.settle_steps = int(st["settle_steps"])
    drum.radii = arrays["radii"]
    st["frames"] = _frames_of(arrays, "frames")
    st["snaps"] = _frames_of(arrays, "snaps")
    cdir = relocate(out, r.cdir, previous, every,
                    lambda c: _checkpoint_write(c, saved, drum, st))
    previous = ()
    return _turn(drum, st, out, progress, figures, previous, every, max_steps, cdir,
                 keep_checkpoint, t0 - st["seconds"])


class _Stop(Exception):
    """max_steps reached (the checkpoint is written)."""


def _turn(drum, st, out, progress, figures, previous, every, max_steps, cdir,
          keep_checkpoint, t_start):
    """Turn the drum from the state ``st`` (step k, clock, angle, what was observed so far)
    to the end of its schedule, observing and checkpointing; returns the results."""
    from ..bed.progress import Progress

    spec, sim = drum.spec, drum.sim
    sched = drum.schedule()
    total = sum(ph.steps for ph in sched)
    ends = set(np.cumsum([ph.steps for ph in sched]).tolist())
    bar = Progress(total, desc="drum", enabled=progress, initial=min(st["k"], total))
    d, R = drum.d, spec.radius * drum.d
    if spec.ends == "caps" and spec.length > 3.0:
        window_half = 0.5 * spec.length * d - d
    else:
        window_half = None
    sample = drum.sample_every()
    t_rev = 2.0 * math.pi / drum.omega
    frame_at = {max(1, int(round(total * (i + 1) / spec.frames))) for i in range(spec.frames)}
    snap_at = set(int(round(x)) for x in np.linspace(total - 1, total - 1 - (sched[-1].steps - 1),
                                                     spec.snapshots))
    samples, frames, snaps = st["samples"], st["frames"], st["snaps"]
    drum.angle = st["angle"]
    stop_at = None if max_steps is None else max_steps

    def observe(k, t_turn, angle, phase):
        drum.angle = angle
        if k in frame_at:
            frames.append(_frame(drum, k, t_turn))
        if (k - 1) in snap_at:
            snaps.append(_frame(drum, k, t_turn))
        if phase.name != "spinup" and (k % sample == 0):
            X = sim.get_positions()
            window = None if window_half is None else np.abs(X[:, 2]) < window_half
            s = measure(X, sim.get_velocities(), drum.radii, R, phase.omega, d, window)
            s.update(t=t_turn, phase=phase.name, revolutions=angle / (2 * math.pi))
            samples.append(s)
        if every is not None and (k % every == 0 or k in ends or k == stop_at):
            st.update(k=k, t=t_turn, angle=angle, seconds=time.perf_counter() - t_start,
                      checkpoint_every=every)
            _checkpoint_write(cdir, spec, drum, st)
        if k == stop_at:
            raise _Stop

    if stop_at is not None and st["k"] >= stop_at:
        bar.close()
        return dict(complete=False, steps_done=st["k"], checkpoint=cdir)
    try:
        run_phases(sched, drum.dt, drum.step, drum.turn, turning_clock(sim, st), observe,
                   bar,
                   start=(st["k"], st["angle"]))
    except _Stop:
        bar.close()
        return dict(complete=False, steps_done=stop_at, checkpoint=cdir)
    except KeyboardInterrupt:
        bar.close()
        if cdir is not None and os.path.isfile(os.path.join(cdir, POINTER)):
            with open(os.path.join(cdir, POINTER)) as fh:
                k = json.load(fh).get("step")
            print(f"drum: interrupted; the checkpoint at step {k} of {total} resumes it "
                  f"(peclet drum --resume {os.path.dirname(cdir)})", file=sys.stderr)
        raise
    bar.close()
    wall = time.perf_counter() - t_start
    meas = [s for s in samples if s["phase"] == "measure"]
    regime, crit = classify(meas, drum.count)
    stats = angle_stats([s["t"] for s in meas], [s["angle"] for s in meas], t_rev)
    ang = stats if regime != "centrifuging" else dict(stats, mean=math.nan)
    fill_meas = _measured_fill(meas, R)
    res = dict(spec=asdict(spec), element=drum.grains["name"], grains=drum.count,
               froude=spec.froude, omega=drum.omega,
               rpm_for_grain_mm=rpm_of_froude(spec.froude, spec.radius, spec.grain_mm),
               wall_speed=drum.omega * R, dt=drum.dt, settle_steps=drum.settle_steps,
               steps=total, sample_every=sample, revolutions_turned=drum.angle / (2 * math.pi),
               regime=regime, mellmann=expected_regimes(spec.froude), criteria=crit,
               angle=ang, fill_measured=fill_meas, state_hash=sim.state_hash(),
               seconds=wall, ms_per_step=1e3 * wall / max(total + drum.settle_steps, 1),
               samples=[{k2: s[k2] for k2 in ("t", "revolutions", "phase", "angle", "s_shape",
                                              "airborne", "flowing", "corotating",
                                              "coverage", "high")} for s in samples])
    if out is not None:
        write_outputs(out, res, drum, frames, snaps, samples, figures, previous)
        if cdir is not None and not keep_checkpoint:
            ckpt.remove(cdir, own=())
    return res


# ---------------------------------------------------------------------------- checkpoints
def checkpoint_dir(path, name="path"):
    """The checkpoint directory of a drum run at ``path`` (its output directory or the
    ``checkpoint/`` in it); PecletArgumentError naming ``name`` if there is none."""
    return ckpt.find(path, name, _WHAT)


def _frames_arrays(prefix, frames):
    if not frames:
        return {}
    return {f"{prefix}_step": np.array([f["step"] for f in frames], np.int64),
            f"{prefix}_t": np.array([f["t"] for f in frames], np.float64),
            f"{prefix}_turned": np.array([f["turned"] for f in frames], np.float64),
            f"{prefix}_X": np.stack([f["X"] for f in frames]),
            f"{prefix}_V": np.stack([f["V"] for f in frames]),
            f"{prefix}_shape": np.stack([np.asarray(f["shape"]) for f in frames])}


def _frames_of(arrays, prefix):
    if f"{prefix}_step" not in arrays:
        return []
    return [dict(step=int(s), t=float(t), turned=float(a), X=X, V=V, shape=sh)
            for s, t, a, X, V, sh in zip(*(arrays[f"{prefix}_{k}"] for k in
                                           ("step", "t", "turned", "X", "V", "shape")))]


def _checkpoint_write(cdir, spec, drum, st):
    """Write step ``st["k"]`` of the run into ``cdir``
    (:func:`peclet.packing.bed.checkpoint.write_loop_step`): ``ckpt-<k>/`` holds ``sim.npz``,
    the loop's state ``state.json`` and the frames and radii ``arrays.npz``."""
    state = dict(t=st["t"], t_begin=st["t_begin"], angle=st["angle"], seconds=st["seconds"],
                 checkpoint_every=st.get("checkpoint_every"), wall=drum.wall,
                 settle_steps=drum.settle_steps, samples=st["samples"])
    arrays = dict(radii=np.asarray(drum.radii, np.float64),
                  **_frames_arrays("frames", st["frames"]),
                  **_frames_arrays("snaps", st["snaps"]))
    ckpt.write_loop_step(cdir, _KIND, asdict(spec), st["run"], st["k"], drum.sim, state,
                         arrays)


def read_checkpoint(cdir, name="path"):
    """(checked spec, state dict, arrays dict, path of ``sim.npz``) of the latest step of the
    checkpoint directory ``cdir`` (see :func:`checkpoint_dir`; this format or the drum's
    earlier one); a pointer that is not a drum checkpoint's, a missing or damaged part, parts
    of two runs or a file that is not the one hashed: PecletArgumentError naming ``name``."""
    return ckpt.read_loop_step(cdir, _KIND, "drum", name, _WHAT,
                               lambda d: DrumSpec(**d).checked())


def same_spec(saved, given, names=None):
    """Refuse ``given`` (a dict of :class:`DrumSpec` fields) unless the run's checked spec
    ``saved`` has them: the error names the first differing field (``names[field]``) and
    the run's value. ``rpm`` is compared as the Froude number it gives."""
    nm = lambda f: (names or {}).get(f, f)  # noqa: E731
    base = asdict(saved)
    unknown = set(given) - set(base)
    if unknown:
        raise PecletArgumentError("given", "DrumSpec fields", sorted(unknown))
    merged = dict(base, **given)
    if given.get("rpm") is not None:
        merged["froude"] = None
    new = asdict(DrumSpec(**merged).checked(names))
    for k in base:
        if base[k] != new[k]:
            flag = "rpm" if k == "froude" and given.get("rpm") is not None else k
            shown = given.get(flag, new[k])
            raise PecletArgumentError(nm(flag), f"the resumed run's {_value(saved, flag)} (a "
                                      "resumed run keeps its parameters: leave the option "
                                      "out, or start a new run)", shown)


def _value(saved, field):
    if field == "rpm":
        return f"{rpm_of_froude(saved.froude, saved.radius, saved.grain_mm):.6g} " \
               f"(Froude {saved.froude:.6g} at {saved.grain_mm:g} mm)"
    return repr(getattr(saved, field))


def _measured_fill(samples, R):
    """The bed's share of the cross-section below the mean surface line (NaN without one)."""
    b = [s["intercept"] for s in samples if np.isfinite(s.get("intercept", math.nan))]
    a = [s["slope"] for s in samples if np.isfinite(s.get("slope", math.nan))]
    if not b:
        return math.nan
    h = float(np.mean(b)) * math.cos(math.atan(float(np.mean(a))))   # distance axis -> line
    h = max(-R, min(R, h))
    th = 2.0 * math.acos(max(-1.0, min(1.0, -h / R)))   # segment below the line
    return float((th - math.sin(th)) / (2.0 * math.pi))


def _frame(drum, k, t):
    sim = drum.sim
    return dict(step=k, t=t, X=sim.get_positions(), V=sim.get_velocities(),
                shape=sim.get_shape_ids(), turned=drum.angle)
