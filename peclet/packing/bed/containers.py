"""Containers of a pack: the page's periodic box, a column, a walled box, any CSG tree.

World frame (docs/architecture.md §10): y up, gravity along -y, the floor's top face at y = 0. A
container is a set of static wall trees (``Simulation.add_analytic_wall``) plus the lateral
geometry the protocols need to place elements (:meth:`Container.sample_xz`) and that the analysis
needs (:attr:`Container.period`, the ``Pack.box``).

Sizes given in a spec string are in element diameters D (the element's envelope outer
diameter); :meth:`Container.bound` turns them into world lengths for a given D.

- ``box:L``: periodic in x and z over [0, L D), the page's floor (as ``freeze.add_floor``).
- ``column:N``: a cylinder of diameter D_t = N D, axis along y through (c, c) with
  c = N D / 2 + D (one diameter of clearance to the period, so that the analysis's periodic
  images of one side never come within D of the other side), a floor at y = 0.
- ``walled:Lx,Lz``: the interior [D, D + Lx D] x [D, D + Lz D], four side walls and the floor.
- ``(builder, root)`` (world lengths, not scaled): the tree's solid is the FLUID region and its
  complement is the wall (``invert=True``): the tree must include its own floor.

Wall trees of a column or a walled box reach from below the floor to ``y_top`` (sized by the
protocol from the element count, so no count is too large for them).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from peclet.core import geom
from peclet.core.validation import PecletArgumentError, check_float

from .user_shapes import is_user_file, mesh_container_tree

__all__ = ["Container", "parse_container", "CONTAINER_FORMS", "MIN_WIDTH", "MAX_WIDTH",
           "MAX_DROP"]

CONTAINER_FORMS = "'box:L', 'column:N', 'walled:Lx,Lz' (in element diameters), a Container, " \
                  "a (builder, root) fluid-region tree or a closed mesh file of the fluid " \
                  "region (vessel.stl[:scale=S,resolution=H])"

#: The narrowest column diameter / box side accepted, in element diameters.
MIN_WIDTH = 1.5
#: The widest (issue 45, extreme numbers): the count cap (100 000) and the film rule (at least
#: one element per D^2 of cross-section) already keep a runnable box or column below ~320 D;
#: beyond 1e4 D its areas and start clouds only overflow.
MAX_WIDTH = 1e4
#: The largest rain drop height (D) and insertion speed (D / time): a drop of 1e4 D already
#: falls for ~2e4 steps of every batch; beyond, the start cloud leaves the DEM's lengths.
MAX_DROP = 1e4

#: Clearance (in D) between a column's or walled box's wall and the analysis period.
_MARGIN = 1.0


@dataclass(frozen=True)
class Container:
    """A container. ``kind`` is "box", "column", "walled" or "tree"; ``size`` holds the
    spec's numbers (in D: (L,), (N,), (Lx, Lz)); ``tree`` the (node_ints, node_reals, root)
    of a "tree" container (world lengths); ``d`` the element diameter the sizes refer to
    (set by :meth:`bound`; 1 until then)."""

    kind: str
    size: tuple = ()
    tree: tuple = None
    d: float = 1.0
    _cache: dict = field(default_factory=dict, compare=False, repr=False)

    # ---------------------------------------------------------------- construction
    @classmethod
    def box(cls, L):
        """The page's periodic box of side L (in D, in [1.5, 1e4])."""
        return cls("box", (check_float("container", L, MIN_WIDTH, MAX_WIDTH),))

    @classmethod
    def column(cls, n):
        """A cylindrical column of diameter N D with a floor (N in [1.5, 1e4])."""
        return cls("column", (check_float("container", n, MIN_WIDTH, MAX_WIDTH),))

    @classmethod
    def walled(cls, lx, lz):
        """A box with four side walls and a floor, interior Lx x Lz (in D, each in [1.5, 1e4])."""
        return cls("walled", (check_float("container", lx, MIN_WIDTH, MAX_WIDTH),
                              check_float("container", lz, MIN_WIDTH, MAX_WIDTH)))

    @classmethod
    def from_tree(cls, builder, root):
        """A container whose fluid region is the solid of ``root`` (world frame)."""
        try:
            ni, nr, _, _ = builder.encode()
            root = int(root)
            if not 0 <= root < len(ni):
                raise ValueError
        except Exception:
            raise PecletArgumentError("container", "a (SceneBuilder, root) pair", (builder, root))\
                from None
        return cls("tree", (), (np.asarray(ni), np.asarray(nr), root))

    def bound(self, d):
        """This container for an element of diameter ``d`` (world length)."""
        return replace(self, d=float(d), _cache={})

    # ---------------------------------------------------------------- geometry
    @property
    def periodic(self):
        """(periodic in x, periodic in z)."""
        return (True, True) if self.kind == "box" else (False, False)

    @property
    def period(self):
        """(L_x, L_z): the box of the analysis's periodic images (``Pack.box``), world."""
        k, s, d = self.kind, self.size, self.d
        if k == "box":
            return (s[0] * d, s[0] * d)
        if k == "column":
            return ((s[0] + 2 * _MARGIN) * d,) * 2
        if k == "walled":
            return ((s[0] + 2 * _MARGIN) * d, (s[1] + 2 * _MARGIN) * d)
        lo, hi = self._tree_box()
        return (hi[0] - lo[0] + 2 * _MARGIN * d, hi[2] - lo[2] + 2 * _MARGIN * d)

    @property
    def radius(self):
        """A column's inner radius (world), else None."""
        return 0.5 * self.size[0] * self.d if self.kind == "column" else None

    @property
    def center_xz(self):
        """The column's axis / walled box's centre (x, z), world."""
        if self.kind in ("column", "walled"):
            Lx, Lz = self.period
            return (0.5 * Lx, 0.5 * Lz)
        if self.kind == "box":
            return (0.5 * self.period[0], 0.5 * self.period[1])
        lo, hi = self._tree_box()
        return (0.5 * (lo[0] + hi[0]), 0.5 * (lo[2] + hi[2]))

    @property
    def floor_y(self):
        """Height of the floor's top face (0 except for a tree container: its lowest point)."""
        if self.kind != "tree":
            return 0.0
        return float(self._tree_box()[0][1])

    def cross_area(self):
        """Horizontal cross-section area (world length^2) of the fluid region."""
        k, s, d = self.kind, self.size, self.d
        if k == "box":
            return (s[0] * d) ** 2
        if k == "column":
            return math.pi * (0.5 * s[0] * d) ** 2
        if k == "walled":
            return s[0] * s[1] * d * d
        lo, hi = self._tree_box()
        return (hi[0] - lo[0]) * (hi[2] - lo[2])

    def domain(self, y_top):
        """(lo, hi) of ``Simulation.set_domain`` (the page's: y from -1.2)."""
        Lx, Lz = self.period
        if self.kind == "tree":
            lo, hi = self._tree_box()
            x0, z0 = lo[0] - _MARGIN * self.d, lo[2] - _MARGIN * self.d
            return (x0, min(-1.2, lo[1] - 1.2 * self.d), z0), (x0 + Lx, max(y_top, hi[1]),
                                                                z0 + Lz)
        return (0.0, -1.2, 0.0), (Lx, float(y_top), Lz)

    def sample_xz(self, rng, clearance, y=None, tries=10_000):
        """An (x, z) where a body of bounding radius ``clearance`` fits laterally (at height
        ``y`` for a tree container), drawn from ``rng`` (uniform over the admissible set by
        rejection; the box draws x then z, as the page does). None if ``tries`` fail."""
        k, s, d = self.kind, self.size, self.d
        if k == "box":
            L = s[0] * d
            return (rng.uniform(0, L), rng.uniform(0, L))
        Lx, Lz = self.period
        cx, cz = self.center_xz
        for _ in range(tries):
            if k == "column":
                R = self.radius - clearance
                x, z = rng.uniform(cx - R, cx + R), rng.uniform(cz - R, cz + R)
                if (x - cx) ** 2 + (z - cz) ** 2 <= R * R:
                    return (x, z)
            elif k == "walled":
                hx, hz = 0.5 * s[0] * d - clearance, 0.5 * s[1] * d - clearance
                if hx <= 0 or hz <= 0:
                    return None
                return (rng.uniform(cx - hx, cx + hx), rng.uniform(cz - hz, cz + hz))
            else:
                lo, hi = self._tree_box()
                # candidates in blocks: one tree evaluation per 64 draws
                xs = rng.uniform(lo[0], hi[0], 64)
                zs = rng.uniform(lo[2], hi[2], 64)
                pts = np.column_stack([xs, np.full(64, float(y)), zs])
                ok = np.flatnonzero(self.fluid_phi(pts) <= -clearance)
                if len(ok):
                    return (float(xs[ok[0]]), float(zs[ok[0]]))
        return None

    def sample_many(self, rng, clearance, y, m):
        """Up to ``m`` admissible (x, z) rows (K, 2) for a body of bounding radius
        ``clearance`` at height ``y``: ``m`` uniform draws over the lateral bounding box, the
        inadmissible ones dropped (one tree evaluation for a tree container)."""
        k, s, d = self.kind, self.size, self.d
        Lx, Lz = self.period
        cx, cz = self.center_xz
        if k == "box":
            return np.column_stack([rng.uniform(0, Lx, m), rng.uniform(0, Lz, m)])
        if k == "column":
            R = self.radius - clearance
            xz = np.column_stack([rng.uniform(cx - R, cx + R, m), rng.uniform(cz - R, cz + R, m)])
            return xz[(xz[:, 0] - cx) ** 2 + (xz[:, 1] - cz) ** 2 <= R * R]
        if k == "walled":
            hx, hz = 0.5 * s[0] * d - clearance, 0.5 * s[1] * d - clearance
            return np.column_stack([rng.uniform(cx - hx, cx + hx, m),
                                    rng.uniform(cz - hz, cz + hz, m)])
        lo, hi = self._tree_box()
        xz = np.column_stack([rng.uniform(lo[0], hi[0], m), rng.uniform(lo[2], hi[2], m)])
        pts = np.column_stack([xz[:, 0], np.full(m, float(y)), xz[:, 1]])
        return xz[self.fluid_phi(pts) <= -clearance]

    def fits(self, clearance, y=None):
        """Whether a body of bounding radius ``clearance`` fits laterally (at height ``y``)."""
        k, s, d = self.kind, self.size, self.d
        if k == "box":
            return True
        if k == "column":
            return self.radius > clearance
        if k == "walled":
            return min(s) * d > 2 * clearance
        return len(self.sample_many(np.random.default_rng(0), clearance, y, 4096)) > 0

    def ceiling(self, clearance):
        """The highest centre height at which a body of bounding radius ``clearance`` fits
        (a tree container: scanned down from its bounding ball's top in 0.1 D steps; -inf if
        nowhere); +inf for the open containers."""
        if self.kind != "tree":
            return math.inf
        key = ("ceiling", float(clearance))
        if key not in self._cache:
            lo, hi = self._tree_box()
            ys = np.arange(hi[1] - clearance, lo[1] + clearance, -0.1 * self.d)
            self._cache[key] = next((float(y) for y in ys if self.fits(clearance, y)),
                                    -math.inf)
        return self._cache[key]

    def fluid_box(self):
        """(lo (3,), hi (3,)) bounding a tree container's fluid region (its bounding ball's
        box; world lengths)."""
        if self.kind != "tree":
            raise PecletArgumentError("container", "a tree container", self.kind)
        return self._tree_box()

    def fluid_phi(self, pts):
        """phi of a tree container's fluid region at world points (K, 3) (< 0 inside)."""
        return self._tree_builder().eval_root(self.tree[2], np.asarray(pts, dtype=np.float64))

    # ---------------------------------------------------------------- walls
    def add_walls(self, sim, wall_material, y_top):
        """Add this container's walls to ``sim`` (restitution wall_material.e_n, friction
        wall_material.mu). Side walls reach from y = -2 D to ``y_top``."""
        m = wall_material.as_tuple()
        if self.kind == "tree":
            ni, nr, root = self.tree
            sim.add_analytic_wall(ni, nr, root, True, m[0], m[2])
            return
        fb, floor = self._floor()
        fi, fr, _, _ = fb.encode()
        sim.add_analytic_wall(fi, fr, floor, False, m[0], m[2])
        if self.kind == "box":
            return
        b = geom.SceneBuilder()
        root = self._side_leaf(b, y_top)
        ni, nr, _, _ = b.encode()
        sim.add_analytic_wall(ni, nr, root, True, m[0], m[2])

    def _floor(self):
        """The page's floor (``freeze.add_floor``): a box below y = 0 reaching 20 periods
        beyond the domain on every side."""
        Lx, Lz = self.period
        fb = geom.SceneBuilder()
        return fb, fb.add_leaf("box", [40.0 + Lx, 1.0, 40.0 + Lz],
                               translation=[Lx / 2, -1.0, Lz / 2])

    def solid_walls(self, y_top):
        """The walls as solid trees, [(builder, root)] in the world frame (phi < 0 in the wall
        material): the floor, and the side wall as a large box minus the fluid region (column,
        walled box) reaching ``y_top``; a tree container's complement. For contact counting."""
        if self.kind == "tree":
            b = geom.SceneBuilder.decode(self.tree[0], self.tree[1])
            c, r, _ = b.node_bound(self.tree[2])
            big = b.add_leaf("box", [r + 2 * self.d] * 3, translation=list(c))
            return [(b, b.add_difference(big, self.tree[2]))]
        Lx, Lz = self.period
        out = [self._floor()]
        if self.kind == "box":
            return out
        b = geom.SceneBuilder()
        fluid = self._side_leaf(b, y_top)
        big = b.add_leaf("box", [Lx, 0.5 * (y_top + 4 * self.d), Lz],
                         translation=[0.5 * Lx, 0.5 * y_top - 2 * self.d, 0.5 * Lz])
        out.append((b, b.add_difference(big, fluid)))
        return out

    def export_solid(self, y_top, thickness=0.1):
        """(builder, root, lo, hi): the container as a solid of wall ``thickness`` (in D) for
        meshing: a tube or box shell from the floor's underside to ``y_top`` with its floor
        plate. None for the periodic box and tree containers."""
        if self.kind not in ("column", "walled"):
            return None
        t, d = thickness * self.d, self.d
        cx, cz = self.center_xz
        b = geom.SceneBuilder()
        hh = 0.5 * (y_top + t)
        c = [cx, 0.5 * (y_top - t), cz]
        if self.kind == "column":
            R = self.radius
            outer = b.add_leaf("cone", [R + t, R + t, hh], translation=c)
            inner = b.add_leaf("cone", [R, R, hh], translation=[cx, c[1] + t, cz])
            ext = (R + t, R + t)
        else:
            hx, hz = 0.5 * self.size[0] * d, 0.5 * self.size[1] * d
            outer = b.add_leaf("box", [hx + t, hh, hz + t], translation=c)
            inner = b.add_leaf("box", [hx, hh, hz], translation=[cx, c[1] + t, cz])
            ext = (hx + t, hz + t)
        root = b.add_difference(outer, inner)
        pad = 0.05 * d
        lo = np.array([cx - ext[0] - pad, -t - pad, cz - ext[1] - pad])
        hi = np.array([cx + ext[0] + pad, y_top + pad, cz + ext[1] + pad])
        return b, root, lo, hi

    def _side_leaf(self, b, y_top):
        y0 = -2.0 * self.d
        hh = 0.5 * (float(y_top) - y0)
        cx, cz = self.center_xz
        centre = [cx, y0 + hh, cz]
        if self.kind == "column":
            R = self.radius
            return b.add_leaf("cone", [R, R, hh], translation=centre)
        return b.add_leaf("box", [0.5 * self.size[0] * self.d, hh, 0.5 * self.size[1] * self.d],
                          translation=centre)

    # ---------------------------------------------------------------- spec
    def to_spec(self):
        """A JSON-able description that :func:`parse_container` reads back."""
        out = dict(kind=self.kind, size=list(self.size))
        if self.tree is not None:
            ni, nr, root = self.tree
            out.update(node_ints=np.asarray(ni).tolist(), node_reals=np.asarray(nr).tolist(),
                       root=int(root))
        return out

    def label(self):
        if self.kind == "box":
            return f"periodic box {self.size[0]:g} D"
        if self.kind == "column":
            return f"column D_t = {self.size[0]:g} D"
        if self.kind == "walled":
            return f"walled box {self.size[0]:g} x {self.size[1]:g} D"
        return "CSG container"

    # ---------------------------------------------------------------- tree helpers
    def _tree_builder(self):
        if "builder" not in self._cache:
            self._cache["builder"] = geom.SceneBuilder.decode(self.tree[0], self.tree[1])
        return self._cache["builder"]

    def _tree_box(self):
        """(lo, hi) of the fluid region's bounding ball."""
        if "box" not in self._cache:
            c, r, _ = self._tree_builder().node_bound(self.tree[2])
            if not np.isfinite(r) or r > 1e6:
                raise PecletArgumentError("container", "a bounded fluid-region tree",
                                          "tree", f"bounding radius {r:g}")
            self._cache["box"] = (np.asarray(c) - r, np.asarray(c) + r)
        return self._cache["box"]


def parse_container(value):
    """A :class:`Container` from a spec string, a Container, a (builder, root) pair or the
    dict written by :meth:`Container.to_spec`; PecletArgumentError naming "container"."""
    if isinstance(value, Container):
        return value
    if isinstance(value, dict):
        try:
            if value["kind"] == "tree":
                b = geom.SceneBuilder.decode(np.asarray(value["node_ints"], np.int32),
                                             np.asarray(value["node_reals"], np.float64))
                return Container.from_tree(b, value["root"])
            return parse_container(f"{value['kind']}:" + ",".join(repr(float(v))
                                                               for v in value["size"]))
        except (KeyError, TypeError, ValueError) as exc:
            if isinstance(exc, PecletArgumentError):
                raise
            raise PecletArgumentError("container", CONTAINER_FORMS, value) from None
    if isinstance(value, tuple) and len(value) == 2 and isinstance(value[0], geom.SceneBuilder):
        return Container.from_tree(*value)
    if is_user_file(value):
        return Container.from_tree(*mesh_container_tree(value))
    if not isinstance(value, str) or ":" not in value:
        raise PecletArgumentError("container", CONTAINER_FORMS, value)
    kind, _, args = value.partition(":")
    try:
        nums = [float(a) for a in args.split(",")]
    except ValueError:
        raise PecletArgumentError("container", CONTAINER_FORMS, value) from None
    makers = {"box": (Container.box, 1), "column": (Container.column, 1),
              "walled": (Container.walled, 2)}
    if kind.strip() not in makers or len(nums) != makers[kind.strip()][1]:
        raise PecletArgumentError("container", CONTAINER_FORMS, value)
    make, _ = makers[kind.strip()]
    try:
        return make(*nums)
    except PecletArgumentError:
        raise PecletArgumentError("container", f"{kind} sizes in [{MIN_WIDTH}, "
                                  f"{MAX_WIDTH:g}] element diameters (finite)", value) from None
