"""``peclet warm``: compile the Numba kernels of a run ahead (a fresh install's first minute).

    peclet warm

Compiles the DEM step's kernels in a child process while this one compiles the quadrature and
the shell probes (on a small solid: :func:`peclet.dem.scene_particle.compile_kernels`) and then
the Hertz–Mindlin substep, so they land in Numba's on-disk cache on two cores at once; last
the colour-by-colour solve of large beds (``peclet stir``'s path). Every later run (and the
test suite) then starts without compiling them. Prints what was compiled and how long it took;
nothing else is written. See :mod:`peclet.dem.warm`.
"""
from __future__ import annotations

import time

__all__ = ["add_parser", "run"]


def add_parser(sub):
    p = sub.add_parser("warm", help="compile the kernels ahead into Numba's cache",
                       description="Compile the DEM step's and the quadrature's Numba kernels "
                       "into the on-disk cache, two processes at once.")
    p.set_defaults(func=run)
    return p


def run(args):
    from peclet.dem import scene_particle, warm
    from peclet.dem.simulation import step_kernels_cached

    t0 = time.perf_counter()
    child = warm.start_background()
    scene_particle.compile_kernels()                      # the quadrature's kernels, here
    t_quad = time.perf_counter() - t0
    warm.compile_step_kernels("hertz")                    # beside the detection's child
    ok = warm.finish(child)
    if not ok:                                            # compile them here instead
        warm.compile_step_kernels()
    warm.compile_step_kernels("colored")                  # loads the detection just cached
    t = time.perf_counter() - t0
    dem = "already cached" if child is None else ("compiled beside it" if ok
                                                  else "compiled after it (the child failed)")
    print(f"quadrature kernels: {t_quad:.0f} s; DEM step kernels: {dem}; Hertz substep and "
          f"coloured solve: after them; total {t:.0f} s; "
          f"cached now: {bool(step_kernels_cached())}")
    return 0
