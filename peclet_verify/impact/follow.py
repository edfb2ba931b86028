"""The one loop every impact adapter runs (stdlib only: a child process in another venv loads
this file by path, with :mod:`peclet_verify.impact.cases`)."""
from __future__ import annotations

__all__ = ["follow_impact"]


def follow_impact(advance, overlap, normal_force, dt, max_steps):
    """Step an engine until the contact that ``overlap()`` (m, > 0 in contact) measures has
    begun and ended: ``advance()`` makes one step of ``dt``; ``normal_force()`` is the normal
    force (N) of the step just made. Returns (delta_max, f_max, contact_time or None if the
    contact did not end within ``max_steps``). One loop for every engine adapter."""
    d_prev, t, t_in = overlap(), 0.0, None
    dmax = fmax = 0.0
    for _ in range(max_steps):
        advance()
        t += dt
        d = overlap()
        fmax = max(fmax, normal_force())
        dmax = max(dmax, d)
        if t_in is None and d > 0.0 >= d_prev:
            t_in = t - dt * d / (d - d_prev)
        if t_in is not None and d <= 0.0 < d_prev:
            return dmax, fmax, t - dt * d / (d - d_prev) - t_in
        d_prev = d
    return dmax, fmax, None
