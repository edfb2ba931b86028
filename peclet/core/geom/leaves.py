"""The leaf table: one row per primitive, read by the builder, the certificate and the docs.

Every leaf is defined in its canonical frame (origin-centred). Its distance formula lives in
exactly one place, :mod:`peclet.core.geom.kernels`; this module holds what Python needs to know
about it: kind id, parameter names, validation, exactness and Lipschitz flags, and the radius of
a ball about the origin that contains the solid.

Flags
-----
exact
    ``phi`` is the signed Euclidean distance to the surface. An exact leaf's enclosing ball is
    *certified*: ``phi(p) >= |p - c| - r`` for every ``p`` (Equation 1 of the Pall-ring page).
lipschitz
    ``|phi(p) - phi(q)| <= |p - q|``. Every exact leaf is 1-Lipschitz; ``hollow_cylinder_shell``
    is 1-Lipschitz but under-estimates the distance (sign-exact only); ``ellipsoid`` and
    ``superquadric`` are neither.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

MAX_PARAMS = 8

#: Kind ids of the CSG operators (DESIGN.md §2).
UNION, INTERSECTION, DIFFERENCE = 32, 33, 34
OPERATOR_NAMES = {UNION: "union", INTERSECTION: "intersection", DIFFERENCE: "difference"}


def _positive(kind: str, names, values, which):
    for i in which:
        v = values[i]
        if not v > 0.0:
            raise ValueError(f"{kind}: parameter {names[i]!r} must be > 0, got {v!r}")


def _nonnegative(kind: str, names, values, which):
    for i in which:
        v = values[i]
        if not v >= 0.0:
            raise ValueError(f"{kind}: parameter {names[i]!r} must be >= 0, got {v!r}")


@dataclass(frozen=True)
class LeafSpec:
    """One row of the leaf table."""

    kind: int
    name: str
    param_names: tuple[str, ...]
    exact: bool
    lipschitz: bool
    doc: str
    check: Callable[[np.ndarray], np.ndarray]
    radius: Callable[[np.ndarray], float]

    @property
    def n_params(self) -> int:
        return len(self.param_names)

    def validate(self, params) -> np.ndarray:
        """Return the params as a float64 array, or raise ``ValueError`` naming the problem."""
        arr = np.asarray(params, dtype=np.float64).reshape(-1)
        if arr.size != self.n_params:
            raise ValueError(
                f"{self.name}: params must have {self.n_params} values "
                f"({', '.join(self.param_names)}), got {arr.size}")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{self.name}: params must be finite, got {arr.tolist()}")
        return self.check(arr)


def _check_sphere(a):
    _positive("sphere", ("radius",), a, [0])
    return a


def _check_box(a):
    _positive("box", ("hx", "hy", "hz"), a, [0, 1, 2])
    return a


def _check_hollow_cylinder(a):
    names = ("rOuter", "height", "thickness")
    _positive("hollow_cylinder", names, a, [0, 1, 2])
    if not a[2] < a[0]:
        raise ValueError("hollow_cylinder: 'thickness' must be in (0, rOuter) "
                         f"(rOuter={a[0]!r}), got {a[2]!r}; for a solid cylinder use a cone "
                         "with equal radii")
    return a


def _check_hollow_cylinder_shell(a):
    names = ("rOuter", "rInner", "height")
    _positive("hollow_cylinder_shell", names, a, [0, 2])
    _nonnegative("hollow_cylinder_shell", names, a, [1])
    if not a[1] < a[0]:
        raise ValueError("hollow_cylinder_shell: 'rInner' must be in [0, rOuter) "
                         f"(rOuter={a[0]!r}), got {a[1]!r}")
    return a


def _check_capsule(a):
    _positive("capsule", ("radius", "halfLength"), a, [0])
    _nonnegative("capsule", ("radius", "halfLength"), a, [1])
    return a


def _check_torus(a):
    _positive("torus", ("R", "r"), a, [0, 1])
    if not a[1] < a[0]:
        raise ValueError(f"torus: tube radius 'r' must be in (0, R) (R={a[0]!r}), got {a[1]!r}")
    return a


def _check_cone(a):
    names = ("rBottom", "rTop", "halfHeight")
    _nonnegative("cone", names, a, [0, 1])
    _positive("cone", names, a, [2])
    if not (a[0] > 0.0 or a[1] > 0.0):
        raise ValueError("cone: at least one of 'rBottom', 'rTop' must be > 0, got both 0")
    return a


def _check_ellipsoid(a):
    _positive("ellipsoid", ("rx", "ry", "rz"), a, [0, 1, 2])
    return a


SUPERQUADRIC_E_RANGE = (0.1, 1.0)


def _check_superquadric(a):
    _positive("superquadric", ("rx", "ry", "rz", "e"), a, [0, 1, 2])
    lo, hi = SUPERQUADRIC_E_RANGE
    if not lo <= a[3] <= hi:
        raise ValueError(f"superquadric: exponent 'e' must be in [{lo}, {hi}] (convex, from "
                         f"near-box to ellipsoid), got {a[3]!r}")
    return a


def _check_half_space(a):
    n = float(np.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]))
    if n == 0.0:
        raise ValueError("half_space: normal (nx, ny, nz) must be non-zero")
    out = a.copy()
    if abs(n - 1.0) > 1e-14:
        out[:3] = a[:3] / n
        out[3] = a[3] / n
    return out


_LEAVES = (
    LeafSpec(1, "sphere", ("radius",), True, True,
             "|p| - r", _check_sphere, lambda a: a[0]),
    LeafSpec(2, "hollow_cylinder", ("rOuter", "height", "thickness"), True, True,
             "tube about y: 2-D box in (r_xz, y)", _check_hollow_cylinder,
             lambda a: float(np.hypot(a[0], 0.5 * a[1]))),
    LeafSpec(3, "box", ("hx", "hy", "hz"), True, True,
             "box of half-extents (hx, hy, hz)", _check_box,
             lambda a: float(np.sqrt(a[0] ** 2 + a[1] ** 2 + a[2] ** 2))),
    LeafSpec(4, "hollow_cylinder_shell", ("rOuter", "rInner", "height"), False, True,
             "tube about z: max(r_xy - rO, rI - r_xy, |z| - H/2); sign-exact, under-estimates",
             _check_hollow_cylinder_shell, lambda a: float(np.hypot(a[0], 0.5 * a[2]))),
    LeafSpec(5, "capsule", ("radius", "halfLength"), True, True,
             "segment [-L, L] on y, thickened by radius", _check_capsule,
             lambda a: a[0] + a[1]),
    LeafSpec(6, "torus", ("R", "r"), True, True,
             "torus about y: |(r_xz - R, y)| - r", _check_torus, lambda a: a[0] + a[1]),
    LeafSpec(7, "cone", ("rBottom", "rTop", "halfHeight"), True, True,
             "capped cone (frustum) about y, rBottom at y=-h, rTop at y=+h", _check_cone,
             lambda a: float(max(np.hypot(a[0], a[2]), np.hypot(a[1], a[2])))),
    LeafSpec(8, "ellipsoid", ("rx", "ry", "rz"), False, False,
             "k0 (k0 - 1) / k1 with k0 = |p/r|, k1 = |p/r^2|; a bound, not 1-Lipschitz",
             _check_ellipsoid, lambda a: float(max(a[0], a[1], a[2]))),
    LeafSpec(9, "superquadric", ("rx", "ry", "rz", "e"), False, False,
             "Taubin estimate (F - 1)/|grad F| of F = ||p/r||_(2/e), clamped at -min(r)",
             _check_superquadric, lambda a: float(np.sqrt(a[0] ** 2 + a[1] ** 2 + a[2] ** 2))),
    LeafSpec(10, "half_space", ("nx", "ny", "nz", "offset"), True, True,
             "solid where n.p <= offset: n.p - offset (n normalised); unbounded",
             _check_half_space, lambda a: float("inf")),
)

LEAVES_BY_KIND: dict[int, LeafSpec] = {s.kind: s for s in _LEAVES}
LEAVES_BY_NAME: dict[str, LeafSpec] = {s.name: s for s in _LEAVES}
LEAF_NAMES = tuple(s.name for s in _LEAVES)


def leaf_spec(kind) -> LeafSpec:
    """Look a leaf up by name (``"box"``) or kind id (``3``); raise ``ValueError`` otherwise."""
    if isinstance(kind, str):
        spec = LEAVES_BY_NAME.get(kind)
    elif isinstance(kind, (int, np.integer)) and not isinstance(kind, bool):
        spec = LEAVES_BY_KIND.get(int(kind))
    else:
        spec = None
    if spec is None:
        raise ValueError(f"kind must be one of {list(LEAF_NAMES)} or their ids "
                         f"{sorted(LEAVES_BY_KIND)}, got {kind!r}")
    return spec
