"""The Hertz engine's explicit substep: the candidates' exact contacts (spheres, patches,
distributed contacts), the forces and rolling torques, kick-drift, guards and commit; the
checks before a run and the listing of the last substep's contacts."""
from __future__ import annotations

import math

import numpy as np

from peclet.core.validation import PecletArgumentError

from .calibration import E_MIN, RAYLEIGH_FRACTION, damping_gamma_linear, rayleigh_time
from .candidates import Pairs, candidates
from .distributed import distributed_geometry
from .law import (ContactRows, ForceOut, Motion, PairLaw, accumulate, contact_forces,
                  contact_geometry, kick_drift, walls_of)
from .overlap import DIST_FEATURE, MODE_DISTRIBUTED
from .patch import PATCH_OK, HertzPatchError, patch_geometry, raise_patch_error
from .rolling import RollLaw, RollOut, Spin, accumulate_torques, rolling_torques

#: Default skin of the candidate list (step_hertz's skin_frac), a fraction of the smallest
#: radius: larger skins rebuild less often and carry more candidates.
DEFAULT_SKIN_FRACTION = 0.1


def distributed_rows(sim, state, cand, x, rotm, pa, pb, pp, pn, pg, status, kept):
    """Replace, in the composed rows' geometry (``pp``, ``pn``, ``pg``, ``status``, changed
    in place), every pair with a contact the patch law cannot hold (a status other than
    PATCH_OK on a touching patch, or a pair seeded MODE_DISTRIBUTED) by one distributed
    contact on the pair's first row (the others get gap +inf). Returns (rows (D,) in the
    composed arrays, overlap-law arrays: kernel gap (D,), kernel R* (D,), gamma (D,)) or None
    when no pair is distributed. Raises HertzPatchError (state restored from ``kept``) for a
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
    estar = cand.params[0][k][rep]
    dkeys = WarmStart.keys_of(Pairs(pa[rep], pb[rep], np.full(len(rep), DIST_FEATURE,
                                                                np.int64)), len(sim._walls))
    out, dst = distributed_geometry(pa[rep], pb[rep], cand.shift[k][rep], x, rotm,
                                    sim._shape_table()[1], sim._geometry(), estar,
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
    # the overlap law through the Hertz kernel: a delta_h and R*_h with the same force F and
    # stiffness S (F = 4/3 E* sqrt(R*_h) delta_h^1.5, S = 2 E* sqrt(R*_h delta_h))
    dh = np.where(touch, 1.5 * force / np.where(touch, stiff, 1.0), 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        rh = np.where(touch, (0.75 * force / (estar * np.where(touch, dh, 1.0) ** 1.5)) ** 2,
                      0.0)
    e = cand.e_n[k][rep]
    gam = np.array([damping_gamma_linear(float(v)) for v in e])
    state.dist_last = out
    return rep, np.where(touch, -dh, np.inf), rh, gam


def check(sim, state, dt):
    """Refuse what the engine cannot run: undeclared moduli, a dt above ``RAYLEIGH_FRACTION``
    of the smallest Rayleigh time (a composed body: its bounding radius, its mass spread over
    the bounding sphere), restitution below ``E_MIN``. A composed particle's unsupported
    contacts are refused when they touch (:class:`HertzPatchError`)."""
    b = sim._bodies
    mats = sim._materials
    ids = mats.body_ids if mats.body_ids is not None else np.zeros(b.n, np.int64)
    state.wall_moduli(mats.wall_ids)
    if not b.n:
        return
    e, nu = state.body_moduli(ids)
    m = b.inv_mass > 0
    if np.any(m):
        r = sim._radii()[m]
        rho = (1.0 / b.inv_mass[m]) / (4.0 / 3.0 * math.pi * r ** 3)
        tr = float(np.min(rayleigh_time(r, rho, e[m], nu[m])))
        if dt > RAYLEIGH_FRACTION * tr:
            raise PecletArgumentError("dt", f"<= {RAYLEIGH_FRACTION} x the smallest Rayleigh "
                                      f"time pi R sqrt(rho/G)/(0.1631 nu + 0.8766) = "
                                      f"{RAYLEIGH_FRACTION * tr:.6g}", dt)
    walls_e = sim._geometry().wall_e
    lows = [float(v) for v in np.concatenate([[sim._material.e_n], walls_e])
            if v < E_MIN]
    lows += [mt.e_n for mt in mats.pairs.values() if mt.e_n < E_MIN]
    if lows:
        raise PecletArgumentError("e_n", f"in [{E_MIN}, 1] for the Hertz engine (its damping "
                                  "cannot stop a contact dead)", min(lows))



def substep(sim, state, dt, skin_frac):
    """One explicit substep of ``dt`` (the facade has checked the arguments and the state and
    cleared ``state.cand`` at the start of the call). Commits the new state; raises StepError
    (state of the substep's start kept) on a non-finite or runaway state."""
    import time

    from peclet.dem import solver
    from peclet.dem.contacts import Contacts, WarmStart, lever_arms
    from peclet.dem.rigid import advance_all

    t0 = time.perf_counter()
    b = sim._bodies
    if state.n_bodies != b.n:
        state.clear_history()
    inv_mass, inv_inertia, x, q, v, w = sim._working_state()
    limits = sim._guard_limits()        # fixed within the substep
    sim._guard(x, q, v, w, limits)
    kept = state.snapshot()
    try:
        cand = candidates(sim, state, x, q, skin_frac, inv_mass)
    except HertzPatchError:
        state.restore(kept)     # a rebuild re-keys the histories
        raise
    t1 = time.perf_counter()
    nc = len(cand.a)
    point = np.empty((nc, 3))
    normal = np.empty((nc, 3))
    gap = np.empty(nc)
    geo = sim._geometry()
    estar, gstar, rstar, mstar, gam, mu = cand.params
    unew = None
    dist = None
    if cand.comp is None:
        contact_geometry(cand.a, cand.b, cand.shift, x, cand.radii, walls_of(geo), point, normal,
                         gap)
    else:
        from peclet.core.geom.transforms import quats_to_matrices
        s = cand.sph
        if len(s):
            ps, ns, gs = np.empty((len(s), 3)), np.empty((len(s), 3)), np.empty(len(s))
            contact_geometry(cand.a[s], cand.b[s], np.ascontiguousarray(cand.shift[s]), x,
                             cand.radii, walls_of(geo), ps, ns, gs)
            point[s], normal[s], gap[s] = ps, ns, gs
        k = cand.comp
        pa, pb = cand.a[k], cand.b[k]
        rotm = np.ascontiguousarray(quats_to_matrices(q))
        pp, pn, pg, pr, _, unew, status = patch_geometry(
            pa, pb, np.ascontiguousarray(cand.shift[k]), cand.mode, cand.u, cand.first, x,
            rotm, sim._shape_table()[1], geo)
        dist = distributed_rows(sim, state, cand, x, rotm, pa, pb, pp, pn, pg, status, kept)
        if np.any(status != PATCH_OK):
            state.restore(kept)
            raise_patch_error(pa, pb, status)
        point[k], normal[k], gap[k] = pp, pn, pg
        rstar = rstar.copy()
        rstar[k] = pr
    feat, keys = cand.feat, cand.keys
    gap_k = gap
    # the rolling lever: the normal law's R* (a patch's), but a distributed contact takes its
    # bounding spheres' R* (its kernel R*_h is no radius, see the module notes)
    rroll = rstar
    if dist is not None:
        # the distributed contacts: their own key and the overlap law through the kernel
        rows = cand.comp[dist[0]]
        rroll = rstar.copy()
        rroll[rows] = cand.params[2][rows]
        feat = feat.copy()
        feat[rows] = DIST_FEATURE
        keys = keys.copy()
        keys[rows] = WarmStart.keys_of(Pairs(cand.a[rows], cand.b[rows], feat[rows]),
                                       len(sim._walls))
        gap_k = gap.copy()
        gap_k[rows] = dist[1]
        rstar[rows] = dist[2]
        gam = gam.copy()
        gam[rows] = dist[3]
    c = Contacts(cand.a, cand.b, cand.shift, point, normal, gap, feat)
    xi = state.lookup(keys)
    ra, rb = lever_arms(c, x)
    nc = len(c.a)
    vw = np.zeros((nc, 3))
    if sim._wallmo.moving():
        isw = c.b < 0
        vw[isw] = sim._wallmo.surface_velocity(-1 - c.b[isw], c.point[isw])
    force = np.empty((nc, 3))
    fn = np.empty(nc)
    rows = ContactRows(c.a, c.b, np.ascontiguousarray(c.normal), np.ascontiguousarray(gap_k), ra,
                       rb)
    contact_forces(rows, PairLaw(estar, gstar, rstar, mstar, gam, mu), Motion(v, w, vw), dt,
                   ForceOut(xi, force, fn))
    fb = np.zeros((b.n, 3)) if sim._ext_force is None else sim._ext_force.copy()
    tb = np.zeros((b.n, 3)) if sim._ext_torque is None else sim._ext_torque.copy()
    accumulate(c.a, c.b, ra, rb, force, b.n, fb, tb)
    mr = None
    if cand.mu_r is not None:
        mr = state.lookup_rolling(keys)
        wom = np.zeros((nc, 3))
        if sim._wallmo.moving():
            isw = c.b < 0
            wom[isw] = sim._wallmo.omega[-1 - c.b[isw]]
        troll = np.empty((nc, 3))
        rolling_torques(rows, RollLaw(estar, rstar, np.ascontiguousarray(rroll), cand.mu_r, fn),
                        Spin(w, wom, inv_mass, np.ascontiguousarray(inv_inertia.mean(axis=1))),
                        dt, RollOut(mr, troll))
        accumulate_torques(c.a, c.b, troll, tb)
    wii = solver.world_inv_inertias(q, inv_inertia)
    with np.errstate(over="ignore", invalid="ignore"):   # the guard reports it
        kick_drift(x, v, w, fb, tb, inv_mass, np.ascontiguousarray(wii), sim._gravity, dt)
    sim._guard(x, q, v, w, limits)
    advance_all(q, w, inv_inertia, dt)
    sim._domain.wrap(x)
    sim._guard(x, q, v, w, limits)
    # commit
    b.pos, b.quat, b.vel, b.omega = x, q, v, w
    touching = c.gap < 0.0
    state.store(keys, xi, touching, b.n, mr)
    if unew is not None:
        state.cand = cand._replace(u=unew)
    state.last = (c, force, fn, xi, troll if mr is not None else None)
    sim._wallmo.advance(dt)
    sim._num_contacts = int(np.count_nonzero(touching))
    sim._step_count += 1
    sim._time += dt
    t2 = time.perf_counter()
    sim.timings["solver"] += t2 - t1
    sim.timings["total"] += t2 - t0


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

