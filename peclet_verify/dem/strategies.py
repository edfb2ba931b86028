"""Hypothesis strategies of the DEM family: rigid-body states and contact-capacity sequences
(peclet's own engine), and pours with capacity hints described as page-API
:class:`~peclet_verify.scenario.Scenario` s (any DEM backend).

Every value is drawn on an integer grid, so a failing input shrinks in few steps, and every
input prints as runnable code (``repr``, ``snippet``). Units: m, s, kg; gravity 9.81 m/s^2
along -y.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from hypothesis import strategies as st

from ..checks import check_int
from ..scenario import STATE, Scenario

__all__ = ["RigidState", "rigid_states", "capacity_sequences", "G", "box_encoding", "Pour",
           "pours", "pour_scenario", "capacity_hints"]

G = 9.81


# ---------------------------------------------------------------------------- DEM states
@dataclass(frozen=True, eq=False)
class RigidState:
    """Rigid-body state arrays (float64): positions (n, 3), quaternions (n, 4) (x, y, z, w),
    velocities (n, 3) and world-frame angular velocities (n, 3)."""

    positions: np.ndarray
    quaternions: np.ndarray
    velocities: np.ndarray
    angular_velocities: np.ndarray

    @property
    def n(self) -> int:
        return len(self.positions)

    def __repr__(self):
        # Python float reprs round-trip exactly, so the text rebuilds the same bits
        def a(x):
            return f"np.array({np.asarray(x, dtype=np.float64).tolist()!r})"
        return (f"RigidState(positions={a(self.positions)}, "
                f"quaternions={a(self.quaternions)}, "
                f"velocities={a(self.velocities)}, "
                f"angular_velocities={a(self.angular_velocities)})")

    def snippet(self) -> str:
        """Runnable Python that rebuilds this state (bit for bit) as ``state``."""
        return ("import numpy as np\nfrom peclet_verify.dem.strategies import RigidState\n"
                f"state = {self!r}")


def rigid_states(n, box=((0.0, 0.0, 0.0), (4.0, 4.0, 4.0)), max_speed: float = 1.0,
                 max_spin: float = 1.0) -> st.SearchStrategy:
    """:class:`RigidState` of ``n`` bodies with positions in ``box=(lo, hi)`` (on a 4096-step
    grid per axis), velocity components in [-max_speed, max_speed] and world-frame spins in
    [-max_spin, max_spin] rad/s (2048 steps each side), unit quaternions (x, y, z, w) (axis
    from integer components in [-256, 256], angle a multiple of pi/256).

    ``n`` is an int >= 1, a pair ``(min_n, max_n)`` (best: bodies form a list Hypothesis can
    delete from anywhere, so a failing state shrinks to its few relevant bodies), or a
    strategy of ints >= 1 (the count is drawn first; shrinking can only drop trailing bodies).
    Every value is drawn as an integer on its grid, so a failing state shrinks in seconds
    towards bodies at rest at ``lo`` with identity rotations; ``repr(state)`` /
    ``state.snippet()`` rebuilds it bit for bit.
    """
    lo = np.asarray(box[0], float).reshape(3)
    hi = np.asarray(box[1], float).reshape(3)
    if not np.all(lo <= hi):
        raise ValueError(f"box must satisfy lo <= hi, got {box!r}")
    for nm, v in (("max_speed", max_speed), ("max_spin", max_spin)):
        if not (math.isfinite(v) and v >= 0):
            raise ValueError(f"{nm} must be finite and >= 0, got {v!r}")

    def grid(lo_, hi_, steps=4096):
        # quantised values shrink in few steps (float arrays can take minutes to shrink)
        return st.integers(0, steps).map(lambda k: lo_ + (hi_ - lo_) * k / steps)

    def sym(h, steps=2048):
        return st.integers(-steps, steps).map(lambda k: h * k / steps)

    def quat(ix, iy, iz, k, steps=256):
        nrm = math.sqrt(ix * ix + iy * iy + iz * iz)
        ax = (1.0, 0.0, 0.0) if nrm == 0 else (ix / nrm, iy / nrm, iz / nrm)
        half = 0.5 * math.pi * k / steps
        s, c = math.sin(half), math.cos(half)
        return (ax[0] * s, ax[1] * s, ax[2] * s, c)

    comp = st.integers(-256, 256)
    body = st.tuples(st.tuples(*(grid(lo[a], hi[a]) for a in range(3))),
                     st.builds(quat, comp, comp, comp, st.integers(0, 256)),
                     st.tuples(*(sym(max_speed) for _ in range(3))),
                     st.tuples(*(sym(max_spin) for _ in range(3))))

    def state(bodies):
        k = len(bodies)
        pos, quats, vel, spin = (np.array([b[j] for b in bodies], dtype=np.float64)
                                 for j in range(4))
        return RigidState(pos.reshape(k, 3), quats.reshape(k, 4), vel.reshape(k, 3),
                          spin.reshape(k, 3))

    if isinstance(n, st.SearchStrategy):
        @st.composite
        def counted(draw):
            k = draw(n)
            if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
                raise ValueError(f"n must draw ints >= 1, got {k!r}")
            return state([draw(body) for _ in range(k)])
        return counted()
    if isinstance(n, (tuple, list)):
        if len(n) != 2:
            raise ValueError(f"n must be an int >= 1, a pair (min_n, max_n) or a strategy, "
                             f"got {n!r}")
        n_lo = check_int(n[0], "n[0] (min_n)", 1)
        n_hi = check_int(n[1], "n[1] (max_n)", n_lo)
    else:
        n_lo = n_hi = check_int(n, "n", 1)
    return st.lists(body, min_size=n_lo, max_size=n_hi).map(state)


def capacity_sequences(min_capacity: int = 1, max_capacity: int = 64, max_size: int = 6):
    """Lists of contact-buffer capacities (ints in [min_capacity, max_capacity]) to apply in
    order; shrinks towards one capacity of ``min_capacity``."""
    lo = check_int(min_capacity, "min_capacity", 1)
    hi = check_int(max_capacity, "max_capacity", lo)
    size = check_int(max_size, "max_size", 1)
    return st.lists(st.integers(lo, hi), min_size=1, max_size=size)


def box_encoding(half, translation=(0.0, 0.0, 0.0), rotation=None):
    """(node_ints, node_reals, root) as plain lists: the flat encoding of one box leaf of half
    extents ``half``, placed by ``translation`` and ``rotation`` (x, y, z, w)."""
    from peclet.core.geom import SceneBuilder
    b = SceneBuilder()
    r = b.add_leaf("box", [float(h) for h in half], translation=list(translation),
                   rotation=None if rotation is None else list(rotation))
    ni, nr, _, _ = b.encode()
    return ni.tolist(), nr.tolist(), int(r)


# ---------------------------------------------------------------------------- the pour
@dataclass(frozen=True)
class Pour:
    """Spheres (radii ``radii``, unit inverse mass) on a jittered lattice in a box container
    (an inverted box wall, floor y = 0), poured under gravity for ``steps`` steps of ``dt``."""

    radii: tuple
    jitter: tuple          # (n, 3) in units of 1/64 of the smallest radius
    velocities: tuple      # (n, 3) m/s
    e: float
    mu: float
    steps: int = 120
    dt: float = 2e-3

    @property
    def n(self):
        return len(self.radii)


def pour_scenario(p: Pour, capacity=None, contact_capacity=None, record_every=20) -> Scenario:
    """The page-API run of a :class:`Pour`."""
    r = np.asarray(p.radii, float)
    rmax, rmin = float(r.max()), float(r.min())
    pitch = 2.1 * rmax + 0.5 * rmin     # no overlap whatever the jitter (<= rmin / 4)
    per_row = 3
    idx = np.arange(p.n)
    cells = np.stack([idx % per_row, idx // (per_row * per_row), (idx // per_row) % per_row],
                     axis=1).astype(float)
    jit = np.asarray(p.jitter, float).reshape(p.n, 3) * rmin / 64.0
    pos = (cells + 0.5) * pitch + jit
    pos[:, 1] += 0.2 * rmax
    L = per_row * pitch
    H = float(pos[:, 1].max() + 2.0 * rmax)
    ni, nr, root = box_encoding((L / 2, H / 2, L / 2), (L / 2, H / 2, L / 2))
    shapes = sorted(set(r.tolist()))
    calls = [("set_domain", ([-0.5 * L, -0.5 * L, -0.5 * L], [1.5 * L, H + L, 1.5 * L])),
             ("set_gravity", (0.0, -G, 0.0)),
             ("set_material_params", (p.e, 0.0, p.mu)),
             ("set_solver_iterations", (10, 8))]
    calls += [("add_sphere_shape", (s,)) for s in shapes]
    calls += [("add_analytic_wall", (ni, nr, root, True, p.e, p.mu)),
              ("set_positions", (pos,)),
              ("set_shape_ids", ([shapes.index(x) for x in r.tolist()],)),
              ("set_velocities", (np.asarray(p.velocities, float).reshape(p.n, 3),)),
              ("set_inv_mass", ([1.0] * p.n,)),
              ("set_inv_inertia", ([[2.5 / x ** 2] * 3 for x in r.tolist()],))]
    return Scenario(p.n if capacity is None else capacity, calls, p.dt, p.steps,
                    record=STATE + ("contacts",), record_every=record_every,
                    contact_capacity=contact_capacity,
                    label=f"pour of {p.n} spheres in a box", meta={"n_bodies": p.n,
                                                                   "radii": list(p.radii)})


def pours(n=(4, 12), steps=120) -> st.SearchStrategy:
    """:class:`Pour` of n (an int or (min, max)) spheres, radii 0.05 .. 0.1 m (two sizes), e in
    [0, 0.9], mu in [0, 0.8], speeds up to 1 m/s."""
    lo, hi = (n, n) if isinstance(n, int) else n

    def build(big, sizes, jit, vel, e, mu):
        m = len(sizes)
        radii = tuple(0.1 if s else 0.1 * big / 8 for s in sizes)
        return Pour(radii, tuple(map(tuple, np.asarray(jit[:m * 3]).reshape(m, 3).tolist())),
                    tuple(tuple(v / 64 for v in vel[3 * i:3 * i + 3]) for i in range(m)),
                    e / 10, mu / 10, steps)
    return st.integers(lo, hi).flatmap(lambda m: st.builds(
        build, st.integers(4, 8), st.lists(st.booleans(), min_size=m, max_size=m),
        st.lists(st.integers(-16, 16), min_size=3 * m, max_size=3 * m),
        st.lists(st.integers(-64, 64), min_size=3 * m, max_size=3 * m),
        st.integers(0, 9), st.integers(0, 8)))


def capacity_hints(max_size=3) -> st.SearchStrategy:
    """Lists of (particle capacity hint, contact capacity hint) pairs, each forcing growth:
    particle hints 1 .. 4, contact hints 1 .. 8."""
    return st.lists(st.tuples(st.integers(1, 4), st.integers(1, 8)), min_size=1,
                    max_size=max_size)
