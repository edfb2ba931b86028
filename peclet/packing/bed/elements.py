"""Packing elements as certified CSG trees.

Every constructor builds one element in its *authoring frame* (origin-centred, the element's
axis on +y, lengths in the user's unit; the Pall-ring defaults are in units of the outer
diameter D = 1, as on the reference page) and returns an :class:`Element`, which unpacks as
``builder, root = pall_ring()``.

Certified by construction (docs/architecture.md §4): the solid that bounds the element (a
distance-exact tube, torus, sphere or cone) is always the LEFT child of every
difference/intersection, and everything on the right is 1-Lipschitz, so
``builder.node_bound(root)[2]`` is True for every element and the scene query may prune it. Each
constructor checks that claim before returning.

Where it is meaningful an element also carries its *envelope*: the convex solid it is inscribed
in (the cylinder of a ring, the element itself for a sphere or a solid cylinder), as a tree in
the same builder and frame, with its exact volume. The envelope packing fraction f_env of a
pack is measured against it (page Step 6).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from peclet.core import geom
from peclet.core.geom.transforms import compose, quat_to_matrix

__all__ = ["Element", "pall_ring", "raschig_ring", "berl_saddle", "intalox_saddle", "sphere",
           "solid_cylinder", "ELEMENTS", "qy", "Param", "PARAMS", "parse_element",
           "element_text", "element_defaults", "check_param"]

#: The reference page's Pall ring, in units of the outer diameter.
PAGE_PALL = dict(r_outer=0.5, height=1.0, thickness=0.12, n_windows=4, window_y=0.24,
                 window_half=(0.16, 0.17, 0.13), web_half=(0.40, 0.06, 0.06))


@dataclass
class Element:
    """A packing element: a certified CSG tree plus what analysis needs to know about it.

    Iterating yields ``(builder, root)`` so that ``b, root = pall_ring()`` works.

    Attributes
    ----------
    builder, root
        The tree (authoring frame; axis on +y where the element has one).
    name
        Element kind, e.g. ``"pall_ring"``.
    params
        The validated construction parameters.
    bounds
        ``(lo, hi)``: an axis-aligned box that contains the solid with a margin, suitable for
        quadrature and for baking.
    envelope_root, envelope_volume
        The convex envelope as a tree in ``builder`` (same frame) and its exact volume, or None
        where no envelope is meaningful (saddles).
    min_feature
        The thinnest feature (wall or web thickness), for probe-spacing checks.
    """

    builder: geom.SceneBuilder
    root: int
    name: str
    params: dict
    bounds: tuple
    envelope_root: int | None = None
    envelope_volume: float | None = None
    min_feature: float = math.nan
    axis: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))
    #: the quadrature's n that aligns its cells with a grid leaf's lattice (bounds then the
    #: lattice's box; :func:`peclet.core.geom.grids.quadrature_layout`), else None
    quadrature_n: int | None = None

    def __iter__(self):
        yield self.builder
        yield self.root


def qy(a):
    """Quaternion (x, y, z, w) of a rotation by angle ``a`` (radians) about +y."""
    return [0.0, float(np.sin(0.5 * a)), 0.0, float(np.cos(0.5 * a))]


def home_transform(builder, root, home_root):
    """(t, q, s): the transform that carries the authoring frame of ``root`` to the home
    (principal) frame of ``home_root``, a reframed copy of it (home = outer ∘ own)."""
    _, _, _, _, t0, q0, s0 = builder.node(root)
    _, _, _, _, t1, q1, s1 = builder.node(home_root)
    inv_q0 = np.array([-q0[0], -q0[1], -q0[2], q0[3]])
    inv = (-(quat_to_matrix(inv_q0) @ t0) / s0, inv_q0, 1.0 / s0)
    return compose((t1, q1, s1), inv)


# ---------------------------------------------------------------------- validation helpers
def _num(name, value, lo=0.0, hi=math.inf, lo_open=True, hi_open=False):
    """``value`` as a float in the given interval, else ValueError naming ``name``."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    ok_lo = v > lo if lo_open else v >= lo
    ok_hi = v < hi if hi_open else v <= hi
    if not (math.isfinite(v) and ok_lo and ok_hi):
        rng = f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
        raise ValueError(f"{name} must be in {rng}, got {value!r}")
    return v


def _triple(name, value):
    try:
        arr = [float(v) for v in value]
    except TypeError:
        raise ValueError(f"{name} must be 3 positive half-extents, got {value!r}") from None
    if len(arr) != 3 or not all(math.isfinite(v) and v > 0 for v in arr):
        raise ValueError(f"{name} must be 3 finite half-extents > 0, got {value!r}")
    return tuple(arr)


def _box_bounds(rx, hy, rz, margin):
    return (np.array([-rx - margin, -hy - margin, -rz - margin]),
            np.array([rx + margin, hy + margin, rz + margin]))


def _certified(b, root, name):
    _, _, cert = b.node_bound(root)
    if not cert:  # construction bug, not a user error: the rules above guarantee it
        raise AssertionError(f"{name}: tree is not certified")
    return root


def _solid_cylinder_node(b, radius, height):
    # a cone with equal radii is the exact solid cylinder (hollow_cylinder needs t < rOuter)
    return b.add_leaf("cone", [radius, radius, 0.5 * height])


# ---------------------------------------------------------------------- elements
def pall_ring(r_outer=0.5, height=1.0, thickness=0.12, n_windows=4, window_y=0.24,
              window_half=(0.16, 0.17, 0.13), web_half=(0.40, 0.06, 0.06), builder=None,
              certified=True):
    """The reference page's Pall ring: a tube minus two rows of windows, plus two inner webs.

    Parameters (lengths in the user's unit; defaults are the page's, D = 2 r_outer = 1)
    ----------
    r_outer : outer radius, > 0.
    height : tube height along y, > 0.
    thickness : wall thickness, in (0, r_outer).
    n_windows : windows per row, integer in [1, 16]; the lower row is offset by half a pitch.
    window_y : height of the two window rows (at +-window_y), in [0, height/2).
    window_half : (radial, axial, tangential) half-extents of each window box, centred on the
        outer radius; the radial half-extent must be >= thickness so the window spans the
        wall, the axial one < height/2.
    web_half : (x, y, z) half-extents of the two crossed web plates at y = +-window_y; x must be
        <= r_outer - thickness/2 (the web ends inside the wall).
    builder : an existing SceneBuilder to add to (default: a new one).
    certified : True (default) builds the tube from the distance-exact ``hollow_cylinder``;
        False builds the page's sign-exact counter-example from ``hollow_cylinder_shell`` (same
        solid, no certificate), kept only to demonstrate the difference (page Step 2).

    Construction: ``union(union(difference(tube, windows), web1), web2)``, tube on the left of
    the difference so the root keeps the tube's certified ball.
    """
    ro = _num("r_outer", r_outer)
    h = _num("height", height)
    t = _num("thickness", thickness, 0.0, ro, hi_open=True)
    if isinstance(n_windows, bool) or not float(n_windows).is_integer() \
            or not 1 <= int(n_windows) <= 16:
        raise ValueError(f"n_windows must be an integer in [1, 16], got {n_windows!r}")
    nw = int(n_windows)
    yw = _num("window_y", window_y, 0.0, 0.5 * h, lo_open=False, hi_open=True)
    wr, wa, wt = _triple("window_half", window_half)
    if wr < t:
        raise ValueError(f"window_half[0] (radial) must be >= thickness = {t:g} so the window, "
                         f"centred on the outer radius, cuts through the wall, got {wr:g}")
    if wa >= 0.5 * h:
        raise ValueError(f"window_half[1] (axial) must be < height/2 = {0.5 * h:g}, got {wa:g}")
    web = _triple("web_half", web_half)
    if web[0] > ro - 0.5 * t + 1e-12:
        raise ValueError(f"web_half[0] must be <= r_outer - thickness/2 = {ro - 0.5 * t:g}, "
                         f"got {web[0]:g}")
    b = geom.SceneBuilder() if builder is None else builder
    if certified:
        tube = b.add_leaf("hollow_cylinder", [ro, h, t])
    else:  # the shell leaf is about z: rotate it onto y
        tube = b.add_leaf("hollow_cylinder_shell", [ro, ro - t, h],
                          rotation=[math.sin(math.pi / 4), 0.0, 0.0, math.cos(math.pi / 4)])
    wins = []
    for row, ysign in enumerate((+1, -1)):
        for k in range(nw):
            phi = 2 * np.pi * k / nw + (np.pi / nw if row else 0.0)
            wins.append(b.add_leaf("box", [wr, wa, wt],
                                   translation=[ro * np.cos(phi), ysign * yw, ro * np.sin(phi)],
                                   rotation=qy(-phi)))
    w = wins[0]
    for x in wins[1:]:
        w = b.add_union(w, x)
    shell = b.add_difference(tube, w)
    root = b.add_union(
        b.add_union(shell, b.add_leaf("box", list(web), translation=[0.0, +yw, 0.0])),
        b.add_leaf("box", list(web), translation=[0.0, -yw, 0.0], rotation=qy(np.pi / 2)))
    if certified:
        _certified(b, root, "pall_ring")
    env = _solid_cylinder_node(b, ro, h)
    params = dict(r_outer=ro, height=h, thickness=t, n_windows=nw, window_y=yw,
                  window_half=(wr, wa, wt), web_half=web)
    return Element(b, root, "pall_ring", params, _box_bounds(ro, 0.5 * h, ro, 0.12 * ro),
                   env, math.pi * ro * ro * h, min(t, 2 * web[1], 2 * web[2]))


def pall_ring_of_thickness(thickness, r_outer=0.5, height=1.0, **kw):
    """The page's sweep construction (Step 6): the Pall ring with webs scaled with the wall,
    ``web_half = (r_outer - t, t/2, t/2)``; other arguments as :func:`pall_ring`."""
    t = _num("thickness", thickness, 0.0, _num("r_outer", r_outer), hi_open=True)
    return pall_ring(r_outer=r_outer, height=height, thickness=t,
                     web_half=(r_outer - t, 0.5 * t, 0.5 * t), **kw)


def raschig_ring(r_outer=0.5, height=1.0, thickness=0.12, builder=None):
    """A Raschig ring: the plain distance-exact tube (axis y). thickness in (0, r_outer)."""
    ro = _num("r_outer", r_outer)
    h = _num("height", height)
    t = _num("thickness", thickness, 0.0, ro, hi_open=True)
    b = geom.SceneBuilder() if builder is None else builder
    root = _certified(b, b.add_leaf("hollow_cylinder", [ro, h, t]), "raschig_ring")
    env = _solid_cylinder_node(b, ro, h)
    return Element(b, root, "raschig_ring", dict(r_outer=ro, height=h, thickness=t),
                   _box_bounds(ro, 0.5 * h, ro, 0.12 * ro), env, math.pi * ro * ro * h, t)


def berl_saddle(R=0.5, r=0.2, builder=None):
    """A Berl-like saddle: the solid torus (axis y, centre-line radius R, tube radius r) cut in
    half by the plane x = 0 (``torus ∩ half_space{x <= 0}``). The arch's inner face, toward the
    axis, has negative Gaussian curvature: the saddle. r in (0, R).

    The half-space is on the RIGHT of the intersection, so the torus's certified ball is kept.
    """
    Rr = _num("R", R)
    rr = _num("r", r, 0.0, Rr, hi_open=True)
    b = geom.SceneBuilder() if builder is None else builder
    torus = b.add_leaf("torus", [Rr, rr])
    cut = b.add_leaf("half_space", [1.0, 0.0, 0.0, 0.0])
    root = _certified(b, b.add_intersection(torus, cut), "berl_saddle")
    m = 0.1 * (Rr + rr)
    bounds = (np.array([-(Rr + rr) - m, -rr - m, -(Rr + rr) - m]),
              np.array([m, rr + m, Rr + rr + m]))
    return Element(b, root, "berl_saddle", dict(R=Rr, r=rr), bounds, None, None, 2 * rr)


def intalox_saddle(R=0.5, r=0.3, thickness=0.06, builder=None):
    """An Intalox-like saddle: a curved sheet of negative Gaussian curvature.

    The hollow torus shell (torus(R, r) minus torus(R, r - thickness)), kept only on its inner
    side (inside the solid cylinder of radius R about the axis) and on one side of the plane
    x = 0: ``((torus_o − torus_i) ∩ cylinder_R) ∩ half_space{x <= 0}``. r in (0, R), thickness
    in (0, r). The outer torus stays the left-most child, so the root is certified.
    """
    Rr = _num("R", R)
    rr = _num("r", r, 0.0, Rr, hi_open=True)
    t = _num("thickness", thickness, 0.0, rr, hi_open=True)
    b = geom.SceneBuilder() if builder is None else builder
    shell = b.add_difference(b.add_leaf("torus", [Rr, rr]), b.add_leaf("torus", [Rr, rr - t]))
    inner = b.add_intersection(shell, _solid_cylinder_node(b, Rr, 2.0 * rr + 0.02 * Rr))
    root = _certified(b, b.add_intersection(inner, b.add_leaf("half_space", [1, 0, 0, 0])),
                      "intalox_saddle")
    m = 0.1 * (Rr + rr)
    bounds = (np.array([-Rr - m, -rr - m, -Rr - m]), np.array([m, rr + m, Rr + m]))
    return Element(b, root, "intalox_saddle", dict(R=Rr, r=rr, thickness=t), bounds, None, None,
                   t)


def sphere(radius=0.5, builder=None):
    """A solid sphere of ``radius`` > 0; its own envelope."""
    r = _num("radius", radius)
    b = geom.SceneBuilder() if builder is None else builder
    root = _certified(b, b.add_leaf("sphere", [r]), "sphere")
    return Element(b, root, "sphere", dict(radius=r), _box_bounds(r, r, r, 0.12 * r), root,
                   4.0 / 3.0 * math.pi * r ** 3, 2 * r)


def solid_cylinder(radius=0.5, height=1.0, builder=None):
    """A solid cylinder (axis y): the exact cone leaf with equal radii; its own envelope."""
    r = _num("radius", radius)
    h = _num("height", height)
    b = geom.SceneBuilder() if builder is None else builder
    root = _certified(b, _solid_cylinder_node(b, r, h), "solid_cylinder")
    return Element(b, root, "solid_cylinder", dict(radius=r, height=h),
                   _box_bounds(r, 0.5 * h, r, 0.12 * max(r, 0.5 * h)), root,
                   math.pi * r * r * h, min(2 * r, h))


#: Constructors by name (the CLI and tests iterate over it).
ELEMENTS = {"pall_ring": pall_ring, "raschig_ring": raschig_ring, "berl_saddle": berl_saddle,
            "intalox_saddle": intalox_saddle, "sphere": sphere, "solid_cylinder": solid_cylinder}


# ---------------------------------------------------------------------- element parameters
@dataclass(frozen=True)
class Param:
    """One construction parameter of a library element, as the command line and a
    :class:`~peclet.ensemble.spec.PackSpec` may set it.

    ``kind``: ``"float"``, ``"int"`` or ``"triple"`` (three numbers written ``a/b/c``).
    ``lo``/``hi``: the accepted interval of a number (open per ``lo_open``/``hi_open``); ``hi``
    may be a callable of the element's resolved parameters returning ``(hi, hi_open, why)``
    where the bound depends on the others. ``doc``: one line (lengths in the element's unit,
    see :data:`PARAMS`). Cross-constraints not expressed by the interval are stated in ``doc``
    and checked by the constructor.
    """

    name: str
    kind: str
    doc: str
    lo: float = 0.0
    hi: object = math.inf
    lo_open: bool = True
    hi_open: bool = False

    def bounds(self, params):
        """(lo, hi, lo_open, hi_open, why) of this parameter given the resolved ``params``."""
        if callable(self.hi):
            hi, hi_open, why = self.hi(params)
            return self.lo, hi, self.lo_open, hi_open, why
        return self.lo, self.hi, self.lo_open, self.hi_open, ""

    def range_text(self, params, why=True):
        """The accepted range as text, e.g. ``in (0, 0.16] (< r_outer = 0.5, ...)`` (the
        reasons for a dependent bound only with ``why``)."""
        if self.kind == "triple":
            return "three numbers a/b/c, each > 0"
        lo, hi, lo_open, hi_open, reason = self.bounds(params)
        rng = f"{'(' if lo_open else '['}{lo:g}, {'inf' if math.isinf(hi) else f'{hi:g}'}" \
              f"{')' if hi_open or math.isinf(hi) else ']'}"
        text = ("an integer in " if self.kind == "int" else "in ") + rng
        return text + (f" ({reason})" if reason and why else "")


def _pall_thickness_hi(p):
    wr, web_x = p["window_half"][0], p["web_half"][0]
    cands = [(p["r_outer"], True, "< r_outer"), (wr, False, "<= window_half radial"),
             (2.0 * (p["r_outer"] - web_x), False, "<= 2 (r_outer - web_half x)")]
    hi, hi_open, _ = min(cands, key=lambda c: (c[0], not c[1]))
    why = ", ".join(f"{w} = {v:g}" for v, _, w in cands)
    return hi, hi_open, why


#: Every library element's parameters (lengths in the element's own unit: the defaults make
#: the envelope diameter D = 1, so with the defaults a length IS in element diameters; the
#: containers of ``pack`` are always in D, D = 2 r_outer, 2 radius or 2 R).
PARAMS = {
    "pall_ring": (
        Param("r_outer", "float", "outer radius (D = 2 r_outer); default 0.5"),
        Param("height", "float", "tube height along the axis; default 1.0"),
        Param("thickness", "float", "wall thickness, < r_outer, <= window_half radial and "
              "<= 2 (r_outer - web_half x); default 0.12 (t/D = 0.12, the page's)",
              hi=_pall_thickness_hi),
        Param("n_windows", "int", "windows per row (lower row offset by half a pitch); "
              "default 4", lo=1, hi=16, lo_open=False),
        Param("window_y", "float", "height of the two window rows and webs (+-window_y); "
              "default 0.24", lo=0.0, lo_open=False,
              hi=lambda p: (0.5 * p["height"], True, "< height/2")),
        Param("window_half", "triple", "window box half-extents radial/axial/tangential, "
              "radial >= thickness, axial < height/2; default 0.16/0.17/0.13"),
        Param("web_half", "triple", "web plate half-extents x/y/z, x <= r_outer - "
              "thickness/2; default 0.4/0.06/0.06"),
    ),
    "raschig_ring": (
        Param("r_outer", "float", "outer radius (D = 2 r_outer); default 0.5"),
        Param("height", "float", "tube height; default 1.0"),
        Param("thickness", "float", "wall thickness, < r_outer; default 0.12",
              hi=lambda p: (p["r_outer"], True, "< r_outer")),
    ),
    "berl_saddle": (
        Param("R", "float", "torus centre-line radius (D = 2 R); default 0.5"),
        Param("r", "float", "torus tube radius, < R; default 0.2",
              hi=lambda p: (p["R"], True, "< R")),
    ),
    "intalox_saddle": (
        Param("R", "float", "torus centre-line radius (D = 2 R); default 0.5"),
        Param("r", "float", "torus tube radius, < R; default 0.3",
              hi=lambda p: (p["R"], True, "< R")),
        Param("thickness", "float", "sheet thickness, < r; default 0.06",
              hi=lambda p: (p["r"], True, "< r")),
    ),
    "sphere": (
        Param("radius", "float", "radius (D = 2 radius); default 0.5"),
    ),
    "solid_cylinder": (
        Param("radius", "float", "radius (D = 2 radius); default 0.5"),
        Param("height", "float", "height along the axis; default 1.0"),
    ),
}


#: Every length parameter of a library element (in the element's unit, whose defaults make
#: D = 1) lies in [MIN_ELEMENT_LENGTH, MAX_ELEMENT_LENGTH], a zero where one is allowed
#: (``window_y``) aside: beyond, the element's volume and moments (D^3, D^5) and the bed's
#: areas in D^2 leave float64 or the DEM's lengths (:mod:`peclet.dem.limits`).
MIN_ELEMENT_LENGTH, MAX_ELEMENT_LENGTH = 1e-6, 1e6
#: ... and within this factor of the element's diameter D (either way): a wall 1e-3 D thin
#: already needs ~1e6 shell probes (they follow the thinnest wall), and a length 1e3 D makes
#: a rod or plate no container in D holds.
MAX_ELEMENT_ASPECT = 1e3


def _check_extents(kind, params, arg, shown):
    """Refuse (PecletArgumentError naming ``arg``) a length parameter of ``kind`` (``params``
    the given ones, defaults for the rest) outside [MIN_ELEMENT_LENGTH, MAX_ELEMENT_LENGTH] or
    farther than MAX_ELEMENT_ASPECT from the diameter D (twice the first parameter)."""
    from peclet.core.validation import PecletArgumentError

    ctx = dict(element_defaults(kind), **params)
    first = PARAMS[kind][0].name
    d = 2.0 * float(ctx[first])
    for p in PARAMS[kind]:
        if p.kind == "int":
            continue
        vals = ctx[p.name] if p.kind == "triple" else (ctx[p.name],)
        for j, v in enumerate(vals):
            v = float(v)
            label = p.name if p.kind != "triple" else f"{p.name}[{j}]"
            if v == 0.0:
                continue
            if not MIN_ELEMENT_LENGTH <= v <= MAX_ELEMENT_LENGTH:
                raise PecletArgumentError(
                    arg, f"{kind} with every length in [{MIN_ELEMENT_LENGTH:g}, "
                    f"{MAX_ELEMENT_LENGTH:g}] (the element's unit, D = 1 by default)", shown,
                    f"{label} = {v:g}")
            if p.name != first and not d / MAX_ELEMENT_ASPECT <= v <= d * MAX_ELEMENT_ASPECT:
                raise PecletArgumentError(
                    arg, f"{kind} with every length within a factor {MAX_ELEMENT_ASPECT:g} of "
                    f"its diameter D = 2 {first} = {d:g}", shown, f"{label} = {v:g}")


def element_defaults(kind):
    """The library element ``kind``'s default parameters (name -> value)."""
    import inspect

    sig = inspect.signature(ELEMENTS[kind])
    return {p.name: sig.parameters[p.name].default for p in PARAMS[kind]}


def _fmt_value(kind, v):
    if kind == "int":
        return str(int(v))
    if kind == "triple":
        return "/".join(repr(float(x)) for x in v)
    return repr(float(v))


def element_text(kind, params):
    """Canonical text of a library element with the given (checked) parameters: the name,
    then ``:k=v,...`` in :data:`PARAMS` order, floats as their shortest round-trip repr,
    triples as ``a/b/c`` (``"pall_ring"`` when none is given)."""
    given = [p for p in PARAMS[kind] if p.name in params]
    if not given:
        return kind
    return kind + ":" + ",".join(f"{p.name}={_fmt_value(p.kind, params[p.name])}"
                                 for p in given)


def check_param(kind, pname, value, params=None, arg="element", shown=None):
    """``value`` (a number or text) of parameter ``pname`` of library element ``kind``
    converted and range-checked against the others (``params``: the given ones, defaults for
    the rest). Raises PecletArgumentError naming ``arg`` with the parameter and its accepted
    range; ``shown`` is the value reported (default: ``value``)."""
    from peclet.core.validation import PecletArgumentError

    shown = value if shown is None else shown
    table = {p.name: p for p in PARAMS[kind]}
    if pname not in table:
        raise PecletArgumentError(arg, f"a parameter of {kind} ({', '.join(table)})", shown,
                                  f"unknown parameter {pname!r}")
    p = table[pname]
    ctx = dict(element_defaults(kind), **(params or {}))
    what = f"{kind} with {pname} {p.range_text(ctx)}"
    if p.kind == "triple":
        parts = value.split("/") if isinstance(value, str) else value
        try:
            arr = tuple(float(x) for x in parts)
        except (TypeError, ValueError):
            raise PecletArgumentError(arg, what, shown, f"{pname} is not three numbers") \
                from None
        if len(arr) != 3 or not all(math.isfinite(x) and x > 0 for x in arr):
            raise PecletArgumentError(arg, what, shown, f"{pname} out of range")
        return arr
    if isinstance(value, bool):
        raise PecletArgumentError(arg, what, shown, f"{pname} is not a number")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise PecletArgumentError(arg, what, shown, f"{pname} is not a number") from None
    if p.kind == "int":
        if not (math.isfinite(v) and v.is_integer()):
            raise PecletArgumentError(arg, what, shown, f"{pname} is not an integer")
        v = int(v)
    lo, hi, lo_open, hi_open, _ = p.bounds(ctx)
    ok = math.isfinite(v) and (v > lo if lo_open else v >= lo) \
        and (v < hi if hi_open else v <= hi)
    if not ok:
        raise PecletArgumentError(arg, what, shown, f"{pname} = {v:g} out of range")
    return v


def parse_element(value, arg="element"):
    """A library element with parameters -> ``(kind, params)``, ``params`` the given ones,
    checked (names, numbers, ranges against each other; the constructor's own cross-checks
    too). Accepted forms: ``"pall_ring"``, ``"pall_ring:thickness=0.024,n_windows=5"`` (the
    command line's; a triple is written ``a/b/c``) and ``("pall_ring", {"thickness": 0.024})``.
    Raises PecletArgumentError naming ``arg``, the parameter and its accepted range."""
    from peclet.core.validation import PecletArgumentError

    forms = (f"a library element {sorted(ELEMENTS)}, optionally with parameters "
             "NAME:KEY=V,KEY=V (see peclet pack -h)")
    if isinstance(value, tuple) and len(value) == 2 and isinstance(value[0], str) \
            and isinstance(value[1], dict):
        kind, items = value[0], list(value[1].items())
    elif isinstance(value, str):
        kind, sep, rest = value.partition(":")
        kind = kind.strip()
        items = []
        if sep:
            if not rest.strip():
                raise PecletArgumentError(arg, forms, value, "no parameters after ':'")
            for tok in rest.split(","):
                k, eq, v = tok.partition("=")
                if not eq or not k.strip() or not v.strip():
                    raise PecletArgumentError(arg, forms, value, f"bad item {tok.strip()!r} "
                                              "(KEY=VALUE expected)")
                items.append((k.strip(), v.strip()))
    else:
        raise PecletArgumentError(arg, forms, value)
    if kind not in ELEMENTS:
        raise PecletArgumentError(arg, forms, value, f"unknown element {kind!r}")
    names = [k for k, _ in items]
    if len(set(names)) != len(names):
        raise PecletArgumentError(arg, forms, value, "a parameter given twice")
    # names and number syntax first, then ranges against the resolved others
    table = {p.name: p for p in PARAMS[kind]}
    raw = {}
    for k, v in items:
        if not isinstance(k, str) or k not in table:
            raise PecletArgumentError(arg, f"a parameter of {kind} ({', '.join(table)})",
                                      value, f"unknown parameter {k!r}")
        raw[k] = v
    loose = {}                    # syntax first (a triple's own check has no range)
    for k, v in raw.items():
        try:
            loose[k] = tuple(float(x) for x in (v.split("/") if isinstance(v, str) else v)) \
                if table[k].kind == "triple" else float(v)
        except (TypeError, ValueError):
            check_param(kind, k, v, {}, arg, value)   # raises: not a number
        if isinstance(v, bool):
            check_param(kind, k, v, {}, arg, value)
    params = {k: check_param(kind, k, raw[k], loose, arg, value) for k in raw}
    _check_extents(kind, params, arg, value)
    try:
        ELEMENTS[kind](**params)
    except ValueError as exc:
        raise PecletArgumentError(arg, f"{kind} parameters consistent with each other "
                                  "(see peclet pack -h)", value, str(exc)) from None
    return kind, params


def params_help():
    """Every library element's parameters as ``-h`` text."""
    lines = []
    for kind, ps in PARAMS.items():
        d = element_defaults(kind)
        items = "; ".join(f"{p.name} {p.range_text(d, False) if p.kind != 'triple' else 'a/b/c'}"
                          f": {p.doc}" for p in ps)
        lines.append(f"{kind}: {items}")
    return ". ".join(lines)
