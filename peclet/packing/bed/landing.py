"""The landing rule of a pour: did the bed land before the quench, and is anything left in the
air when the run ends (docs/architecture.md §10). Reads the state only: no run's numbers
depend on it."""
from __future__ import annotations

import math

import numpy as np

from peclet.core.validation import PecletArgumentError

#: A body moving faster than this (D/time) when the quench starts has not landed.
LAND_SPEED = 1.0

#: A body whose bounding sphere is farther than this (D) from the floor and from every
#: supported body's bounding sphere when the run ends is in the air (:func:`in_air`).
AIR_GAP = 0.25


class LandingWarning(RuntimeWarning):
    """A run's quench started while elements were still falling (see the module notes)."""


def landing_state(sim, ctx, st, protocol=None):
    """The landing rule's record of the current state (reads it only): step, bodies, bodies
    moving faster than LAND_SPEED D/time, the largest speed (D/time), the threshold, for the
    page protocol the start cloud's free-fall time and the time before the quench
    (``fall_time``, ``landing_time``; None otherwise), and ``landed``: no body that fast and
    (page) a fall time within the time before the quench. (The speed alone misses bodies
    still in the air that a tap's upward kick slowed.)"""
    d = ctx["body"].d
    n = sim.num_particles()
    v = np.asarray(sim.get_velocities(), dtype=np.float64).reshape(n, 3) if n \
        else np.zeros((0, 3))
    speed = np.sqrt((v * v).sum(axis=1)) / d
    moving = int(np.count_nonzero(speed > LAND_SPEED))
    fall = ctx.get("fall_time")
    before = getattr(protocol, "landing_time", None) if fall is not None else None
    late = fall is not None and before is not None and fall > before
    return dict(step=int(st.step), bodies=int(n), moving=moving,
                max_speed=float(speed.max()) if n else 0.0, threshold=LAND_SPEED,
                fall_time=fall, landing_time=before, landed=moving == 0 and not late)


def in_air(positions, r_b, d, container, gap=AIR_GAP):
    """Boolean (N,): the bodies in the air, reading positions only.

    A body is supported when its bounding sphere (radius ``r_b``, world) comes within
    ``gap`` D (``d`` the element diameter, world) of the floor (``container.floor_y``) or, in
    a tree container, of the wall (its fluid region's phi at the centre >= -(r_b + gap d)),
    or within ``gap`` D of a supported body's bounding sphere (minimum images in a periodic
    box). The rest are in the air: at the end of a run, nothing at rest is. Bounding spheres
    hold the elements, so a body resting on another is always linked to it."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    P = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    n = len(P)
    if n == 0:
        return np.zeros(0, bool)
    g = float(gap) * float(d)
    seed = P[:, 1] - r_b <= container.floor_y + g
    if container.kind == "tree":
        seed |= container.fluid_phi(P) >= -(r_b + g)
    X = P.copy()
    box = None
    if any(container.periodic):
        L = container.period
        span = float(X[:, 1].max() - X[:, 1].min()) + 4.0 * r_b + 2.0 * g + 1.0
        X[:, 0] = np.mod(X[:, 0], L[0])
        X[:, 2] = np.mod(X[:, 2], L[1])
        X[:, 1] -= X[:, 1].min()
        box = np.array([L[0], 2.0 * span, L[1]])
        X = np.minimum(X, np.nextafter(box, 0.0))     # a coordinate rounded up to L
    pairs = cKDTree(X, boxsize=box).query_pairs(2.0 * r_b + g, output_type="ndarray")
    # node n is the floor (and walls): an edge from it to every seed
    s = np.flatnonzero(seed)
    rows = np.concatenate([pairs[:, 0], np.full(len(s), n)])
    cols = np.concatenate([pairs[:, 1], s])
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n + 1, n + 1))
    _, label = connected_components(graph, directed=False)
    return label[:n] != label[n]


def record_in_air(sim, ctx, st):
    """Add the end-of-run count of bodies in the air (:func:`in_air`) to the landing record
    ``st.landing``: ``in_air``, ``air_step`` (the run's last step), ``air_gap`` (D) and
    ``air_top`` (the highest such centre above the floor, D); a run with any is not
    ``landed``."""
    rec = st.landing
    body, cont = ctx["body"], ctx["container"]
    n = sim.num_particles()
    P = np.asarray(sim.get_positions(), dtype=np.float64).reshape(n, 3) if n \
        else np.zeros((0, 3))
    air = in_air(P, body.r_b, body.d, cont)
    k = int(np.count_nonzero(air))
    rec.update(in_air=k, air_step=int(st.step), air_gap=AIR_GAP,
               air_top=float((P[air, 1].max() - cont.floor_y) / body.d) if k else 0.0)
    rec["landed"] = bool(rec["landed"]) and k == 0
    return rec


def check_gravity(value, name="gravity"):
    """``value`` as the magnitude of g (length/time^2): a finite number > 0. Every protocol
    applies it along -y, towards the floor (or a tree container's bottom) its bed forms on; a
    negative magnitude would point up, lifting the bodies off the floor, and zero would leave
    them where they were put: either run returns a "bed" that never formed.
    PecletArgumentError naming ``name``."""
    try:
        g = float(value) if not isinstance(value, (bool, str)) else math.nan
    except (TypeError, ValueError):
        g = math.nan
    if not (math.isfinite(g) and g > 0.0):
        raise PecletArgumentError(
            name, "the magnitude of g, a finite number > 0 (length/time^2, acting along -y "
            "towards the floor the protocol builds its bed on)", value,
            "g < 0 points up, away from the floor, and g = 0 switches gravity off: no bed "
            "forms" if math.isfinite(g) else "")
    return g
