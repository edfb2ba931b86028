"""Coordination as the DEM engine sees it: contacts of a frozen pack from the engine's own
contact detection (:meth:`peclet.dem.Simulation.detect_contacts`).

Why not count probes: two convex curved surfaces touch at one point, and no surface probe sits
on it, so testing one element's probes against the other's tree undercounts every sphere bed
(a rained sphere column read Z = 1.2 where its centres have 4.6 neighbours within 1e-3 d) and,
less visibly, every composed particle. The engine's narrow phase is exact for spheres (centre
distance) and, for composed particles, runs both probe directions against the exact trees with
the same probes that carried the load while the pack was made, so it counts the contacts the
bed actually stands on. The probe test survives only where it measures something else: the
overlap depth (:func:`peclet.packing.analysis.geometry.probe_overlap`).

Conventions: lengths are world lengths (the pack's unit, D = element diameter for library
elements); a pair touches when the engine's signed gap (< 0 a penetration) is below ``gap``;
walls are solid trees (phi < 0 in the wall material). A periodic pack (x and z) is read with
its images: the elements' copies within one interaction reach of the box are added as bodies,
so a contact across a face counts for the element on each side, and an element touching its own
image (a box narrower than two elements) counts it once from each side, as the page does.
"""
from __future__ import annotations

import math

import numpy as np

from peclet.core.geom import SceneBuilder
from peclet.core.validation import PecletArgumentError, check_bool, check_float

from ..bed.freeze import Pack

__all__ = ["engine_coordination", "sphere_radius_of", "STABLE_CONTACTS"]

#: Fewest contacts that can hold a frictional element still in 3-D (d + 1 with friction):
#: elements below it are reported as ``under_stable``.
STABLE_CONTACTS = 4

#: The sphere leaf's kind in the flat encoding (``peclet.core.geom.leaves``).
_SPHERE_KIND = 1


def sphere_radius_of(pack: Pack):
    """The radius if the pack's element is a plain sphere centred on its home origin (the DEM's
    exact sphere then applies), else None."""
    b = SceneBuilder.decode(pack.node_ints, pack.node_reals)
    kind, _, _, params, t, _, s = b.node(pack.home_root)
    if kind != _SPHERE_KIND:
        return None
    r = float(params[0]) * float(s)
    if float(np.abs(t).max()) > 1e-12 * r:
        return None
    return r


def _periodic_images(pack: Pack, reach):
    """(positions, quaternions, owner, is_original): the pack plus its x/z images whose centres
    lie within ``reach`` of the box [0, L_x) x [0, L_z)."""
    Lx, Lz = (float(v) for v in pack.box)
    P, Q = pack.positions, pack.quaternions
    pos, quat, owner = [P], [Q], [np.arange(pack.n)]
    for i in (-1, 0, 1):
        for j in (-1, 0, 1):
            if i == 0 and j == 0:
                continue
            S = P + np.array([i * Lx, 0.0, j * Lz])
            keep = ((S[:, 0] > -reach) & (S[:, 0] < Lx + reach)
                    & (S[:, 2] > -reach) & (S[:, 2] < Lz + reach))
            pos.append(S[keep])
            quat.append(Q[keep])
            owner.append(np.flatnonzero(keep))
    owner = np.concatenate(owner)
    orig = np.zeros(len(owner), bool)
    orig[:pack.n] = True
    return np.concatenate(pos), np.concatenate(quat), owner, orig


def engine_coordination(pack: Pack, walls=(), gap=1e-3, periodic=True, sphere_radius=None):
    """Contacts per element from the DEM engine's contact detection at the pack's state.

    pack: a :class:`~peclet.packing.bed.freeze.Pack` (its shell probes are the engine's probes for a
    composed element). walls: a sequence of ``(SceneBuilder, root)`` solid trees in the world
    frame (phi < 0 inside the wall material: a floor, a column's complement); each is one
    contact partner. gap: a world length >= 0; an element pair or element-wall pair touches
    when the engine's gap between them is below it (for spheres: centre distance < d + gap).
    periodic: whether the pack is periodic in x and z over ``pack.box`` (a column or walled box
    is not). sphere_radius: the sphere's radius for a sphere pack (None: detected from the tree,
    :func:`sphere_radius_of`).

    Returns a dict: ``elem`` (N,) element partners (an image counts as a partner), ``wall``
    (N,) walls touched, ``total`` (N,), ``z_elem`` and ``z_total`` (means), ``rattlers``
    (elements with no contact at all), ``under_stable`` (fewer than :data:`STABLE_CONTACTS`),
    ``pairs`` (element-element contacts, each counted once), ``gap`` (the threshold used),
    ``min_gap`` (the smallest engine gap over touching pairs; < 0 is the deepest overlap the
    engine sees) and ``method`` ("engine: exact spheres" or "engine: narrow phase").
    """
    from peclet.dem import Simulation

    if not isinstance(pack, Pack):
        raise PecletArgumentError("pack", "a peclet.packing.bed.freeze.Pack", type(pack).__name__)
    g = check_float("gap", gap, 0.0)
    per = check_bool("periodic", periodic)
    walls = list(walls)
    for k, w in enumerate(walls):
        if not (isinstance(w, (tuple, list)) and len(w) == 2 and hasattr(w[0], "encode")):
            raise PecletArgumentError(f"walls[{k}]", "a (SceneBuilder, root) pair", w)
    r_sph = sphere_radius_of(pack) if sphere_radius is None else \
        check_float("sphere_radius", sphere_radius, 0.0, lo_open=True)
    if r_sph is None and len(pack.shell) == 0:
        raise PecletArgumentError("pack", "a pack with surface probes (pack.shell) for a "
                                  "composed element", "no shell")
    rad = r_sph if r_sph is not None else pack.bounding_radius
    reach = 2.0 * rad + 2.0 * g
    if per:
        pos, quat, owner, orig = _periodic_images(pack, reach)
    else:
        pos, quat = pack.positions, pack.quaternions
        owner, orig = np.arange(pack.n), np.ones(pack.n, bool)

    sim = Simulation(len(pos))
    if r_sph is not None:
        sid = sim.add_sphere_shape(r_sph)
    else:
        sid = sim.add_scene_shape(pack.node_ints, pack.node_reals, pack.home_root, pack.shell,
                                  pack.bounding_radius)
    for b, root in walls:
        ni, nr, _, _ = b.encode()
        sim.add_analytic_wall(ni, nr, root, False, 0.0, 0.0)
    # the detection margin must reach past the threshold (the default is 5% of the radius)
    sim.set_contact_margin_fraction(min(10.0, max(0.05, 2.0 * g / rad)))
    sim.set_positions(pos)
    sim.set_shape_ids(np.full(len(pos), sid, np.int32))
    sim.set_quaternions(quat)
    sim.set_inv_mass(np.ones(len(pos)))
    sim.set_inv_inertia(np.ones((len(pos), 3)))
    c = sim.detect_contacts()

    a, b_, gaps = c["body_a"], c["body_b"], -c["depth"]
    hit = gaps < g
    a, b_, gaps = a[hit], b_[hit], gaps[hit]
    elem = np.zeros(pack.n, np.int64)
    wall = np.zeros(pack.n, np.int64)
    # one row per touching (a, b) pair: the manifold may hold several points of one pair
    key = np.unique(np.stack([a, b_], axis=1), axis=0) if len(a) else np.zeros((0, 2), int)
    min_gap = float(gaps.min()) if len(gaps) else math.inf
    inner = cross = 0
    for i, j in key.tolist():
        if j < 0:                       # a wall, -1 - index
            if orig[i]:
                wall[owner[i]] += 1
            continue
        if orig[i]:
            elem[owner[i]] += 1
        if orig[j]:
            elem[owner[j]] += 1
        inner += orig[i] and orig[j]
        cross += orig[i] != orig[j]
    # a pair across a periodic face is seen once from each side's original: count it once
    pairs = inner + cross // 2
    total = elem + wall
    return dict(elem=elem, wall=wall, total=total, z_elem=float(elem.mean()),
                z_total=float(total.mean()), rattlers=int((total < 1).sum()),
                under_stable=int((total < STABLE_CONTACTS).sum()), pairs=int(pairs),
                gap=g, min_gap=min_gap,
                method="engine: exact spheres" if r_sph is not None else
                "engine: narrow phase")
