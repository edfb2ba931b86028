"""Every check of ``peclet pall-ring`` / :func:`peclet.packing.page.pipeline.run`, made before the ring
is built (the build and the pour are minutes; a refusal here costs at most a second or two,
measured: 0.01-2.3 s, the first call paying for the ring's radius bound).

The rules (each a :class:`~peclet.core.validation.PecletArgumentError` naming the argument;
the command line's names are used when ``cli=True``):

- ``rings``: an integer in [1, RINGS_MAX]. The cap bounds the work: the pour costs about
  0.094 ms per ring-step on this 2-core machine (issue 14's 300-ring bed) over the page's 3700
  steps, so RINGS_MAX rings is about an hour of stepping on a quiet machine (and the start
  cloud of a million rings alone would spin).
- ``seed``: an integer >= 0 (numpy's generators take no negative seed).
- ``steps_scale``: a finite number in (0, STEPS_SCALE_MAX].
- ``box`` (in ring diameters D), two rules, both from the element and the count:
  1. the engine's periodic cell must exceed twice its interaction cutoff (else one pair could
     meet through two images): ``box > 2 (2 r_b + margin)``, r_b the ring's bounding radius
     about its centre of mass and margin the engine's contact margin
     (``DEFAULT_MARGIN_FRACTION r_b + 2 dt v``) at the speed v a ring reaches falling from the
     top of the start cloud, doubled for spin: ``v = 2 sqrt(2 g y_c)``;
  2. every ring must land before the quench: free fall from the start cloud's top y_c takes
     ``sqrt(2 y_c / g)``, at most the time of the pour, taps and relaxation. A narrow box
     stacks the cloud high (it is the page's algorithm: each ring needs 1.55 D of room from the
     last 14), so this rule is what refuses 2000 rings in the page's 3.5 D box.
  The domain then reaches :func:`~peclet.packing.bed.pour.y_top_for` (y_c): the page's 60 D, or
  more for a taller cloud, so its height follows from the count.
- ``mc_samples``: an integer in [MC_SAMPLES_MIN, MC_SAMPLES_MAX]. From 1000 samples on, the
  binomial standard error sqrt(p (1 - p) / n) of a voidage is at most 0.016 and its normal
  approximation holds for fractions in [0.01, 0.99] (n p (1 - p) >= 10); 10^7 points are
  240 MB of coordinates.
- ``shell_points``: an integer in [SHELL_POINTS_MIN, SHELL_POINTS_MAX]. The probes are spread
  evenly (:func:`peclet.core.geom.shell.even_spacing`: hexagonal spacing
  ``sqrt(2 A / (sqrt(3) M))`` over the ring's area A = 6.56 D^2); that spacing must not exceed
  the wall thickness 0.12 D, so that every face strip of the wall (its rims, window edges)
  carries probes and a neighbour's edge cannot pass between them unseen:
  ``count_for_spacing(6.56, 0.12) = 527`` probes, 600 with a margin. (The page's median
  spacing of 0.0369 D at 1200 probes came from clumped marching-cubes vertices; an even spread
  of 1200 has 0.079 D.)
- ``out``: a directory that exists and is writable, or can be created; one holding the files of
  an earlier run (:data:`OUTPUTS`) is refused unless ``overwrite``, which then removes exactly
  those files before the run (other files are never touched).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from peclet.core.outputs import check_output_dir, clear_outputs
from peclet.core.validation import (PecletArgumentError, check_bool, check_float, check_int,
                                     describe_range)

from ..bed.pour import Protocol, start_cloud, y_top_for

__all__ = ["check_run", "clear_outputs", "RunPlan", "OUTPUTS", "RINGS_MAX",
           "MC_SAMPLES_MIN", "MC_SAMPLES_MAX", "SHELL_POINTS_MIN", "SHELL_POINTS_MAX",
           "STEPS_SCALE_MAX", "BOX_MAX"]

RINGS_MAX = 10_000
MC_SAMPLES_MIN = 1_000
MC_SAMPLES_MAX = 10_000_000
SHELL_POINTS_MIN = 600
SHELL_POINTS_MAX = 20_000
STEPS_SCALE_MAX = 20.0
#: A box side beyond which the analysis' 3 x 3 periodic images cost more than they tell.
BOX_MAX = 100.0
GRAVITY = 9.81

#: Every file a run writes into ``out``: what marks a directory as holding an earlier run.
OUTPUTS = ("pall_ring_pack.npz", "pour_frames.npz", "results.json", "ring.png",
           "kinetic_energy.png", "pack.png", "orientation.png", "voidage_sweep.png", "pour.gif")

_CLI = dict(out="--out", rings="--rings", seed="--seed", threads="--threads",
            steps_scale="--steps-scale", box="--box", mc_samples="--mc-samples",
            shell_points="--shell-points", overwrite="--overwrite")


@dataclass(frozen=True)
class RunPlan:
    """The checked arguments of a run and what follows from them."""

    out: str
    rings: int
    seed: int
    threads: int | None
    steps_scale: float
    box: float
    mc_samples: int
    shell_points: int
    protocol: Protocol
    y_cloud: float          # the start cloud's highest centre (D)
    y_top: float            # the domain's top (D)
    box_min: float          # rule 1's bound on the box (D)
    previous: tuple         # files of an earlier run in ``out`` (removed when overwriting)


@lru_cache(maxsize=1)
def ring_radius_bound():
    """An upper bound of the page ring's bounding radius about its centre of mass (D).

    The pour uses ``|c_home| + r`` of the home (centre-of-mass) frame's ball, i.e.
    ``r + |c - com|`` with (c, r) the authoring ball. The centre of mass is known only after the
    quadrature (minutes); here a Monte Carlo estimate (2^18 points, fixed seed) plus six
    standard errors bounds ``|c - com|`` (measured by quadrature: 5.6e-4 D; the bound adds
    about 0.01 D).
    """
    from ..bed import elements

    ring = elements.pall_ring()
    c, r, _ = ring.builder.node_bound(ring.root)
    lo, hi = ring.bounds
    p = np.random.default_rng(0).uniform(lo, hi, size=(1 << 18, 3))
    inside = p[ring.builder.eval_root(ring.root, p) < 0.0]
    com = inside.mean(axis=0)
    se = inside.std(axis=0) / math.sqrt(len(inside))
    return float(r + np.linalg.norm(com - c) + 6.0 * np.linalg.norm(se))


def _margin_fraction():
    from peclet.dem.simulation import DEFAULT_MARGIN_FRACTION

    return float(DEFAULT_MARGIN_FRACTION)


def box_bound(r_b, y_cloud, dt):
    """Rule 1: the smallest box side (D) the engine accepts for bodies of bounding radius
    ``r_b`` falling from ``y_cloud``: ``2 (2 r_b + f r_b + 2 dt v)``, v = 2 sqrt(2 g y)."""
    v = 2.0 * math.sqrt(2.0 * GRAVITY * max(y_cloud, 0.0))
    return 2.0 * (2.0 * r_b + _margin_fraction() * r_b + 2.0 * dt * v)


def _int_arg(name, value, lo, hi, why=""):
    """check_int with the rule's reason appended to the message."""
    v = check_int(name, value, -math.inf, math.inf)
    if not lo <= v <= hi:
        raise PecletArgumentError(name, f"an integer {describe_range(lo, hi)}", value, why)
    return v


def check_run(out="results", rings=48, seed=5, threads=None, steps_scale=1.0, box=3.5,
              mc_samples=400_000, shell_points=1200, overwrite=False, particle=None,
              quad_n=32, shell_resolution=112, sweep=(), sweep_n=32, mesh_n=150,
              progress=True, write_figures=True, animation=False, log=None, cli=False):
    """Check the arguments of :func:`~peclet.packing.page.pipeline.run` (the module notes state the
    rules) and return a :class:`RunPlan`; raise :class:`PecletArgumentError` naming the first
    bad one (with ``cli=True`` by its command-line option). Cheap: no tree is built and nothing
    is written. ``particle``, when given, supplies the bounding radius and skips
    ``shell_points``' rule (the particle's probes are used)."""
    nm = (lambda k: _CLI.get(k, k)) if cli else (lambda k: k)
    for k, v in (("progress", progress), ("write_figures", write_figures),
                 ("animation", animation), ("overwrite", overwrite)):
        check_bool(nm(k), v)
    rings = _int_arg(nm("rings"), rings, 1, RINGS_MAX,
                     "the cap bounds the work: about an hour of pouring on 2 cores")
    seed = _int_arg(nm("seed"), seed, 0, math.inf, "numpy's generators need a seed >= 0")
    if threads is not None:
        import numba

        threads = _int_arg(nm("threads"), threads, 1, int(numba.config.NUMBA_NUM_THREADS),
                           "NUMBA_NUM_THREADS is the most numba will run")
    steps_scale = check_float(nm("steps_scale"), steps_scale, 0.0, STEPS_SCALE_MAX,
                              lo_open=True)
    box = check_float(nm("box"), box, 0.0, BOX_MAX, lo_open=True)
    mc_samples = _int_arg(nm("mc_samples"), mc_samples, MC_SAMPLES_MIN, MC_SAMPLES_MAX,
                          "fewer gives no meaningful standard error")
    if particle is None:
        shell_points = _int_arg(nm("shell_points"), shell_points, SHELL_POINTS_MIN,
                                SHELL_POINTS_MAX, "an even spread must be at most the wall "
                                "thickness apart")
    check_int("quad_n", quad_n, 2, 4096)
    check_int("shell_resolution", shell_resolution, 8, 1024)
    check_int("sweep_n", sweep_n, 2, 4096)
    check_int("mesh_n", mesh_n, 3, 1024)
    if isinstance(sweep, (str, bytes)) or not hasattr(sweep, "__iter__"):
        raise PecletArgumentError("sweep", "a sequence of wall thicknesses in (0, 0.5) D",
                                  sweep)
    for t in sweep:
        check_float("sweep", t, 0.0, 0.5, lo_open=True, hi_open=True)
    if log is not None and not callable(log):
        raise PecletArgumentError("log", "a callable taking one string, or None", log)

    protocol = Protocol().scaled(steps_scale) if steps_scale != 1.0 else Protocol()
    P0, _ = start_cloud(rings, box, seed)
    y_cloud = float(P0[:, 1].max())
    r_b = float(particle.bounding_radius) if particle is not None else ring_radius_bound()
    box_min = box_bound(r_b, y_cloud, protocol.dt)
    if not box > box_min:
        raise PecletArgumentError(
            nm("box"), f"> {box_min:.3f} D for {rings} rings", box,
            f"the periodic cell must exceed twice the contact cutoff 2 r_b + margin: "
            f"r_b = {r_b:.4f} D, margin at the fall speed from the start cloud's top "
            f"y = {y_cloud:.1f} D")
    t_land = protocol.dt * (protocol.pour_steps + protocol.taps * protocol.tap_steps
                            + protocol.relax_steps)
    t_fall = math.sqrt(2.0 * y_cloud / GRAVITY)
    if t_fall > t_land:
        raise PecletArgumentError(
            nm("box"), f"wide enough for {rings} rings to land before the quench", box,
            f"their start cloud reaches y = {y_cloud:.1f} D, a free fall of {t_fall:.2f} "
            f"> {t_land:.2f} time units before the quench: widen {nm('box')} or raise "
            f"{nm('steps_scale')}")
    out_abs, previous = check_output_dir(out, OUTPUTS, overwrite, nm("out"))
    return RunPlan(out=out_abs, rings=rings, seed=seed, threads=threads,
                   steps_scale=steps_scale, box=box, mc_samples=mc_samples,
                   shell_points=shell_points, protocol=protocol, y_cloud=y_cloud,
                   y_top=y_top_for(y_cloud), box_min=box_min,
                   previous=previous)
