"""Step guards: a non-finite or runaway state stops the step before it is committed."""
from __future__ import annotations

import math

from numba import njit

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


@njit(cache=True)
def _first_bad(x, q, v, w, radii, bound):
    """(0, -1) when every particle is finite and within the speed bound; else (1, i) for the
    first non-finite particle i, or (2, i) for the first too fast one (finiteness first)."""
    n = x.shape[0]
    for i in range(n):
        for e in range(3):
            if not (math.isfinite(x[i, e]) and math.isfinite(v[i, e])
                    and math.isfinite(w[i, e])):
                return 1, i
        for e in range(4):
            if not math.isfinite(q[i, e]):
                return 1, i
    for i in range(n):
        sv = math.sqrt(v[i, 0] ** 2 + v[i, 1] ** 2 + v[i, 2] ** 2)
        sw = math.sqrt(w[i, 0] ** 2 + w[i, 1] ** 2 + w[i, 2] ** 2) * radii[i]
        if max(sv, sw) > bound:
            return 2, i
    return 0, -1


def check_state(x, q, v, w, radii, bound, step, cause=""):
    """Raise :class:`StepError` naming ``step`` and the first particle whose state is
    non-finite or whose speed (|v|, or |omega| times its radius) exceeds ``bound``; ``cause``
    (the user's inputs that stage of the step applied, e.g. the gravity times dt) is added
    to the message."""
    kind, i = _first_bad(x, q, v, w, radii, float(bound))
    tail = f"; {cause}" if cause else ""
    if kind == 1:
        raise StepError(f"step {step}: particle {i} has a non-finite state "
                        f"(x={x[i]}, v={v[i]}, omega={w[i]}){tail}", step, i)
    if kind == 2:
        # hypot: an overflowing square must not turn a huge speed into inf (or a warning)
        speed = max(math.hypot(*v[i]), math.hypot(*w[i]) * float(radii[i]))
        raise StepError(f"step {step}: particle {i} moves at {speed:.6g} > the bound "
                        f"{bound:.6g} (1e3 domain sizes per unit time){tail}", step, i)
