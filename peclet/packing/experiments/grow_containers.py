"""The containers a growth run shrinks (:mod:`peclet.packing.experiments.grow`, issue 41 item 5).

Growing every body by s about its centre in a fixed container is, up to a change of unit
(lengths divided by s), the same configuration as keeping the bodies and shrinking the
container by 1/s about its centre while the centres follow the same affine map. The element's
shape (its probes, distance grid, pruned programs) is then built once, whatever s. Each
container holds a linear size ``L`` and maps it onto the simulation:

- ``periodic`` (:class:`PeriodicCube`): a triply periodic cube of side L (world length) sized
  by the count and ``phi_start``; positions are scaled into [0, L) (issue 23's growth, the same
  bits as before this module);
- ``box:AxBxC`` (:class:`ClosedBox`): a closed box of inner sides A, B, C element diameters D
  at the start, centred on the origin, six walls (slabs 1 D thick, each reaching 2 D past the
  box's other faces so the corners stay closed). L is the scale (1 at the start): the wall of
  face +-x stands at +-L A D / 2, put there by ``Simulation.set_wall_transform`` (a pose, no
  velocity: the wall is moved between steps, as the periodic cube is resized). The start
  fraction N V_env / (A B C D^3) is the box's, and must be at most ``PHI_START_MAX``;
- ``column:N`` (:class:`ClosedColumn`): a closed column of diameter N D at the start, axis y
  through the origin, a floor and a lid (slabs, moved as the box's) at -+L H / 2, the height H
  sized by the count and ``phi_start``. A wall's pose is rigid, and no pose shrinks a straight
  cylinder, so the side wall is an inverted cone of taper k = ``COLUMN_TAPER`` D / H (its radius
  grows by k per unit height): between floor and lid it is a cylinder to within
  ``COLUMN_TAPER`` D, and lifting it by Delta shrinks its radius at every height by k Delta, so
  at scale L it is lifted by R (1 - L) / k (about 1e5 D: a long cone, float64 distances to
  1e-11 D). Its volume between floor and lid is pi (R^2 H + k^2 H^3 / 12) L^3, exact.

Every container gives the simulation its domain (for the speed guard), places the start
centres (the walled ones at least a bounding radius inside every wall, so no body starts in a
wall), and answers what the growth loop asks: the volume at L, the L of a given envelope
fraction, whether L is too small to go on, and the L that opens the container by an overlap.
"""
from __future__ import annotations

import math

import numpy as np

from peclet.core import geom
from peclet.core.validation import PecletArgumentError, check_float

__all__ = ["GROW_CONTAINERS", "parse_grow_container", "make_container", "PeriodicCube",
           "ClosedBox", "ClosedColumn", "COLUMN_TAPER", "PHI_START_MAX", "WALL_THICKNESS"]

GROW_CONTAINERS = ("'periodic' (a periodic cube sized by the count), 'box:AxBxC' (a closed "
                   "box, six walls) or 'column:N' (a closed column: cylinder, floor and lid), "
                   "sizes in element diameters D, each in [1.5, 1e4]")
#: The densest start: random centres relaxed apart (a walled box's start fraction is its own).
PHI_START_MAX = 0.4
#: A column's radius differs by at most this (in D) between its floor and its lid.
COLUMN_TAPER = 1e-4
#: Wall slab thickness, in D.
WALL_THICKNESS = 1.0
#: Accepted container sizes (D), those of peclet.packing.bed.containers.
SIZE_RANGE = (1.5, 1e4)
#: The lid's clearance below the cone's top end, in D.
_CONE_CLEARANCE = 2.0


def parse_grow_container(value, arg="container"):
    """(kind, sizes) of a growth container: ("periodic", ()), ("box", (A, B, C)) or
    ("column", (N,)), sizes in D. PecletArgumentError naming ``arg`` otherwise."""
    if value == "periodic":
        return "periodic", ()
    kind, sep, rest = str(value).partition(":") if isinstance(value, str) else ("", "", "")
    parts = rest.split("x") if kind == "box" else [rest]
    try:
        nums = tuple(float(p) for p in parts)
    except ValueError:
        nums = ()
    if not sep or kind not in ("box", "column") or len(nums) != (3 if kind == "box" else 1):
        hint = ("; box:L is the periodic box of rain and page packs: leave the container out "
                "for the periodic cube") if kind == "box" and len(nums) == 1 else ""
        raise PecletArgumentError(arg, GROW_CONTAINERS, value, hint.lstrip("; "))
    for v in nums:
        check_float(arg, v, *SIZE_RANGE)
    return kind, nums


def make_container(spec, model, env_one):
    """The container of ``spec`` (a checked GrowSpec) for ``model`` (an ElementModel) whose
    envelope volume is ``env_one`` (world length^3, a body's). PecletArgumentError naming
    "container" (a box too small for the count) or "target_phi" (not above the start
    fraction)."""
    kind, size = parse_grow_container(spec.container)
    n, d, rb = spec.count, model.d, model.bounding_radius
    if kind == "periodic":
        out = PeriodicCube(n, env_one, spec.phi_start, rb)
    elif kind == "box":
        out = ClosedBox(n, 0.5 * np.asarray(size) * d, d, rb, (spec.wall_e_n, spec.wall_mu),
                        n * env_one)
        if out.phi_start > PHI_START_MAX:
            raise PecletArgumentError(
                "container", f"a closed box holding count = {n} bodies at a start fraction "
                f"N V_env / V <= {PHI_START_MAX:g}", spec.container,
                f"{out.phi_start:.4g}: a larger box or fewer bodies")
    else:
        R = 0.5 * size[0] * d
        out = ClosedColumn(n, R, n * env_one / (spec.phi_start * math.pi * R * R), d, rb,
                           (spec.wall_e_n, spec.wall_mu), n * env_one)
    if spec.target_phi is not None and not spec.target_phi > out.phi_start:
        raise PecletArgumentError("target_phi", f"above the start fraction {out.phi_start:.4g} "
                                  f"of the {kind} container", spec.target_phi)
    return out


class PeriodicCube:
    """The triply periodic cube of issue 23 (module notes); ``L`` its side (world)."""

    periodic = True
    kind = "periodic"

    def __init__(self, n, env_one, phi_start, rb):
        self.n, self.env_one, self.phi_start, self.rb = n, env_one, phi_start, rb

    def place(self, sim, rng):
        """Side L of the start cube and n uniform centres in it (the domain set)."""
        n = self.n
        L = (n * self.env_one / self.phi_start) ** (1.0 / 3.0)
        sim.set_domain([0.0, 0.0, 0.0], [L, L, L])
        return L, rng.uniform(0.0, L, size=(n, 3))

    def volume(self, L):
        return L ** 3

    def size_at(self, env, phi):
        """The side at which ``env`` fills the cube to ``phi``."""
        return (env / phi) ** (1.0 / 3.0)

    def too_small(self, L):
        """True when the cube no longer holds a body's periodic images apart."""
        return L <= 2.0 * (2.0 * self.rb) * 1.05

    def resize(self, sim, L_old, L_new):
        f = L_new / L_old
        sim.set_positions(np.minimum(sim.get_positions() * f, np.nextafter(L_new, 0.0)))
        sim.set_domain([0.0, 0.0, 0.0], [L_new, L_new, L_new])

    def opened(self, L, ov, d):
        """The side that opens the cube by half the overlap ``ov`` (in ``d``)."""
        return L * (1.0 + 0.5 * ov * d / L)

    def describe(self, L, d):
        return dict(kind="periodic", size=[L / d] * 3, scale=1.0, label=f"periodic cube "
                    f"{L / d:.4f} D")


class _Walled:
    """What the closed containers share: walls moved by their poses, centres scaled about the
    origin; ``L`` the scale (1 at the start)."""

    periodic = False

    def _add(self, sim, builder, root, invert):
        ni, nr, _, _ = builder.encode()
        return sim.add_analytic_wall(ni, nr, root, invert, self.mat[0], self.mat[1])

    def _slab(self, sim, centre, half):
        b = geom.SceneBuilder()
        return self._add(sim, b, b.add_leaf("box", list(half), translation=list(centre)),
                         False)

    def place(self, sim, rng):
        """Walls added, the domain set (the start's walls' box), centres drawn inside."""
        self.walls = self._walls(sim)
        hi = np.asarray(self.outer)
        sim.set_domain(list(-hi), list(hi))
        return 1.0, self._centres(rng, self.n)

    def size_at(self, env, phi):
        return (env / (phi * self.volume(1.0))) ** (1.0 / 3.0)

    def too_small(self, L):
        return L * self.min_width <= 2.0 * self.rb * 1.05 or L < self.l_min

    def resize(self, sim, L_old, L_new):
        sim.set_positions(sim.get_positions() * (L_new / L_old))
        for w, t in zip(self.walls, self._poses(L_new)):
            sim.set_wall_transform(w, t)

    def opened(self, L, ov, d):
        return L * (1.0 + 0.5 * ov * d / (L * self.min_width))


class ClosedBox(_Walled):
    """A closed box (module notes): ``half`` (3,) the inner half-sides at the start (world)."""

    kind = "box"

    def __init__(self, n, half, d, rb, mat, env):
        self.n, self.half, self.d, self.rb, self.mat = n, np.asarray(half, float), d, rb, mat
        self.min_width = 2.0 * float(self.half.min())
        self.l_min = 0.0
        self.outer = self.half + WALL_THICKNESS * d * 2.0
        self.phi_start = env / self.volume(1.0)

    def volume(self, L):
        return float(np.prod(2.0 * self.half)) * L ** 3

    def _walls(self, sim):
        T = WALL_THICKNESS * self.d
        out = []
        for axis in range(3):
            for sign in (-1.0, 1.0):
                half = self.half + 2.0 * T
                half[axis] = T
                centre = np.zeros(3)
                centre[axis] = sign * (self.half[axis] + T)
                out.append(self._slab(sim, centre, half))
        return out

    def _poses(self, L):
        for axis in range(3):
            for sign in (-1.0, 1.0):
                t = np.zeros(3)
                t[axis] = -sign * self.half[axis] * (1.0 - L)
                yield t

    def _centres(self, rng, n):
        room = self.half - self.rb
        if np.any(room <= 0.0):
            raise PecletArgumentError("container", "a closed box wider than the element's "
                                      "bounding ball on every side", "box",
                                      f"bounding radius {self.rb / self.d:.4g} D")
        return rng.uniform(-1.0, 1.0, size=(n, 3)) * room

    def describe(self, L, d):
        size = (2.0 * self.half * L / d).tolist()
        return dict(kind="box", size=size, start_size=(2.0 * self.half / d).tolist(), scale=L,
                    label="closed box " + " x ".join(f"{s:.4f}" for s in size) + " D")


class ClosedColumn(_Walled):
    """A closed column (module notes): radius ``R`` and height ``H`` at the start (world)."""

    kind = "column"

    def __init__(self, n, R, H, d, rb, mat, env):
        self.n, self.R, self.H, self.d, self.rb, self.mat = n, R, H, d, rb, mat
        self.k = COLUMN_TAPER * d / H
        self.min_width = min(2.0 * R, H)
        # the cone is long enough for the container to shrink until the envelopes fill it
        self.l_min = (env / self.volume(1.0)) ** (1.0 / 3.0)
        T = WALL_THICKNESS * d
        self.outer = np.array([R + 2.0 * T, 0.5 * H + 2.0 * T, R + 2.0 * T])
        self.phi_start = env / self.volume(1.0)

    def volume(self, L):
        return math.pi * (self.R ** 2 * self.H + self.k ** 2 * self.H ** 3 / 12.0) * L ** 3

    def _walls(self, sim):
        T, R, H, k = WALL_THICKNESS * self.d, self.R, self.H, self.k
        half = [R + 2.0 * T, T, R + 2.0 * T]
        out = [self._slab(sim, [0.0, -0.5 * H - T, 0.0], half),
               self._slab(sim, [0.0, 0.5 * H + T, 0.0], half)]
        top = 0.5 * H + _CONE_CLEARANCE * self.d            # the cone's top end (start pose)
        lift = R * (1.0 - 0.99 * self.l_min) / k             # the most it is ever lifted
        hh = 0.5 * (top + 0.5 * H + _CONE_CLEARANCE * self.d + lift)
        yc = top - hh
        r_top = R + k * top                                  # radius R + k y at y = top
        b = geom.SceneBuilder()
        cone = b.add_leaf("cone", [r_top - 2.0 * k * hh, r_top, hh], translation=[0.0, yc, 0.0])
        out.append(self._add(sim, b, cone, True))
        return out

    def _poses(self, L):
        yield np.array([0.0, 0.5 * self.H * (1.0 - L), 0.0])
        yield np.array([0.0, -0.5 * self.H * (1.0 - L), 0.0])
        yield np.array([0.0, self.R * (1.0 - L) / self.k, 0.0])

    def _centres(self, rng, n):
        rr = self.R - self.rb - 0.5 * self.k * self.H
        hy = 0.5 * self.H - self.rb
        if rr <= 0.0 or hy <= 0.0:
            raise PecletArgumentError("container", "a closed column wider and taller than the "
                                      "element's bounding ball", "column",
                                      f"bounding radius {self.rb / self.d:.4g} D")
        out = np.zeros((0, 2))
        while len(out) < n:                  # uniform in the disc, by rejection, in blocks
            xz = rng.uniform(-rr, rr, size=(2 * n, 2))
            out = np.vstack([out, xz[(xz * xz).sum(axis=1) <= rr * rr]])
        y = rng.uniform(-hy, hy, size=n)
        return np.column_stack([out[:n, 0], y, out[:n, 1]])

    def describe(self, L, d):
        return dict(kind="column", size=[2.0 * self.R * L / d, self.H * L / d],
                    start_size=[2.0 * self.R / d, self.H / d], scale=L, taper=COLUMN_TAPER,
                    label=f"closed column D_t {2.0 * self.R * L / d:.4f} D, height "
                    f"{self.H * L / d:.4f} D")
