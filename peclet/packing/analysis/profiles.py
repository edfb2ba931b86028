"""Column analysis of a frozen pack: radial and axial voidage profiles, bulk voidage and
envelope fraction with standard errors over axial windows, orientation against an axis, and
coordination counting element-element and element-wall contacts.

Conventions: world frame y up, the column axis along y; lengths are world lengths unless named
``z`` (distance from the wall, in element diameters ``d_elem``). A point is solid when some
element's tree has phi < 0 there (phi < 0 inside) and in an envelope when some envelope has
phi <= 0, as in :mod:`peclet.packing.analysis.geometry`. Points are tested exactly on the trees through
the scene query (:meth:`peclet.core.geom.SceneBuilder.eval_scene`, a BVH over the elements'
certified balls), never on a voxel grid; every fraction is a Monte Carlo mean of uniform points
with its binomial standard error ``sqrt(p (1 - p) / n)``.

A pack's cross-section is given explicitly (this module does not know the container):
:class:`ColumnSection` (a disc, not periodic) or :class:`BoxSection` (a rectangle, periodic or
walled); :func:`periodic_section` is the page's periodic box of a pack.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from peclet.core.validation import (PecletArgumentError, check_array, check_bool, check_float,
                                    check_int)

from .geometry import PackGeometry, fraction_se, probe_overlap
from ..bed.freeze import Pack

__all__ = ["ColumnSection", "BoxSection", "FluidSection", "periodic_section", "PackSampler",
           "radial_profile",
           "check_column_holds_bed",
           "axial_profile", "bulk", "orientation_to_axis", "coordination", "de_klerk_voidage",
           "benyahia_oneill_voidage"]


# ---------------------------------------------------------------------- cross-sections
@dataclass(frozen=True)
class ColumnSection:
    """The disc of a cylindrical column: ``radius`` > 0 about ``center_xz`` = (x, z)."""

    radius: float
    center_xz: tuple = (0.0, 0.0)
    periodic = False

    def __post_init__(self):
        object.__setattr__(self, "radius", check_float("column_radius", self.radius, 0.0,
                                                       lo_open=True))
        c = check_array("center_xz", self.center_xz, (2,))
        object.__setattr__(self, "center_xz", (float(c[0]), float(c[1])))

    @property
    def area(self):
        return math.pi * self.radius ** 2

    def sample(self, rng, n):
        """(x, z) of ``n`` points uniform on the disc (radius ``R sqrt(U)``: area-correct)."""
        r = self.radius * np.sqrt(rng.random(n))
        t = 2.0 * math.pi * rng.random(n)
        return self.center_xz[0] + r * np.cos(t), self.center_xz[1] + r * np.sin(t)


@dataclass(frozen=True)
class BoxSection:
    """The rectangle [lo_xz, hi_xz) in (x, z); ``periodic`` for the page's periodic box."""

    lo_xz: tuple
    hi_xz: tuple
    periodic: bool = False

    def __post_init__(self):
        lo = check_array("lo_xz", self.lo_xz, (2,))
        hi = check_array("hi_xz", self.hi_xz, (2,))
        if not np.all(hi > lo):
            raise PecletArgumentError("hi_xz", f"greater than lo_xz = {lo.tolist()}", hi.tolist())
        object.__setattr__(self, "lo_xz", (float(lo[0]), float(lo[1])))
        object.__setattr__(self, "hi_xz", (float(hi[0]), float(hi[1])))
        object.__setattr__(self, "periodic", check_bool("periodic", self.periodic))

    @property
    def area(self):
        return (self.hi_xz[0] - self.lo_xz[0]) * (self.hi_xz[1] - self.lo_xz[1])

    def sample(self, rng, n):
        return (rng.uniform(self.lo_xz[0], self.hi_xz[0], n),
                rng.uniform(self.lo_xz[1], self.hi_xz[1], n))


@dataclass(frozen=True)
class FluidSection:
    """A container whose fluid region changes with height (a vessel from a tree or a CAD mesh,
    e.g. with a support plate): points are drawn on the rectangle ``box`` (a
    :class:`BoxSection` holding the region's horizontal extent) and only those where
    ``fluid(points (K, 3)) -> bool (K,)`` holds count, so a voidage is the fraction of the
    fluid region's volume, never of the vessel's internals."""

    box: BoxSection
    fluid: object
    periodic = False

    def __post_init__(self):
        if not isinstance(self.box, BoxSection) or not callable(self.fluid):
            raise PecletArgumentError("section", "a FluidSection(BoxSection, fluid callable)",
                                      self)

    @property
    def area(self):
        return self.box.area

    def sample(self, rng, n):
        return self.box.sample(rng, n)


#: The cross-sections the profiles accept
SECTIONS = (ColumnSection, BoxSection, FluidSection)


def _fluid_mask(section, pts):
    """Which of ``pts`` are in the section's fluid region (None: all of them)."""
    if not isinstance(section, FluidSection):
        return None
    return np.asarray(section.fluid(pts), bool)


def periodic_section(pack: Pack) -> BoxSection:
    """The pack's own periodic box [0, L_x) x [0, L_z)."""
    return BoxSection((0.0, 0.0), tuple(pack.box), True)


# ---------------------------------------------------------------------- exact point tests
class PackSampler:
    """Point membership in a pack's elements and envelopes, evaluated exactly on the trees.

    One scene per tree (element, envelope), each instance placed at its position with its
    quaternion (x, y, z, w, home -> world). ``periodic`` adds the images of the pack's periodic
    box in x and z (the scene wraps query points into it).
    """

    def __init__(self, pack: Pack, periodic=False):
        self.pack = pack
        self.periodic = check_bool("periodic", periodic)
        self.has_envelope = pack.envelope_root >= 0
        self._solid = self._scene(pack.home_root)
        self._env = self._scene(pack.envelope_root) if self.has_envelope else None

    def _scene(self, root):
        b = self.pack.builder()
        pos = self.pack.positions
        if self.periodic:  # the scene wants every instance inside the box on its periodic axes
            pos = pos.copy()
            for a, L in ((0, self.pack.box[0]), (2, self.pack.box[1])):
                pos[:, a] = np.mod(pos[:, a], L)
                pos[pos[:, a] >= L, a] = 0.0  # a tiny negative coordinate rounds up to L
        for p, q in zip(pos, self.pack.quaternions):
            b.add_instance(root, translation=p, rotation=q)
        if not self.periodic:
            return lambda pts: b.eval_scene(pts)
        y = self.pack.positions[:, 1]
        r = self.pack.bounding_radius
        box = ((0.0, float(y.min()) - r - 1.0, 0.0),
               (float(self.pack.box[0]), float(y.max()) + r + 1.0, float(self.pack.box[1])))
        return lambda pts: b.eval_scene(pts, box=box, periodic=(True, False, True))

    def solid(self, pts):
        """Boolean (K,): inside some element (phi < 0) at world points ``pts`` (K, 3)."""
        return self._solid(np.ascontiguousarray(pts, dtype=np.float64)) < 0.0

    def in_envelope(self, pts):
        """Boolean (K,): inside some envelope (phi <= 0); requires an envelope."""
        if not self.has_envelope:
            raise ValueError("the pack's element has no envelope")
        return self._env(np.ascontiguousarray(pts, dtype=np.float64)) <= 0.0


def _sampler_for(pack, section):
    return PackSampler(pack, periodic=section.periodic)


def _check_pack(pack):
    if not isinstance(pack, Pack):
        raise PecletArgumentError("pack", "a peclet.packing.bed.freeze.Pack", pack)
    if pack.n < 1:
        raise PecletArgumentError("pack", "a pack of at least one element", pack.n)
    return pack


def _check_span(y_lo, y_hi):
    lo = check_float("y_lo", y_lo)
    hi = check_float("y_hi", y_hi)
    if not hi > lo:
        raise PecletArgumentError("y_hi", f"greater than y_lo = {lo:g}", y_hi)
    return lo, hi


def _fractions(flags, groups, n_per, mask=None):
    """Per-group mean of boolean ``flags`` laid out group-major, and binomial standard errors;
    with ``mask``, over the masked points of each group only (NaN for a group with none)."""
    if mask is None:
        p = flags.reshape(groups, n_per).mean(axis=1)
        return p, np.sqrt(np.maximum(p * (1.0 - p), 0.0) / n_per)
    m = mask.reshape(groups, n_per)
    count = m.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        p = (flags.reshape(groups, n_per) & m).sum(axis=1) / count
        return p, np.sqrt(np.maximum(p * (1.0 - p), 0.0) / count)


# ---------------------------------------------------------------------- profiles
def check_column_holds_bed(pack, section, y_lo, y_hi):
    """Refuse a column (a :class:`ColumnSection`: radius R about ``center_xz``, world) that
    does not hold the bed between heights ``y_lo`` and ``y_hi`` (world), reading the element
    centres and the bounding radius r_b only. PecletArgumentError naming ``y_lo`` when no
    element's bounding sphere reaches the span, and ``center_xz`` when an element there lies
    wholly outside the column (its centre farther than R + r_b from the axis): no wall of
    that column bounds it, so the column is not the bed's."""
    P, rb = pack.positions, float(pack.bounding_radius)
    span = (P[:, 1] + rb > y_lo) & (P[:, 1] - rb < y_hi)
    if not span.any():
        raise PecletArgumentError(
            "y_lo", "the bottom of a height span that meets the bed", y_lo,
            f"y in [{y_lo:.4g}, {y_hi:.4g}]; element centres from y = {P[:, 1].min():.4g} to "
            f"{P[:, 1].max():.4g}, bounding radius {rb:.4g}")
    cx, cz = section.center_xz
    rho = np.hypot(P[:, 0] - cx, P[:, 2] - cz)
    out = span & (rho > (section.radius + rb) * (1.0 + 1e-12))
    if out.any():
        k = int(np.flatnonzero(out)[np.argmax(rho[out])])
        raise PecletArgumentError(
            "center_xz", f"the axis (x, z) of a column of radius {section.radius:.4g} that "
            "holds the bed", section.center_xz,
            f"{int(out.sum())} of {int(span.sum())} elements in the span lie wholly outside "
            f"it, e.g. element {k} at (x, z) = ({P[k, 0]:.4g}, {P[k, 2]:.4g}), "
            f"{rho[k]:.4g} from the axis > R + r_b = {section.radius + rb:.4g}"
            + ("; the centre is outside the bed: every shell would read eps = 1"
               if out.sum() == span.sum() else ""))


def radial_profile(pack, column_radius, center_xz, y_lo, y_hi, d_elem=1.0, shell_width=0.02,
                   samples_per_shell=4000, seed=0):
    """Voidage against the distance from a cylindrical wall, eps(z), z = (R - r) / d_elem.

    Shells are annuli of width ``shell_width * d_elem`` (``shell_width`` in (0, 0.02]) counted
    from the wall r = R inwards (the last one, at the axis, may be narrower: a disc), between
    heights ``y_lo`` and ``y_hi``. Each shell gets ``samples_per_shell`` points uniform in its
    volume: r = sqrt(r_in^2 + U (r_out^2 - r_in^2)) (area-correct), angle and height uniform
    (numpy ``default_rng(seed)``). The column is not periodic.

    Returns a dict: ``z`` (shell centres, in d_elem), ``z_edges`` (n + 1), ``eps`` and
    ``eps_se`` (binomial standard error per shell), ``n_per_shell``, ``y_span``, ``d_elem``.

    The column must hold the bed (:func:`check_column_holds_bed`): a height span no element
    reaches is refused (naming ``y_lo``), and so is a column of radius R about ``center_xz``
    that leaves an element of the span wholly outside it (naming ``center_xz``): a centre
    outside the bed would otherwise give eps = 1 in every shell, a misplaced one a profile of
    no wall.
    """
    pack = _check_pack(pack)
    sec = ColumnSection(column_radius, center_xz)
    lo, hi = _check_span(y_lo, y_hi)
    d = check_float("d_elem", d_elem, 0.0, lo_open=True)
    w = check_float("shell_width", shell_width, 0.0, 0.02, lo_open=True) * d
    n = check_int("samples_per_shell", samples_per_shell, 1, 10 ** 7)
    check_column_holds_bed(pack, sec, lo, hi)
    R = sec.radius
    nshell = max(1, int(math.ceil(R / w - 1e-9)))
    dist = np.minimum(np.arange(nshell + 1) * w, R)  # distance from the wall at shell edges
    r_out = R - dist[:-1]
    r_in = R - dist[1:]
    rng = np.random.default_rng(seed)
    u = rng.random((nshell, n))
    r = np.sqrt(r_in[:, None] ** 2 + u * (r_out ** 2 - r_in ** 2)[:, None])
    t = 2.0 * math.pi * rng.random((nshell, n))
    y = rng.uniform(lo, hi, (nshell, n))
    pts = np.column_stack([(sec.center_xz[0] + r * np.cos(t)).ravel(), y.ravel(),
                           (sec.center_xz[1] + r * np.sin(t)).ravel()])
    solid, se = _fractions(_sampler_for(pack, sec).solid(pts), nshell, n)
    return dict(z=0.5 * (dist[:-1] + dist[1:]) / d, z_edges=dist / d, eps=1.0 - solid,
                eps_se=se, n_per_shell=n, y_span=(lo, hi), d_elem=d)


def axial_profile(pack, section, y_lo, y_hi, slab=0.05, d_elem=1.0, samples_per_slab=4000,
                  seed=0):
    """Voidage of horizontal slabs of height ``slab * d_elem`` over the cross-section.

    ``section``: a :class:`ColumnSection`, :class:`BoxSection` or :class:`FluidSection`
    (a slab's voidage is then over its fluid points; NaN where it has none); slabs tile
    [y_lo, y_hi) (the
    top one may be thinner). Returns a dict: ``y`` (slab centres, world), ``y_edges``, ``eps``,
    ``eps_se`` (binomial), ``n_per_slab``.
    """
    pack = _check_pack(pack)
    if not isinstance(section, SECTIONS):
        raise PecletArgumentError("section", "a ColumnSection, BoxSection or FluidSection",
                                  section)
    lo, hi = _check_span(y_lo, y_hi)
    d = check_float("d_elem", d_elem, 0.0, lo_open=True)
    h = check_float("slab", slab, 0.0, lo_open=True) * d
    n = check_int("samples_per_slab", samples_per_slab, 1, 10 ** 7)
    nslab = max(1, int(math.ceil((hi - lo) / h - 1e-9)))
    edges = np.minimum(lo + np.arange(nslab + 1) * h, hi)
    rng = np.random.default_rng(seed)
    x, z = section.sample(rng, nslab * n)
    y = edges[:-1, None] + rng.random((nslab, n)) * np.diff(edges)[:, None]
    pts = np.column_stack([x, y.ravel(), z])
    solid, se = _fractions(_sampler_for(pack, section).solid(pts), nslab, n,
                           _fluid_mask(section, pts))
    return dict(y=0.5 * (edges[:-1] + edges[1:]), y_edges=edges, eps=1.0 - solid, eps_se=se,
                n_per_slab=n)


def bulk(pack, section, floor_y=0.0, top_y=None, d_elem=1.0, crop=2.0, n_windows=4,
         samples_per_window=100_000, seed=0):
    """Bulk voidage eps and envelope fraction f_env over the whole cross-section, with standard
    errors over axial windows.

    Cropping rule: the floor zone [floor_y, floor_y + crop d_elem) and the free-surface zone
    (top_y - crop d_elem, top_y] are left out, ``top_y`` being the highest element centre unless
    given; the remaining height is cut into ``n_windows`` equal windows, each sampled with
    ``samples_per_window`` uniform points. The bulk value is the mean of the windows; ``eps_se``
    is the standard error of that mean from the window-to-window scatter (std / sqrt(n_windows),
    which holds both the sampling noise and the bed's own axial variation) and
    ``eps_se_sampling`` the binomial error of the pooled points alone. f_env likewise (NaN
    without an envelope). A column's bulk keeps its wall zone: it is the cross-section mean that
    the bed-voidage correlations (e.g. Benyahia & O'Neill 2005) describe.
    """
    pack = _check_pack(pack)
    if not isinstance(section, SECTIONS):
        raise PecletArgumentError("section", "a ColumnSection, BoxSection or FluidSection",
                                  section)
    y0 = check_float("floor_y", floor_y)
    top = float(pack.positions[:, 1].max()) if top_y is None else check_float("top_y", top_y)
    d = check_float("d_elem", d_elem, 0.0, lo_open=True)
    c = check_float("crop", crop, 0.0)
    nw = check_int("n_windows", n_windows, 2, 1000)
    n = check_int("samples_per_window", samples_per_window, 1, 10 ** 8)
    lo, hi = y0 + c * d, top - c * d
    if not hi > lo:
        raise PecletArgumentError(
            "crop", f"small enough to leave a bed between the cropped zones (<= "
            f"{max((top - y0) / (2 * d), 0.0):.3g} for this bed)", crop,
            f"bed from y = {y0:g} to its top at {top:g}")
    edges = lo + (hi - lo) * np.arange(nw + 1) / nw
    # a window no element's bounding sphere reaches holds no bed: refused, not eps = 1 +- 0
    ys, rb = pack.positions[:, 1], float(pack.bounding_radius)
    for a, b in zip(edges[:-1], edges[1:]):
        if not np.any((ys - rb < b) & (ys + rb > a)):
            raise PecletArgumentError(
                "pack", "a bed that reaches every bulk window (no element reaches the window "
                f"y in [{a:.4g}, {b:.4g}): the bed is a film or has a gap)", f"{pack.n} elements",
                f"centres from y = {ys.min():.4g} to {ys.max():.4g}, bounding radius {rb:.4g}")
    rng = np.random.default_rng(seed)
    x, z = section.sample(rng, nw * n)
    y = edges[:-1, None] + rng.random((nw, n)) * np.diff(edges)[:, None]
    pts = np.column_stack([x, y.ravel(), z])
    smp = _sampler_for(pack, section)
    mask = _fluid_mask(section, pts)
    counted = nw * n if mask is None else int(mask.sum())
    solid, _ = _fractions(smp.solid(pts), nw, n, mask)
    if not np.all(solid > 0):
        k = int(np.flatnonzero(~(solid > 0))[0])
        raise PecletArgumentError(
            "samples_per_window", "enough samples for every window to hit an element", n,
            f"no sample of window y in [{edges[k]:.4g}, {edges[k + 1]:.4g}) hit one: eps "
            "would be 1 +- 0; the bed is too sparse there (a film) or the samples too few")
    eps_w = 1.0 - solid
    out = dict(windows=np.column_stack([edges[:-1], edges[1:]]), eps_windows=eps_w,
               eps=float(eps_w.mean()), eps_se=float(eps_w.std(ddof=1) / math.sqrt(nw)),
               eps_se_sampling=fraction_se(float(eps_w.mean()), counted),
               n_samples=counted, crop=c, top_y=top)
    if smp.has_envelope:
        f_w, _ = _fractions(smp.in_envelope(pts), nw, n, mask)
        out.update(f_env_windows=f_w, f_env=float(f_w.mean()),
                   f_env_se=float(f_w.std(ddof=1) / math.sqrt(nw)),
                   f_env_se_sampling=fraction_se(float(f_w.mean()), counted))
    else:
        out.update(f_env_windows=np.full(nw, math.nan), f_env=math.nan, f_env_se=math.nan,
                   f_env_se_sampling=math.nan)
    return out


# ---------------------------------------------------------------------- orientation, contacts
def orientation_to_axis(pack, axis=(0.0, 1.0, 0.0)):
    """|cos theta| between each element's axis (R(q_i) @ pack.axis_home) and ``axis``.

    Returns a dict: cos (N,), mean, sem (sample standard error), sem_iso (that of an isotropic
    axis, |cos| uniform on [0, 1]: 1/sqrt(12 N)) and s2 = <(3 cos^2 - 1) / 2>, the nematic order
    parameter (0 isotropic, 1 all along ``axis``, -1/2 all perpendicular).
    """
    pack = _check_pack(pack)
    a = check_array("axis", axis, (3,))
    na = float(np.linalg.norm(a))
    if na == 0.0:
        raise PecletArgumentError("axis", "a non-zero vector", axis)
    c = np.abs((pack.rotations() @ pack.axis_home) @ (a / na))
    n = len(c)
    return dict(cos=c, mean=float(c.mean()),
                sem=float(c.std(ddof=1) / math.sqrt(n)) if n > 1 else math.nan,
                sem_iso=float(1.0 / math.sqrt(12.0 * n)),
                s2=float(np.mean(1.5 * c * c - 0.5)))


def coordination(pack, walls=(), gap=0.0, periodic=False):
    """Contacts per element, counting other elements AND walls, from the DEM engine's own
    contact detection (:func:`peclet.packing.analysis.coordination.engine_coordination`: exact for
    spheres, the narrow phase for composed elements).

    ``walls`` is a sequence of ``(builder, root)`` trees in the world frame, phi < 0 inside the
    wall material (e.g. a column's complement, a floor), each one contact partner;
    ``gap`` (a length >= 0) the contact threshold on the engine's gap; ``periodic`` whether the
    pack's box is periodic in x and z (False for a column or walled box: no images).

    Returns the engine's dict (elem, wall, total, z_elem, z_total, rattlers, under_stable,
    pairs, gap, min_gap, method) and ``probe_max_depth``, the deepest surface probe of one
    element inside another (:func:`peclet.packing.analysis.geometry.probe_overlap`: the overlap depth,
    which the probes measure, not a contact count).
    """
    from .coordination import engine_coordination

    pack = _check_pack(pack)
    per = check_bool("periodic", periodic)
    out = engine_coordination(pack, walls, gap=gap, periodic=per)   # checks walls and gap
    if len(pack.shell):
        if not per:
            # images one box apart would touch across the wall: put them out of every reach
            ext = np.ptp(pack.positions, axis=0).max() + 4.0 * pack.bounding_radius + 1.0
            pack = dataclasses.replace(pack, box=np.array([ext, ext]))
        out["probe_max_depth"] = probe_overlap(PackGeometry(pack))["max_depth"]
    else:
        out["probe_max_depth"] = math.nan
    return out


# ---------------------------------------------------------------------- sphere correlations
def de_klerk_voidage(z, eps_bulk=0.39):
    """Radial voidage of a random bed of equal spheres against z, the distance from the wall in
    sphere diameters (de Klerk, AIChE J. 49 (2003) 2022-2029):

        eps = 2.14 z^2 - 2.53 z + 1                                          z <= 0.637
        eps = eps_b + 0.29 exp(-0.6 z) cos(2.3 pi (z - 0.16)) + 0.15 exp(-0.9 z)   z > 0.637

    ``eps_bulk`` (eps_b) is the far-field voidage; 0.39 is the large-N limit of
    :func:`benyahia_oneill_voidage`. The branches meet continuously at z = 0.637 only for
    eps_b close to 0.361; for other eps_b the correlation jumps there (by +0.029 at 0.39).
    """
    z = np.asarray(z, dtype=np.float64)
    near = 2.14 * z * z - 2.53 * z + 1.0
    far = (eps_bulk + 0.29 * np.exp(-0.6 * z) * np.cos(2.3 * math.pi * (z - 0.16))
           + 0.15 * np.exp(-0.9 * z))
    return np.where(z <= 0.637, near, far)


def benyahia_oneill_voidage(n_ratio):
    """Mean bed voidage of equal spheres in a column of D_t / d = ``n_ratio`` (Benyahia &
    O'Neill, Part. Sci. Technol. 23 (2005) 169-177): eps = 0.390 + 1.740 / (N + 1.140)^2."""
    n = np.asarray(n_ratio, dtype=np.float64)
    return 0.390 + 1.740 / (n + 1.140) ** 2
