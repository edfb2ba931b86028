"""One realization: :func:`realize` packs a :class:`~peclet.ensemble.spec.PackSpec` and
measures it. This is the function a Dask worker runs; it is also the serial reference.

Figures of merit, as the page computes them (peclet.packing.page.pipeline): the porosity eps and the
envelope packing fraction f_env by Monte Carlo over the first bulk window
(``analysis.bulk_windows``; ``spec.mc_samples`` points, sample seed 0), and the mean
coordination Z (element-element, from the engine's own contact detection at the page
pipeline's contact gap, :mod:`peclet.packing.analysis.coordination`; ``z_total`` adds the walls).
Everything but the timings is a deterministic function of the spec, at any thread count.
"""
from __future__ import annotations

import os
import platform
import time

__all__ = ["realize", "FIGURES"]

#: The figures of merit every result carries (and the summary reports).
FIGURES = ("eps", "f_env", "z_mean")


def _material(spec):
    from peclet.packing import Material

    return Material(e_n=spec.e_n, e_t=spec.e_t, mu=spec.mu)


def _protocol(spec):
    """The spec's protocol: its name, or (steps_scale != 1, page only: PackSpec checks it)
    the page protocol with every step count scaled."""
    if spec.steps_scale == 1.0:
        return spec.protocol
    from peclet.packing import PageProtocol

    return PageProtocol().scaled(spec.steps_scale)


def realize(spec, threads=None):
    """Pack ``spec`` with :func:`peclet.packing.pack` and measure it.

    threads: Numba threads for this call (None keeps the process's setting); set here, inside
    the task, because a Dask worker process does not inherit the caller's setting.
    Returns ``(result, pack)``: result a JSON-able dict (spec, id, state_hash, eps, eps_se,
    f_env, f_env_se, z_mean, rattlers, window, steps, timing, threads, host, pid; state_hash
    is ``PackResult.state_hash()``, SHA-256 of the positions' and quaternions' float64 bytes)
    and pack the
    frozen :class:`peclet.packing.bed.freeze.Pack`.
    """
    from peclet.packing import pack
    from peclet.packing.analysis import geometry as analysis
    from peclet.packing.analysis import coordination
    from peclet.packing.bed.threads import set_threads
    from peclet.packing.page.pipeline import CONTACT_GAP

    if threads is not None:
        set_threads(threads)
    import numba

    t0 = time.perf_counter()
    res = pack(element=spec.element, container=spec.container, count=spec.count,
               protocol=_protocol(spec), material=_material(spec), wall_material=None,
               seed=spec.seed, threads=None, progress=False)
    p = res.pack
    t1 = time.perf_counter()
    geo = analysis.PackGeometry(p)
    windows, wscale = analysis.bulk_windows(p)
    fr = analysis.cover_fractions(geo, windows[0], spec.mc_samples, seed=0)
    walls = res.container.solid_walls(float(p.positions[:, 1].max()) + 4 * res.container.d)
    con = coordination.engine_coordination(p, walls, gap=CONTACT_GAP * res.container.d,
                                           periodic=res.container.kind == "box")
    t2 = time.perf_counter()
    out = dict(spec=spec.as_dict(), id=spec.id,
               state_hash=res.state_hash(),
               eps=fr["eps"], eps_se=fr["eps_se"], f_env=fr["f_env"],
               f_env_se=fr["f_env_se"], z_mean=con["z_elem"], z_total=con["z_total"],
               rattlers=con["rattlers"], contact_method=con["method"], landed=res.landed,
               contact_gap=CONTACT_GAP, window=fr["window"], window_scale=wscale,
               steps=int(getattr(res, "steps", 0)),
               timing=dict(pack=t1 - t0, analysis=t2 - t1),
               threads=int(numba.get_num_threads()), host=platform.node(), pid=os.getpid())
    return out, p
