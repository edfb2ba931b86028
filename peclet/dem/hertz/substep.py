"""The Hertz engine's explicit substep: the candidates' exact contacts (spheres, patches,
distributed contacts), the forces and rolling torques, kick-drift, guards and commit; the
checks before a run and the listing of the last substep's contacts."""
from __future__ import annotations

import numpy as np

from typing import NamedTuple

from .candidates import Pairs, candidates
from .distributed import distributed_geometry
from .law import (ContactRows, ForceOut, Motion, accumulate, contact_geometry, kick_drift,
                  walls_of)
from .overlap import DIST_FEATURE, MODE_DISTRIBUTED
from .patch import PATCH_OK, HertzPatchError, patch_geometry, raise_patch_error
from .rolling import RollOut, Spin, accumulate_torques, rolling_torques

#: Default skin of the candidate list (step_hertz's skin_frac), a fraction of the smallest
#: radius: larger skins rebuild less often and carry more candidates.
DEFAULT_SKIN_FRACTION = 0.1


class Distributed(NamedTuple):
    """The distributed contacts of a substep: ``rep`` their rows in the composed arrays and,
    per contact, the overlap ``depth``, and the overlap law's ``force`` and ``stiffness``
    (:func:`~peclet.dem.hertz.distributed.distributed_geometry`), ``touch`` (force > 0),
    ``e_n`` the pair's restitution and ``modulus`` the E* it was sampled with."""
    rep: np.ndarray
    depth: np.ndarray
    force: np.ndarray
    stiffness: np.ndarray
    touch: np.ndarray
    e_n: np.ndarray
    modulus: np.ndarray


def distributed_rows(world, state, cand, modulus, x, rotm, pa, pb, pp, pn, pg, status, kept):
    """Replace, in the composed rows' geometry (``pp``, ``pn``, ``pg``, ``status``, changed
    in place), every pair with a contact the patch law cannot hold (a status other than
    PATCH_OK on a touching patch, or a pair seeded MODE_DISTRIBUTED) by one distributed
    contact on the pair's first row (the others get gap +inf), its region sampled with the
    law's effective ``modulus`` per candidate. Returns a :class:`Distributed` or None when no
    pair is distributed. Raises HertzPatchError (state restored from ``kept``) for a
    distributed contact it refuses."""
    from peclet.dem.contacts import WarmStart
    dist = (status != PATCH_OK) | (cand.mode == MODE_DISTRIBUTED)
    # a pair with a failed seed (a watched probe) and no touching Hertz patch is sampled too:
    # a line or edge contact can lie between the probes
    watched = (cand.mode == 1) | (cand.mode == 2)
    if np.any(watched):
        hertz_touch = np.unique(cand.first[(cand.mode == 0) & (pg < 0.0)])
        dist |= watched & ~np.isin(cand.first, hertz_touch)
    if not np.any(dist):
        return None
    rep = np.unique(cand.first[dist])
    in_d = np.isin(cand.first, rep)
    k = cand.comp
    estar = modulus[k][rep]
    dkeys = WarmStart.keys_of(Pairs(pa[rep], pb[rep], np.full(len(rep), DIST_FEATURE,
                                                                np.int64)), len(world.walls))
    out, dst = distributed_geometry(pa[rep], pb[rep], cand.shift[k][rep], x, rotm,
                                    world.shape_table()[1], world.geometry(), estar,
                                    np.isin(dkeys, state.keys))
    if np.any(dst != PATCH_OK):
        state.restore(kept)
        raise_patch_error(pa[rep], pb[rep], dst)
    pg[in_d] = np.inf
    status[in_d] = PATCH_OK
    force, stiff = out[:, 7], out[:, 8]
    touch = force > 0.0
    pg[rep] = np.where(touch, -out[:, 6], np.inf)
    pp[rep] = out[:, :3]
    pn[rep] = out[:, 3:6]
    state.dist_last = out
    return Distributed(rep, out[:, 6], force, stiff, touch, cand.e_n[k][rep], estar)


def _sphere_rows(cand, x, geo, point, normal, gap, rows=None):
    # the exact contacts of candidate rows between spheres (and spheres and walls)
    if rows is None:
        contact_geometry(cand.a, cand.b, cand.shift, x, cand.radii, walls_of(geo), point,
                         normal, gap)
        return
    ps, ns, gs = np.empty((len(rows), 3)), np.empty((len(rows), 3)), np.empty(len(rows))
    contact_geometry(cand.a[rows], cand.b[rows], np.ascontiguousarray(cand.shift[rows]), x,
                     cand.radii, walls_of(geo), ps, ns, gs)
    point[rows], normal[rows], gap[rows] = ps, ns, gs


def substep(world, state, law, dt, skin_frac):
    """One explicit substep of ``dt`` under the force ``law`` (:class:`peclet.dem.engine.
    ForceLaw`), ``state`` the engine's history (a :class:`HertzState`); the engine has checked
    the arguments and the state and cleared ``state.cand`` at the start of the call. Commits
    the new state (:meth:`World.commit`); raises StepError (state of the substep's start
    kept) on a non-finite or runaway state."""
    import time

    from peclet.dem import solver
    from peclet.dem.contacts import Contacts, WarmStart, lever_arms
    from peclet.dem.rigid import advance_all

    t0 = time.perf_counter()
    b = world.bodies
    if state.n_bodies != b.n:
        state.clear_history()
    inv_mass, inv_inertia, x, q, v, w = world.working_state()
    limits = world.guard_limits()        # fixed within the substep
    world.guard(x, q, v, w, limits)
    kept = state.snapshot()
    try:
        cand = candidates(world, state, law, x, q, skin_frac, inv_mass)
    except HertzPatchError:
        state.restore(kept)     # a rebuild re-keys the histories
        raise
    t1 = time.perf_counter()
    nc = len(cand.a)
    point = np.empty((nc, 3))
    normal = np.empty((nc, 3))
    gap = np.empty(nc)
    geo = world.geometry()
    params = cand.params
    unew = None
    dist = None
    if cand.comp is None:
        _sphere_rows(cand, x, geo, point, normal, gap)
    else:
        from peclet.core.geom.transforms import quats_to_matrices
        if len(cand.sph):
            _sphere_rows(cand, x, geo, point, normal, gap, cand.sph)
        k = cand.comp
        pa, pb = cand.a[k], cand.b[k]
        rotm = np.ascontiguousarray(quats_to_matrices(q))
        pp, pn, pg, pr, _, unew, status = patch_geometry(
            pa, pb, np.ascontiguousarray(cand.shift[k]), cand.mode, cand.u, cand.first, x,
            rotm, world.shape_table()[1], geo)
        dist = distributed_rows(world, state, cand, law.modulus(params), x, rotm, pa, pb, pp,
                                pn, pg, status, kept)
        if np.any(status != PATCH_OK):
            state.restore(kept)
            raise_patch_error(pa, pb, status)
        point[k], normal[k], gap[k] = pp, pn, pg
        params = law.with_patches(params, k, pr)
    feat, keys = cand.feat, cand.keys
    gap_k = gap
    if dist is not None:
        # the distributed contacts: their own key, and the law's parameters and kernel gap
        rows = cand.comp[dist.rep]
        feat = feat.copy()
        feat[rows] = DIST_FEATURE
        keys = keys.copy()
        keys[rows] = WarmStart.keys_of(Pairs(cand.a[rows], cand.b[rows], feat[rows]),
                                       len(world.walls))
        gap_k = gap.copy()
        params, gap_k[rows] = law.with_distributed(params, cand.params, rows, dist)
    c = Contacts(cand.a, cand.b, cand.shift, point, normal, gap, feat)
    xi = state.lookup(keys)
    ra, rb = lever_arms(c, x)
    nc = len(c.a)
    vw = np.zeros((nc, 3))
    if world.wall_motion.moving():
        isw = c.b < 0
        vw[isw] = world.wall_motion.surface_velocity(-1 - c.b[isw], c.point[isw])
    force = np.empty((nc, 3))
    fn = np.empty(nc)
    rows = ContactRows(c.a, c.b, np.ascontiguousarray(c.normal), np.ascontiguousarray(gap_k), ra,
                       rb)
    law.forces(rows, params, Motion(v, w, vw), dt, ForceOut(xi, force, fn))
    fb = np.zeros((b.n, 3)) if world.ext_force is None else world.ext_force.copy()
    tb = np.zeros((b.n, 3)) if world.ext_torque is None else world.ext_torque.copy()
    accumulate(c.a, c.b, ra, rb, force, b.n, fb, tb)
    mr = None
    if cand.mu_r is not None:
        mr = state.lookup_rolling(keys)
        wom = np.zeros((nc, 3))
        if world.wall_motion.moving():
            isw = c.b < 0
            wom[isw] = world.wall_motion.omega[-1 - c.b[isw]]
        troll = np.empty((nc, 3))
        rolling_torques(rows, law.rolling_law(params, cand.mu_r, fn),
                        Spin(w, wom, inv_mass, np.ascontiguousarray(inv_inertia.mean(axis=1))),
                        dt, RollOut(mr, troll))
        accumulate_torques(c.a, c.b, troll, tb)
    wii = solver.world_inv_inertias(q, inv_inertia)
    with np.errstate(over="ignore", invalid="ignore"):   # the guard reports it
        kick_drift(x, v, w, fb, tb, inv_mass, np.ascontiguousarray(wii), world.gravity, dt)
    world.guard(x, q, v, w, limits)
    advance_all(q, w, inv_inertia, dt)
    world.domain.wrap(x)
    world.guard(x, q, v, w, limits)
    touching = c.gap < 0.0
    state.store(keys, xi, touching, b.n, mr)
    if unew is not None:
        state.cand = cand._replace(u=unew)
    state.last = (c, force, fn, xi, troll if mr is not None else None)
    t2 = time.perf_counter()
    world.commit((x, q, v, w), dt, np.count_nonzero(touching), (t2 - t1, t2 - t0))


def last_listing(state):
    """The last substep's touching contacts, sorted by (body_a, body_b, feature): ``body_a``,
    ``body_b`` (a wall is -1 - index), ``point`` (n, 3), ``normal`` (n, 3) from b to a,
    ``depth`` (n,) overlap > 0, ``force`` (n, 3) on body a (world; b gets the opposite),
    ``normal_force`` (n,) >= 0, ``tangential_displacement`` (n, 3) the Mindlin history,
    ``rolling_torque`` (n, 3) the rolling resistance torque on body a (b gets the opposite, a
    wall nothing; zero without rolling friction)."""
    if state.last is None:
        z = np.zeros(0)
        return {"body_a": np.zeros(0, np.int64), "body_b": np.zeros(0, np.int64),
                "point": np.zeros((0, 3)), "normal": np.zeros((0, 3)), "depth": z,
                "force": np.zeros((0, 3)), "normal_force": z,
                "tangential_displacement": np.zeros((0, 3)), "rolling_torque": np.zeros((0, 3))}
    c, force, fn, xi, troll = state.last
    m = c.gap < 0.0
    o = np.lexsort((c.feat[m], c.b[m], c.a[m]))
    if troll is None:
        troll = np.zeros((len(c.a), 3))
    return {"body_a": c.a[m][o], "body_b": c.b[m][o], "point": c.point[m][o],
            "normal": c.normal[m][o], "depth": -c.gap[m][o], "force": force[m][o],
            "normal_force": fn[m][o], "tangential_displacement": xi[m][o],
            "rolling_torque": troll[m][o]}

