"""The leaf table: one row per primitive, read by the builder, the certificate and the docs.

Every leaf is defined in its canonical frame (origin-centred). Its distance formula lives in
exactly one place, :mod:`peclet.core.geom.kernels`; this module holds what Python needs to know
about it: kind id, parameter names, validation, exactness and Lipschitz flags, and the radius of
a ball about the origin that contains the solid.

Each row with a closed form also carries the leaf's mass properties at unit density
(:func:`closed_form_mass_properties`): the one home of those formulas for the tests, the
benchmarks and the certificate.

Flags
-----
exact
    ``phi`` is the signed Euclidean distance to the surface. An exact leaf's enclosing ball is
    *certified*: ``phi(p) >= |p - c| - r`` for every ``p`` (Equation 1 of the Pall-ring page).
lipschitz
    ``|phi(p) - phi(q)| <= |p - q|``. Every exact leaf is 1-Lipschitz; ``hollow_cylinder_shell``
    is 1-Lipschitz but under-estimates the distance (sign-exact only); ``ellipsoid`` and
    ``superquadric`` are neither.
sampled
    The ``grid`` leaf (kind 0): its field is data, samples in data rows of the node table
    (:mod:`peclet.core.geom.sampled`); neither exact nor 1-Lipschitz, its ball and Lipschitz
    constant are measured from the samples by the builder. It is not in :data:`LEAF_NAMES`
    (leaves authored from parameters alone), but in :data:`SAMPLED_LEAF_NAMES`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, NamedTuple, Optional

import numpy as np

MAX_PARAMS = 8

#: Kind ids of the CSG operators (docs/architecture.md §2).
UNION, INTERSECTION, DIFFERENCE = 32, 33, 34
#: Kind id of the grid leaf (a sampled field; its samples live in data rows, below).
GRID = 0
#: Kind id of a *data row* of the node table: not a node, but 16 samples of a grid leaf's
#: field in its ``node_reals`` row (docs/architecture.md §2, :mod:`peclet.core.geom.sampled`).
DATA = 31
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
    #: Validated params -> :class:`ClosedForm`, or None where the leaf has no closed form.
    mass_properties: Optional[Callable[[np.ndarray], "ClosedForm"]] = None
    #: True for a leaf whose field is data (the grid): its params address data rows of the
    #: node table and its radius is measured from them (:mod:`peclet.core.geom.sampled`).
    sampled: bool = False

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

#: Samples per axis a grid leaf accepts (2 is one cell; 1024^3 doubles would be 8 GiB).
GRID_DIM_RANGE = (2, 1024)


def _check_grid(a):
    names = ("first_row", "nx", "ny", "nz", "spacing")
    _nonnegative("grid", names, a, [0])
    _positive("grid", names, a, [4])
    lo, hi = GRID_DIM_RANGE
    for i in (0, 1, 2, 3):
        if not float(a[i]).is_integer():
            raise ValueError(f"grid: parameter {names[i]!r} must be an integer, got {a[i]!r}")
    for i in (1, 2, 3):
        if not lo <= a[i] <= hi:
            raise ValueError(f"grid: parameter {names[i]!r} (samples on an axis) must be in "
                             f"[{lo}, {hi}], got {a[i]!r}")
    return a


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


class ClosedForm(NamedTuple):
    """Exact mass properties of a leaf at unit density, in its canonical frame.

    volume (user units^3); com (3,), the centre of mass; inertia (3, 3), the inertia tensor
    about the com, ``integral of (r^2 I - r r^T) dV`` with r measured from the com.
    """

    volume: float
    com: np.ndarray
    inertia: np.ndarray


def _closed_form(volume, diag, com_y=0.0):
    """A ClosedForm with a diagonal inertia (the canonical axes are principal)."""
    return ClosedForm(float(volume), np.array([0.0, com_y, 0.0]), np.diag(np.asarray(diag, float)))


def _mp_sphere(a):
    r = a[0]
    v = 4.0 / 3.0 * math.pi * r ** 3
    return _closed_form(v, [0.4 * v * r * r] * 3)


def _mp_box(a):
    x2, y2, z2 = a[0] ** 2, a[1] ** 2, a[2] ** 2
    v = 8.0 * a[0] * a[1] * a[2]
    return _closed_form(v, [v * (y2 + z2) / 3.0, v * (x2 + z2) / 3.0, v * (x2 + y2) / 3.0])


def _mp_ellipsoid(a):
    x2, y2, z2 = a[0] ** 2, a[1] ** 2, a[2] ** 2
    v = 4.0 / 3.0 * math.pi * a[0] * a[1] * a[2]
    return _closed_form(v, [v * (y2 + z2) / 5.0, v * (x2 + z2) / 5.0, v * (x2 + y2) / 5.0])


def _tube(ro, ri, h):
    """(volume, axial moment, transverse moment) of a tube of radii ri < ro, length h."""
    v = math.pi * (ro * ro - ri * ri) * h
    s = ro * ro + ri * ri
    return v, 0.5 * v * s, v * (0.25 * s + h * h / 12.0)


def _mp_hollow_cylinder(a):
    v, axial, transverse = _tube(a[0], a[0] - a[2], a[1])          # axis y
    return _closed_form(v, [transverse, axial, transverse])


def _mp_hollow_cylinder_shell(a):
    v, axial, transverse = _tube(a[0], a[1], a[2])                 # axis z
    return _closed_form(v, [transverse, transverse, axial])


def _mp_torus(a):
    R, r = a[0], a[1]
    v = 2.0 * math.pi ** 2 * R * r * r
    transverse = v * (0.5 * R * R + 0.625 * r * r)
    return _closed_form(v, [transverse, v * (R * R + 0.75 * r * r), transverse])


def _mp_capsule(a):
    """A cylinder of length 2L about y with a hemisphere on each end. A hemisphere of mass m
    has 2/5 m r^2 about any axis through its base's centre and its com 3r/8 from the base, so
    about a transverse axis through the capsule's centre (base at L) it has
    2/5 m r^2 + m (L^2 + 2 L 3r/8)."""
    r, L = a[0], a[1]
    vc = 2.0 * math.pi * r * r * L
    vh = 2.0 / 3.0 * math.pi * r ** 3
    axial = 0.5 * vc * r * r + 2.0 * vh * 0.4 * r * r
    transverse = vc * (0.25 * r * r + L * L / 3.0) + 2.0 * vh * (0.4 * r * r + L * L + 0.75 * L * r)
    return _closed_form(vc + 2.0 * vh, [transverse, axial, transverse])


def _mp_cone(a):
    """Frustum about y, radius rho(s) = r1 + (r2 - r1) s / H at height s = y + h in [0, H],
    H = 2h. With p = r1^2 + r1 r2 + r2^2, the integrals of rho^2, s rho^2, s^2 rho^2 and
    rho^4 over [0, H] are H p / 3, H^2 (r1^2 + 2 r1 r2 + 3 r2^2) / 12,
    H^3 (r1^2 + 3 r1 r2 + 6 r2^2) / 30 and H (r1^4 + r1^3 r2 + ... + r2^4) / 5. A disc of
    radius rho has pi rho^4 / 2 about the axis and pi rho^4 / 4 about a diameter; the com is
    NOT at the origin (unless r1 = r2)."""
    r1, r2, h = a[0], a[1], a[2]
    H = 2.0 * h
    p = r1 * r1 + r1 * r2 + r2 * r2
    v = math.pi * H * p / 3.0
    sc = H * (r1 * r1 + 2.0 * r1 * r2 + 3.0 * r2 * r2) / (4.0 * p)        # com above the base
    q4 = H * (r1 ** 4 + r1 ** 3 * r2 + r1 * r1 * r2 * r2 + r1 * r2 ** 3 + r2 ** 4) / 5.0
    axial = 0.5 * math.pi * q4
    s2 = math.pi * H ** 3 * (r1 * r1 + 3.0 * r1 * r2 + 6.0 * r2 * r2) / 30.0 - v * sc * sc
    transverse = 0.25 * math.pi * q4 + s2
    return _closed_form(v, [transverse, axial, transverse], com_y=sc - h)


_LEAVES = (
    LeafSpec(1, "sphere", ("radius",), True, True,
             "|p| - r", _check_sphere, lambda a: a[0], _mp_sphere),
    LeafSpec(2, "hollow_cylinder", ("rOuter", "height", "thickness"), True, True,
             "tube about y: 2-D box in (r_xz, y)", _check_hollow_cylinder,
             lambda a: float(np.hypot(a[0], 0.5 * a[1])), _mp_hollow_cylinder),
    LeafSpec(3, "box", ("hx", "hy", "hz"), True, True,
             "box of half-extents (hx, hy, hz)", _check_box,
             lambda a: float(np.sqrt(a[0] ** 2 + a[1] ** 2 + a[2] ** 2)), _mp_box),
    LeafSpec(4, "hollow_cylinder_shell", ("rOuter", "rInner", "height"), False, True,
             "tube about z: max(r_xy - rO, rI - r_xy, |z| - H/2); sign-exact, under-estimates",
             _check_hollow_cylinder_shell, lambda a: float(np.hypot(a[0], 0.5 * a[2])),
             _mp_hollow_cylinder_shell),
    LeafSpec(5, "capsule", ("radius", "halfLength"), True, True,
             "segment [-L, L] on y, thickened by radius", _check_capsule,
             lambda a: a[0] + a[1], _mp_capsule),
    LeafSpec(6, "torus", ("R", "r"), True, True,
             "torus about y: |(r_xz - R, y)| - r", _check_torus, lambda a: a[0] + a[1],
             _mp_torus),
    LeafSpec(7, "cone", ("rBottom", "rTop", "halfHeight"), True, True,
             "capped cone (frustum) about y, rBottom at y=-h, rTop at y=+h", _check_cone,
             lambda a: float(max(np.hypot(a[0], a[2]), np.hypot(a[1], a[2]))), _mp_cone),
    LeafSpec(8, "ellipsoid", ("rx", "ry", "rz"), False, False,
             "k0 (k0 - 1) / k1 with k0 = |p/r|, k1 = |p/r^2|; a bound, not 1-Lipschitz",
             _check_ellipsoid, lambda a: float(max(a[0], a[1], a[2])), _mp_ellipsoid),
    LeafSpec(9, "superquadric", ("rx", "ry", "rz", "e"), False, False,
             "Taubin estimate (F - 1)/|grad F| of F = ||p/r||_(2/e), clamped at -min(r)",
             _check_superquadric, lambda a: float(np.sqrt(a[0] ** 2 + a[1] ** 2 + a[2] ** 2))),
    LeafSpec(10, "half_space", ("nx", "ny", "nz", "offset"), True, True,
             "solid where n.p <= offset: n.p - offset (n normalised); unbounded",
             _check_half_space, lambda a: float("inf")),
    # the radius of a grid is measured from its samples by the builder (sampled.py), so the
    # table's radius is never called for it
    LeafSpec(GRID, "grid", ("first_row", "nx", "ny", "nz", "spacing"), False, False,
             "trilinear in a centred lattice of samples; outside it, the distance to the "
             "lattice's box plus the value at the nearest box point",
             _check_grid, lambda a: float("nan"), sampled=True),
)

LEAVES_BY_KIND: dict[int, LeafSpec] = {s.kind: s for s in _LEAVES}
LEAVES_BY_NAME: dict[str, LeafSpec] = {s.name: s for s in _LEAVES}
#: The leaves authored from their parameters alone (random trees draw from these).
LEAF_NAMES = tuple(s.name for s in _LEAVES if not s.sampled)
#: The leaves whose field is data (:mod:`peclet.core.geom.sampled`).
SAMPLED_LEAF_NAMES = tuple(s.name for s in _LEAVES if s.sampled)


def leaf_spec(kind) -> LeafSpec:
    """Look a leaf up by name (``"box"``) or kind id (``3``); raise ``ValueError`` otherwise."""
    if isinstance(kind, str):
        spec = LEAVES_BY_NAME.get(kind)
    elif isinstance(kind, (int, np.integer)) and not isinstance(kind, bool):
        spec = LEAVES_BY_KIND.get(int(kind))
    else:
        spec = None
    if spec is None:
        raise ValueError(f"kind must be one of {list(LEAVES_BY_NAME)} or their ids "
                         f"{sorted(LEAVES_BY_KIND)}, got {kind!r}")
    return spec


def closed_form_mass_properties(kind, params) -> Optional[ClosedForm]:
    """Exact mass properties of leaf ``kind`` (name or id) with ``params``, at unit density in
    its canonical frame (see the table's axis conventions: tubes, torus, capsule and cone
    about y, hollow_cylinder_shell about z): a :class:`ClosedForm` (volume, com (3,), inertia
    (3, 3) about the com), or None for a leaf without one (superquadric, half_space). The
    params are validated like the builder's; a bad kind or param raises ``ValueError``."""
    spec = leaf_spec(kind)
    a = spec.validate(params)
    if spec.mass_properties is None:
        return None
    return spec.mass_properties(a)
