"""The whole reference page (Steps 1-7) as one function: :func:`run`.

Build the Pall ring (Step 1), test its certificate against the sign-exact twin (Step 2),
measure it by quadrature and shell it (Step 3), pour / tap / quench (Step 4), analyse the frozen
pack on the exact trees (Step 5), sweep the wall thickness (Step 6) and freeze it (Step 7).
Writes into ``out`` (all atomically): ``pall_ring_pack.npz``, ``pour_frames.npz`` (animation
frames and the kinetic-energy history), ``results.json`` and the figures
``ring.png``, ``kinetic_energy.png``, ``pack.png``, ``orientation.png``, ``voidage_sweep.png``.
Units: the ring's outer diameter D = 1; time in the page's units (g = 9.81).
"""
from __future__ import annotations

import os
import time

import numpy as np

from peclet.core.files import atomic_write, write_json
from peclet.core.geom.mesh import surface_mesh
from peclet.core.geom.quadrature.refine import kernels_cached as quadrature_cached
from peclet.core.geom.transforms import quat_to_matrix
from peclet.core.outputs import recording

from ..analysis import coordination
from ..analysis import geometry as analysis
from ..bed import elements
from ..bed.elements import home_transform
from ..bed.freeze import Pack, save_pack
from ..bed.threads import set_threads
from .checks import OUTPUTS, check_run, clear_outputs
from ..bed.pour import pour
from ..bed.progress import ms_per_step
from .sweep_process import SweepProcess
from .table import PAGE, results_table

__all__ = ["run", "check_run", "PAGE", "results_table", "OUTPUTS",
           "check_stages"]

SWEEP_T = (0.024, 0.04, 0.06, 0.08, 0.12, 0.16)
#: The sweep's quadrature tolerance (relative, on each thickness' volume).
SWEEP_TOL = 1e-4


#: Contact gap (in D) for coordination: two rings (or a ring and the floor) whose gap in the
#: engine's own contact detection (:mod:`peclet.packing.analysis.coordination`) is below it touch. The
#: page counted a probe strictly inside the other tree (gap 0), which only works for an engine
#: that lets rings overlap (its max overlap was 23% of the wall); ours removes overlap and
#: leaves touching rings at gaps of its resting slop (~4e-4 D).
CONTACT_GAP = 1e-3


def _page_floor(box):
    """The page's floor as a solid tree (:func:`peclet.packing.bed.freeze.add_floor`'s box)."""
    from peclet.core.geom import SceneBuilder

    fb = SceneBuilder()
    return fb, fb.add_leaf("box", [40.0 + box, 1.0, 40.0 + box],
                           translation=[box / 2, -1.0, box / 2])


def run(out="results", rings=48, seed=5, threads=None, steps_scale=1.0, box=3.5,
        mc_samples=400_000, quad_n=32, shell_resolution=112, shell_points=1200,
        sweep=SWEEP_T, sweep_n=32, mesh_n=150, progress=True, write_figures=True,
        animation=False, particle=None, log=print, overwrite=False, stages=None):
    """Run the page end to end; returns the results dict (also written to results.json).

    rings: number of rings (>= 1); seed: start-cloud seed; threads: numba threads (None keeps
    the current setting); steps_scale: multiplies every protocol step count (1 = the page);
    box: periodic box side (in D); mc_samples: Monte Carlo points per bulk window; quad_n,
    shell_resolution, shell_points: ``scene_particle.build`` knobs; animation: also write
    ``pour.gif`` (about 10-20 s of rendering); particle: a prebuilt particle of the page's ring
    (same attributes as ``scene_particle.build``'s result, its ``home_root`` in the builder of
    ``elements.pall_ring()`` — built on a fresh one, whose node indices are deterministic),
    to skip Step 3's build; sweep: wall thicknesses t
    (in D) for Step 6 and sweep_n their quadrature resolution (computed in a low-priority child
    process beside the measurement and the pour, :mod:`peclet.packing.page.sweep_process`: the same
    rows bit for bit; read from the results cache when an earlier run computed them,
    ``sweep_source`` in the result); mesh_n: marching-cubes
    lattice for the surface area; overwrite: replace the files of an earlier run in ``out``
    (without it such a directory is refused; with it those files are removed first, so no old
    figure stays beside new results; other files in ``out`` are never touched); stages: None
    or a dict {name: callable(pack, progress) -> JSON-ready dict}, run in order on the frozen
    pack, each result stored as ``res[name]`` and timed as ``timing[name]``. The flow is such
    a stage, composed by the command line (this layer does not import ``peclet.flow``):
    ``stages={"flow": peclet.flow.page.stage(8)}`` adds k and dP/L against Ergun to
    ``res["flow"]`` and the Results table (check the resolution against the box first with
    :func:`peclet.flow.page.check_resolution`).

    Every argument is checked before any work
    (:func:`~peclet.packing.page.checks.check_run`, which states the rules: ring cap, box
    size for the element and the count, samples):
    a bad one raises :class:`~peclet.core.validation.PecletArgumentError` and nothing is
    written. The domain's height follows from the count (the start cloud's top).
    """
    plan = check_run(out=out, rings=rings, seed=seed, threads=threads, steps_scale=steps_scale,
                     box=box, mc_samples=mc_samples, shell_points=shell_points,
                     overwrite=overwrite, particle=particle, quad_n=quad_n,
                     shell_resolution=shell_resolution, sweep=sweep, sweep_n=sweep_n,
                     mesh_n=mesh_n, progress=progress, write_figures=write_figures,
                     animation=animation, log=log)
    out = plan.out
    stages = check_stages(stages)
    if threads is not None:
        set_threads(plan.threads)
    with recording(out, OUTPUTS):   # the manifest of what this run writes (core.outputs)
        clear_outputs(out, plan.previous)
        T0 = time.perf_counter()
        timing = {}
        # a cold cache: the step's kernels compile in a child on the other core while the element
        # is measured (its quadrature compiles here), instead of after it (peclet.dem.warm)
        from peclet.dem import warm
        warming = warm.start_background()
        # Step 6's sweep runs in a low-priority child (peclet.packing.page.sweep_process) beside the
        # measurement and the pour: started now when the quadrature's kernels are cached, else
        # once the element's measurement has compiled them
        sweeper = None
        sweep_args = ([float(x) for x in sweep], sweep_n, SWEEP_TOL, plan.threads)
        if quadrature_cached():
            sweeper = SweepProcess(*sweep_args)
        try:
            res = dict(config=_config(plan, quad_n, sweep_n))
            ring = _certificate(res, timing)
            sp, b, env_home, axis_home = _measure(ring, particle, plan, quad_n,
                                                  shell_resolution, mesh_n, res, timing)
            if sweeper is None:
                sweeper = SweepProcess(*sweep_args)
            pack_of = _pack_maker(sp, b, plan.box, env_home, ring.envelope_volume, axis_home)
            if warm.running(warming):
                # a cold run: while the DEM kernels compile in the children, the analysis'
                # kernels compile here (on a one-ring pack of this element: the same signatures)
                t = time.perf_counter()
                analysis.compile_kernels(pack_of(np.array([[0.0, 1.0, 0.0]]),
                                                 np.array([[0.0, 0.0, 0.0, 1.0]])))
                timing["analysis_compile"] = time.perf_counter() - t
            pr, max_ov_engine = _pour(sp, plan, warming, progress, log, res, timing)
            # ---- Step 7 (frozen state first: every statistic below is computed from it)
            pack = pack_of(pr.positions, pr.quaternions)
            _freeze(out, pack, pr, res)
            wall_t = ring.params["thickness"]
            fr, ori = _analyse(pack, plan, wall_t, max_ov_engine, res, timing)
            # ---- optional stages on the frozen pack (the flow), beside the sweep
            for name, run_stage in stages.items():
                t = time.perf_counter()
                res[name] = run_stage(pack, progress)
                timing[name] = time.perf_counter() - t
            figs = {}
            if write_figures:
                figs = _figures(b, ring.root, pr, pack, ori, plan, animation, timing)
            _sweep(sweeper, fr, wall_t, write_figures, figs, out, res, timing)
            timing["total"] = time.perf_counter() - T0
            res["timing"] = timing
            res["results_json"] = os.path.abspath(
                write_json(os.path.join(out, "results.json"), res))
            if log is not None:
                log(results_table(res))
            return res
        finally:
            if sweeper is not None:
                sweeper.stop()          # a run that failed: the child is not left running


def _config(plan, quad_n, sweep_n):
    """The run's settings as the results record them (``res["config"]``)."""
    return dict(rings=plan.rings, seed=plan.seed, threads=plan.threads,
                steps_scale=plan.steps_scale, box=plan.box, y_top=plan.y_top,
                mc_samples=plan.mc_samples, quad_n=quad_n, sweep_n=sweep_n,
                shell_points=plan.shell_points, protocol=plan.protocol.__dict__.copy())


def _certificate(res, timing):
    """Steps 1-2: the ring, its certificate against the sign-exact twin (``res["certificate"]``)
    and its resolved construction parameters (``res["element"]``). Returns the ring."""
    t = time.perf_counter()
    ring = elements.pall_ring()
    twin = elements.pall_ring(certified=False)
    b, root = ring
    cert = analysis.certificate_check(b, root)
    bad = analysis.certificate_check(twin.builder, twin.root)
    q = np.random.default_rng(11).uniform(-1.0, 1.0, size=(200_000, 3))
    same = float((np.sign(b.eval_root(root, q))
                  == np.sign(twin.builder.eval_root(twin.root, q))).mean())
    res["certificate"] = dict(certified=cert, sign_exact=bad, same_sign=same,
                              nodes=int(b.num_nodes()))
    # the element's resolved construction parameters (elements.PARAMS; lengths in D)
    res["element"] = dict(name=ring.name, text=elements.element_text(ring.name, {}),
                          params={k: list(v) if isinstance(v, tuple) else v
                                  for k, v in ring.params.items()})
    timing["certificate"] = time.perf_counter() - t
    return ring


def _measure(ring, particle, plan, quad_n, shell_resolution, mesh_n, res, timing):
    """Step 3: measure, reframe and shell the ring (or take ``particle``, built on the ring's
    builder), and its surface area; ``res["particle"]``. Returns (the particle, the builder it
    lives in, its envelope's root and its axis in its home frame)."""
    from scipy.spatial import cKDTree

    from peclet.dem import scene_particle

    b, root = ring
    t = time.perf_counter()
    if particle is None:
        sp = scene_particle.build(b, root, bounds=ring.bounds, n=quad_n,
                                  shell_resolution=shell_resolution,
                                  target_shell_points=plan.shell_points)
    else:
        sp = particle
        ni0, nr0, _, _ = b.encode()
        if not (len(sp.node_ints) > len(ni0)
                and np.array_equal(np.asarray(sp.node_ints)[:len(ni0)], ni0)
                and np.array_equal(np.asarray(sp.node_reals)[:len(ni0)], nr0)):
            raise ValueError("particle must be built on the builder of "
                             "elements.pall_ring()")
        b = type(b).decode(sp.node_ints, sp.node_reals)
    timing["scene_particle"] = time.perf_counter() - t
    tq, qq, sq = home_transform(b, root, sp.home_root)
    env_home = b.add_reframed(ring.envelope_root, translation=tq, rotation=qq, scale=sq)
    axis_home = quat_to_matrix(qq) @ np.array([0.0, 1.0, 0.0])
    d_nn, _ = cKDTree(sp.shell).query(sp.shell, k=2)
    t = time.perf_counter()
    _, _, area = surface_mesh(b, root, [-0.62] * 3, [0.62] * 3, mesh_n)
    timing["surface_mesh"] = time.perf_counter() - t
    v_env = ring.envelope_volume
    res["particle"] = dict(
        volume=float(sp.volume), volume_error=float(sp.volume_error),
        volume_fraction=float(sp.volume / v_env), envelope_volume=v_env,
        com=np.asarray(sp.com, float).tolist(), principal=np.asarray(sp.principal).tolist(),
        moment_error=float(np.max(sp.moment_error)), quat=np.asarray(sp.quat).tolist(),
        bounding_radius=float(sp.bounding_radius), shell_points=int(len(sp.shell)),
        probe_spacing_median=float(np.median(d_nn[:, 1])),
        probe_spacing_p90=float(np.percentile(d_nn[:, 1], 90)),
        min_feature=float(ring.min_feature), surface_area=area,
        specific_surface=area / v_env, mesh_n=int(mesh_n))
    return sp, b, env_home, axis_home


def _pack_maker(sp, b, box, env_home, v_env, axis_home):
    """``pack_of(positions, quaternions)``: the :class:`Pack` of particles ``sp`` (in builder
    ``b``, envelope ``env_home`` of volume ``v_env``, axis ``axis_home``) at those poses in the
    periodic box of side ``box``."""
    ni, nr, _, _ = b.encode()

    def pack_of(positions, quaternions):
        return Pack(positions, quaternions, [box, box], sp.volume, ni, nr, sp.home_root,
                    sp.bounding_radius, sp.shell, sp.mass, sp.inv_inertia_unit, env_home,
                    v_env, axis_home)
    return pack_of


def _pour(sp, plan, warming, progress, log, res, timing):
    """Step 4: pour, tap and quench (after the DEM kernels compiling in ``warming``'s children,
    if any); ``res["pour"]``. Returns (the pour's result, the engine's largest overlap)."""
    from peclet.dem import warm

    t = time.perf_counter()
    if warming is not None:
        log("waiting for the DEM kernels compiling beside the measurement (first run only)")
        warm.finish(warming)
        timing["wait_for_dem_kernels"] = time.perf_counter() - t
        t = time.perf_counter()
    pr = pour(sp, n=plan.rings, box=plan.box, seed=plan.seed, protocol=plan.protocol,
              progress=progress, y_top=plan.y_top)
    timing["pour"] = time.perf_counter() - t
    sim = pr.sim
    e_scale = plan.rings * sp.mass * 9.81 * 1.0      # lifting the whole bed one diameter
    ke_end = float(sim.kinetic_energy())
    max_ov_engine = float(sim.compute_overlaps())
    res["pour"] = dict(steps=pr.steps, seconds=pr.seconds,
                       first_step_seconds=pr.first_step_seconds,
                       ms_per_step=ms_per_step(pr.seconds, pr.first_step_seconds, pr.steps),
                       ke_end=ke_end,
                       ke_ratio=ke_end / e_scale, max_overlap_engine=max_ov_engine,
                       bed_y=[float(pr.positions[:, 1].min()),
                              float(pr.positions[:, 1].max())])
    return pr, max_ov_engine


def _freeze(out, pack, pr, res):
    """Step 7's files: the frozen ``pack`` (``pall_ring_pack.npz``, ``res["pack_file"]``) and the
    pour's frames and kinetic-energy history (``pour_frames.npz``)."""
    npz = save_pack(os.path.join(out, "pall_ring_pack.npz"), pack)
    res["pack_file"] = dict(path=os.path.abspath(npz), kib=os.path.getsize(npz) / 1024)
    fpos = np.array([f[0] for f in pr.frames])
    fquat = np.array([f[1] for f in pr.frames])

    def write_frames(tmp):
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, positions=fpos, quaternions=fquat,
                                t=np.asarray(pr.frame_t), ke_t=np.asarray(pr.t),
                                ke=np.asarray(pr.ke))
    atomic_write(os.path.join(out, "pour_frames.npz"), write_frames)


def _analyse(pack, plan, wall_t, max_ov_engine, res, timing):
    """Step 5: the pack, numerically (voidage in the bulk windows, overlap, coordination,
    orientation, containment); ``res["pack"]``. Returns (the windows' fractions, the
    orientation)."""
    t = time.perf_counter()
    geo = analysis.PackGeometry(pack)
    windows, wscale = analysis.bulk_windows(pack)
    fr = [analysis.cover_fractions(geo, w, plan.mc_samples, seed=k)
          for k, w in enumerate(windows)]
    con = analysis.probe_overlap(geo)
    co = coordination.engine_coordination(pack, [_page_floor(plan.box)], gap=CONTACT_GAP)
    ori = analysis.orientation(pack)
    box_chk = analysis.floor_and_box(pack, y_top=plan.y_top)
    eps_all = np.array([f["eps"] for f in fr])
    res["pack"] = dict(
        windows=fr, window_scale=wscale, eps=fr[0]["eps"], eps_se=fr[0]["eps_se"],
        eps_mean=float(eps_all.mean()), eps_spread=float(eps_all.std()),
        f_env=fr[0]["f_env"], f_env_se=fr[0]["f_env_se"], double=fr[0]["double"],
        double_se=fr[0]["double_se"], z_mean=co["z_total"], z_elem=co["z_elem"],
        rattlers=co["rattlers"], under_stable=co["under_stable"],
        floor_contacts=int(co["wall"].sum()), contact_gap=CONTACT_GAP,
        contact_method=co["method"], contacts_per_ring=co["total"].tolist(),
        contact_pairs=co["pairs"], candidate_pairs=con["pairs"],
        max_overlap=con["max_depth"], max_overlap_wall=con["max_depth"] / wall_t,
        max_overlap_engine_wall=max_ov_engine / wall_t,
        cos_mean=ori["mean"], cos_sem=ori["sem"], cos_sem_iso=ori["sem_iso"],
        cos=ori["cos"].tolist(), lowest_probe=box_chk["min_lowest_probe"],
        all_in_box=box_chk["all_in_box"], n_outside=box_chk["n_outside"])
    timing["analysis"] = time.perf_counter() - t
    return fr, ori


def _figures(b, root, pr, pack, ori, plan, animation, timing):
    """The figures of the ring, the pour and the pack (drawn while the sweep's child
    finishes): {name: path}."""
    out = plan.out
    t = time.perf_counter()
    # matplotlib (0.7 s to import) only where a figure is drawn: a refused or
    # figure-less run, and the command line's checks, never load it
    from ..output import figures
    rv, rf, _ = surface_mesh(b, root, [-0.62] * 3, [0.62] * 3, 60)  # (area: mesh_n)
    figs = dict(
        ring=figures.ring_views(rv, rf, os.path.join(out, "ring.png")),
        kinetic_energy=figures.kinetic_energy(
            pr.t, pr.ke, plan.protocol.phases(), plan.protocol.dt,
            os.path.join(out, "kinetic_energy.png")),
        pack=figures.pack_by_height(pack.positions, pack.rotations(), pack.shell,
                                    pack.box, os.path.join(out, "pack.png")),
        orientation=figures.orientation_histogram(
            ori["cos"], os.path.join(out, "orientation.png")))
    if animation:
        figs["animation"] = figures.pour_animation(
            pr.frames, pr.frame_t, pack.shell, pack.box, os.path.join(out, "pour.gif"))
    timing["figures"] = time.perf_counter() - t
    return figs


def _sweep(sweeper, fr, wall_t, write_figures, figs, out, res, timing):
    """Step 6: the wall-thickness sweep, eps(t) = 1 - f_env s(t), from the sweep's child
    (``res["sweep"]``, ``res["sweep_source"]``) and its figure (``res["figures"]``, with
    ``figs``)."""
    t = time.perf_counter()
    fractions = sweeper.rows()
    timing["sweep_wait"] = time.perf_counter() - t
    rows = analysis.sweep_voidage(fractions, fr[0]["f_env"], fr[0]["f_env_se"])
    res["sweep"] = rows
    # read from the results cache (an earlier run's rows, the same bits) or computed now
    res["sweep_source"] = "cache" if sweeper.from_cache else "computed"
    if write_figures:
        from ..output import figures

        t = time.perf_counter()
        figs["voidage_sweep"] = figures.voidage_sweep(
            rows, fr[0]["eps"], wall_t / 1.0, os.path.join(out, "voidage_sweep.png"))
        timing["figures"] += time.perf_counter() - t
        res["figures"] = {k: os.path.abspath(v) for k, v in figs.items()}


def check_stages(stages, name="stages"):
    """``stages`` as a dict {name: callable}; None gives {}. PecletArgumentError naming
    ``name`` for anything else, or a stage name that would replace one of the run's own keys."""
    from peclet.core.validation import PecletArgumentError

    if stages is None:
        return {}
    what = "None or a dict {name: callable(pack, progress)}"
    if not isinstance(stages, dict):
        raise PecletArgumentError(name, what, stages)
    for k, v in stages.items():
        if not isinstance(k, str) or not callable(v):
            raise PecletArgumentError(name, what, stages, f"entry {k!r} is not str: callable")
        if k in _RESULT_KEYS:
            raise PecletArgumentError(name, what, stages, f"{k!r} is one of the run's own "
                                      "results")
    return dict(stages)


#: The keys of the run's own results dict, which a stage may not take.
_RESULT_KEYS = ("config", "certificate", "element", "particle", "pour", "pack_file", "pack",
                "sweep", "sweep_source", "figures", "timing", "results_json")


