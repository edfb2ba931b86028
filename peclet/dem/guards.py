"""Step guards: a non-finite or runaway state stops the step before it is committed."""
from __future__ import annotations

import numpy as np

#: Speed guard: |v| (and |omega| times the bounding radius) must stay below this many domain
#: sizes per unit time, or the step raises :class:`StepError`.
SPEED_BOUND_DOMAINS_PER_TIME = 1.0e3


class StepError(RuntimeError):
    """A step produced a non-finite or runaway state. ``step`` and ``particle`` name where.

    The simulation's state is left as it was before the failing step.
    """

    def __init__(self, message, step, particle):
        super().__init__(message)
        self.step = step
        self.particle = particle


def speed_bound(domain, pos, radii):
    """The speed limit: 1e3 times the domain's largest side, else that of the particles'
    bounding box plus two bounding radii."""
    if domain.lo is not None:
        size = float((domain.hi - domain.lo).max())
    else:
        ext = pos.max(axis=0) - pos.min(axis=0)
        size = float(ext.max()) + 2.0 * float(radii.max())
    return SPEED_BOUND_DOMAINS_PER_TIME * size


def check_state(x, q, v, w, radii, bound, step):
    """Raise :class:`StepError` naming ``step`` and the first particle whose state is
    non-finite or whose speed (|v|, or |omega| times its radius) exceeds ``bound``."""
    bad = ~(np.isfinite(x).all(axis=1) & np.isfinite(q).all(axis=1)
            & np.isfinite(v).all(axis=1) & np.isfinite(w).all(axis=1))
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise StepError(f"step {step}: particle {i} has a non-finite state "
                        f"(x={x[i]}, v={v[i]}, omega={w[i]})", step, i)
    speed = np.maximum(np.sqrt((v ** 2).sum(axis=1)), np.sqrt((w ** 2).sum(axis=1)) * radii)
    fast = speed > bound
    if np.any(fast):
        i = int(np.flatnonzero(fast)[0])
        raise StepError(f"step {step}: particle {i} moves at {speed[i]:.6g} > the bound "
                        f"{bound:.6g} (1e3 domain sizes per unit time)", step, i)
