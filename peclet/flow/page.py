"""The flow stage of the page pipeline: ``peclet pall-ring --flow`` pushes a slow flow through
the frozen pack and adds k and dP/L against Ergun to the Results.

The pipeline (``peclet.packing.page.pipeline``) sits below ``peclet.flow`` in the layers
(docs/architecture.md §1), so it never imports this module: it runs the *stages* it is given
after the pack is frozen, and the command line composes them (``stages={"flow": stage(8)}``).
"""
from __future__ import annotations

import warnings

from peclet.core.validation import PecletArgumentError, check_float

from .permeability import ThinWallWarning, permeability

__all__ = ["FLOW_TOL", "check_resolution", "summary", "stage"]

#: Convergence tolerance of the page's flow run (relative, on the superficial velocity;
#: peclet.flow.solver): k to about 4 digits, in a few thousand steps at D/8.
FLOW_TOL = 1e-5

#: What ``res["flow"]`` keeps of :meth:`PackFlow.summary`.
_KEEP = ("resolution", "k_D2", "k_lattice", "dpdl_lattice", "Re", "eps", "eps_envelope",
         "d_sauter", "d_envelope", "kozeny", "ergun_ratio_sauter", "ergun_ratio_envelope",
         "drag_cv", "solid_drag_balance", "steps", "converged", "fluid_nodes", "dims",
         "window", "y_mode", "memory_MiB", "thin_wall_warning")


def check_resolution(resolution, box, name="flow"):
    """``resolution`` (cells per D) as a float; refused (PecletArgumentError naming ``name``)
    outside [4, 64] or when the periodic box side ``box`` (D) is not a whole number of cells."""
    r = check_float(name, resolution, 4.0, 64.0)
    if abs(box * r - round(box * r)) > 1e-9 * max(1.0, box * r):
        raise PecletArgumentError(name, f"a resolution N in [4, 64] cells per D with the box "
                                  f"side ({box:g} D) a whole number of cells, box * N integer",
                                  resolution)
    return r


def summary(pack, resolution, progress=False):
    """Permeability of ``pack`` at ``resolution`` cells per D (:func:`permeability` with
    :data:`FLOW_TOL`, a progress bar when ``progress``): the JSON-ready dict stored as
    ``res["flow"]`` (k in D^2 and cells^2, dP/L in lattice units, the Ergun viscous ratios
    (Sauter and envelope diameters), the Kozeny constant, porosity, steps, the thin-wall
    warning if any)."""
    from peclet.packing.bed.progress import Progress

    bar = Progress(100_000, desc=f"flow D/{resolution:g}", enabled=bool(progress), note=None)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ThinWallWarning)
        try:
            pf = permeability(pack, resolution=resolution, tol=FLOW_TOL, progress=bar)
        finally:
            bar.close()
    s = pf.summary()
    return {k: s[k] for k in _KEEP if k in s}


def stage(resolution):
    """The pipeline stage ``(pack, progress) -> dict`` that computes :func:`summary` at
    ``resolution`` (checked against the box with :func:`check_resolution` beforehand)."""
    return lambda pack, progress: summary(pack, resolution, progress=progress)
