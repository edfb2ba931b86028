"""Turn a CSG tree into a DEM particle: mass properties, principal frame, shell probes.

>>> sp = scene_particle.build(b, ring, bounds=([-0.56] * 3, [0.56] * 3), n=32,
...                           shell_resolution=112, target_shell_points=1200)
>>> shape_id = sp.register(sim)

Frames: the *authoring* frame is the parent frame of ``root``; the *home* frame is the principal
frame (com at the origin, principal axes on x, y, z with ascending moments). ``quat`` (x, y, z, w)
rotates home coordinates into authoring coordinates: the columns of its matrix are the principal
axes written in the authoring frame, and p_author = R(quat) p_home + com.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from peclet.core.geom import quadrature
from peclet.core.geom.shell import shell_probes
from peclet.core.validation import PecletArgumentError, check_float
from peclet.dem.limits import MAX_INVERSE, MAX_LENGTH, MIN_INVERSE, MIN_LENGTH


@dataclass(frozen=True)
class SceneParticle:
    """A measured, reframed and shelled CSG particle (see the module docstring for frames).

    ``inv_inertia_unit`` is 1 / principal (per unit density times the density given), i.e.
    the inverse of the body's actual principal moments. ``node_ints`` / ``node_reals`` are the
    builder's encoding at build time; ``home_root`` indexes it.
    """

    volume: float
    mass: float
    density: float
    com: np.ndarray
    principal: np.ndarray
    quat: np.ndarray
    axes: np.ndarray
    home_root: int
    shell: np.ndarray
    bounding_radius: float
    inv_inertia_unit: np.ndarray
    node_ints: np.ndarray
    node_reals: np.ndarray
    volume_error: float
    moment_error: float
    spacing: dict = field(default_factory=dict)
    diagnostics: dict = field(default_factory=dict)

    def register(self, sim) -> int:
        """Register with a Simulation; returns its shape id.

        Calls ``sim.add_scene_shape(node_ints, node_reals, home_root, shell, bounding_radius)``.
        """
        return sim.add_scene_shape(self.node_ints, self.node_reals, self.home_root, self.shell,
                                   self.bounding_radius)


def _as_bounds(bounds):
    try:
        lo, hi = bounds
    except (TypeError, ValueError):
        raise ValueError(f"bounds must be (lo, hi) with 3 numbers each, got {bounds!r}") from None
    lo, hi = quadrature.check_box(lo, hi)
    if max(float(np.abs(lo).max()), float(np.abs(hi).max())) > MAX_LENGTH \
            or float((hi - lo).min()) < MIN_LENGTH:
        raise PecletArgumentError("bounds", f"a box with coordinates of magnitude <= "
                                  f"{MAX_LENGTH:g} and sides >= {MIN_LENGTH:g} (lengths; "
                                  "peclet.dem.limits)", bounds)
    return lo, hi


def _check_mass(density, props):
    """Refuse a density whose mass or principal moments (density r^3, density r^5) leave
    [MIN_INVERSE, MAX_INVERSE]: their inverses are the body's inverse mass and moments."""
    vals = [float(props.mass)] + [float(p) for p in props.principal]
    if not all(MIN_INVERSE <= v <= MAX_INVERSE for v in vals):
        raise PecletArgumentError(
            "density", f"a density giving a mass and principal moments in [{MIN_INVERSE:g}, "
            f"{MAX_INVERSE:g}] (their inverses are the DEM's inverse mass and moments)",
            density, f"mass {vals[0]:g}, moments {', '.join(f'{v:g}' for v in vals[1:])}")


def check_bounded(builder, root, name="root"):
    """Refuse (PecletArgumentError naming ``name``) a tree whose bounding ball
    (``builder.node_bound``) has an infinite or NaN radius: an unbounded solid such as a
    ``half_space``, which no particle can be. Returns the ball's (centre, radius)."""
    c, r, _ = builder.node_bound(root)
    if not np.isfinite(r):
        raise PecletArgumentError(
            name, "the root of a bounded solid (a particle has a finite extent)", root,
            f"its bounding ball's radius is {r}: a half_space leaf is unbounded; a union with "
            "one is too, and an intersection or difference takes its left operand's ball, so "
            "put the bounded operand on the left")
    return c, r


def build(builder, root, bounds, n=32, shell_resolution=112, target_shell_points=1200,
          density=1.0, seed=0, tol=1e-8, cache=None):
    """Measure ``root``, reframe it to its principal frame and place shell probes.

    Parameters
    ----------
    bounds : (lo, hi), a box in the authoring frame that contains the solid (coordinates of
        magnitude <= 1e100, sides >= 1e-100).
    n : int in [2, 4096], the quadrature's sampling resolution per axis of ``bounds`` (see
        :func:`quadrature.body_properties`: ``ceil(n / 4)`` top-level cells, refined
        adaptively). The page's n = 32 measures the Pall ring to ~1e-9 relative.
    tol : relative accuracy asked of the quadrature (its ``volume_error`` reports what was
        reached).
    shell_resolution : int in [8, 1024], marching-cubes lattice per axis for the shell.
    target_shell_points : int >= 4, number of shell probes (exact).
    density : > 0, such that the mass and principal moments lie in [1e-100, 1e100]
        (:mod:`peclet.dem.limits`; checked once measured).
    cache : optional dict shared between builds of the same tree and bounds (the quadrature's,
        :func:`quadrature.body_properties`): a second build, e.g. with more shell probes,
        measures nothing again. The results are bitwise the same with or without it.

    A particle is a bounded solid: a tree whose bounding ball is infinite (a ``half_space``
    leaf in a union, or on the left of an intersection or difference, whose ball it takes)
    is refused (PecletArgumentError naming ``root``) before any work. Otherwise the
    quadrature would measure only the part inside ``bounds`` and the DEM would get an
    infinite bounding radius.
    """
    check_bounded(builder, root)
    lo, hi = _as_bounds(bounds)
    density = check_float("density", density, 0.0, lo_open=True)
    t = target_shell_points
    if isinstance(t, bool) or not isinstance(t, (int, np.integer)) or t < 4:
        raise ValueError(f"target_shell_points must be an integer >= 4, got {t!r}")
    r = shell_resolution
    if isinstance(r, bool) or not isinstance(r, (int, np.integer)) or not 8 <= r <= 1024:
        raise ValueError(f"shell_resolution must be an integer in [8, 1024], got {r!r}")
    home, props = quadrature.principal_frame(builder, root, lo, hi, density=density, n=n,
                                              tol=tol, cache=cache)
    _check_mass(density, props)
    # a box in the home frame containing the solid: the authoring box's corners, rotated
    At = props.axes.T
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])])
    hc = (corners - props.com) @ At.T
    pad = 1e-3 * float(np.max(hi - lo))
    shell, stats = shell_probes(builder, home, int(target_shell_points), shell_resolution,
                                hc.min(axis=0) - pad, hc.max(axis=0) + pad, seed=seed)
    # Guaranteed radius: the home root's bounding ball contains the solid (docs/architecture.md
    # §4), so |c| + r bounds |p| over it. max |probe| is only a lower bound (kept for
    # diagnostics).
    c, r, _ = builder.node_bound(home)
    radius = float(np.linalg.norm(c) + r)
    ni, nr, _, _ = builder.encode()
    return SceneParticle(volume=props.volume, mass=props.mass, density=props.density,
                         com=props.com, principal=props.principal, quat=props.quat,
                         axes=props.axes, home_root=int(home), shell=shell,
                         bounding_radius=radius, inv_inertia_unit=1.0 / props.principal,
                         node_ints=ni, node_reals=nr, volume_error=props.volume_error,
                         moment_error=props.moment_error, spacing=stats,
                         diagnostics=dict(props.diagnostics,
                                          max_probe_radius=float(np.linalg.norm(shell,
                                                                                axis=1).max())))


def compile_kernels():
    """Measure and shell a small composed solid once: compiles (or loads from Numba's on-disk
    cache) the kernels every :func:`build` runs (the quadrature, the principal frame, the shell
    probes) for about 0.1 s of work beyond that, where measuring the page's ring costs 2 s.
    The kernels take flat arrays, so one solid compiles them for every tree. What ``peclet
    warm`` and the test suite's cold start run."""
    from peclet.core import geom

    b = geom.SceneBuilder()
    root = b.add_union(b.add_leaf("sphere", [0.3], translation=[0.1, 0.0, 0.0]),
                       b.add_leaf("box", [0.25, 0.05, 0.15], translation=[-0.1, 0.1, 0.0]))
    build(b, root, bounds=([-0.5] * 3, [0.5] * 3), n=8, shell_resolution=16,
          target_shell_points=64, tol=1e-4)
