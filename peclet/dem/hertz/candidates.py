"""The Hertz engine's candidate contacts: the Verlet list within a skin, the pair parameters of
each candidate, and a composed pair's patches with the histories carried over to their new keys
at a rebuild (docstring of :mod:`peclet.dem.hertz.patch`, "Patches are seeded")."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .fields import probe_counts, shapes_of
from .overlap import DIST_FEATURE, MODE_DISTRIBUTED
from .patch import FAILED_FEATURE, MAX_PATCHES
from .seeds import seed_patches


def pair_basics(world, c, mass_inv):
    """What every force law asks of a candidate pair (each (nc,)): R* (``1/R* = 1/R_a +
    1/R_b`` of the bounding radii; a wall counts as flat, R* = R_a), m* (``1/m* = 1/m_a +
    1/m_b``; a wall or a body of inverse mass 0 adds nothing; 0 when both are fixed), the
    pair material's restitution e_n and friction mu."""
    from peclet.dem.materials import per_contact
    mats = world.materials
    radii = world.radii()
    isw = c.b < 0
    bi = np.where(isw, 0, c.b)
    ra = radii[c.a]
    rb = radii[bi]
    rstar = np.where(isw, ra, ra * rb / (ra + rb))
    im = mass_inv[c.a] + np.where(isw, 0.0, mass_inv[bi])
    with np.errstate(divide="ignore"):
        mstar = np.where(im > 0.0, 1.0 / np.where(im > 0.0, im, 1.0), 0.0)
    if mats.active():
        e_c, _, mu_c = mats.per_contact(c.a, c.b, world.default_material, world.geometry())
    else:
        e_c, _, mu_c = per_contact(c.b, world.default_material, world.geometry())
    return rstar, mstar, e_c, np.ascontiguousarray(mu_c, dtype=np.float64)


def pair_rolling(world, c, state):
    """mu_r per contact (nc,) from :meth:`HertzState.set_rolling` (a pair of material ids, else
    the setting for every pair, else 0; a wall without a material id takes the setting for
    every pair), or None when no contact has rolling resistance (the step then does not run
    the rolling kernel at all: the arithmetic of a run without it)."""
    if not state.rolling_active():
        return None
    mats = world.materials
    nc = len(c.a)
    ida = mats.body_ids[c.a] if mats.body_ids is not None else np.zeros(nc, np.int64)
    isw = c.b < 0
    bb = np.where(isw, 0, c.b)
    idb = mats.body_ids[bb] if mats.body_ids is not None else np.zeros(nc, np.int64)
    if len(mats.wall_ids):
        idb = np.where(isw, mats.wall_ids[np.where(isw, -1 - c.b, 0)], idb)
    else:
        idb = np.where(isw, -1, idb)
    default = state.rolling.get(None, 0.0)
    out = np.full(nc, default)
    pairs = [(k, v) for k, v in state.rolling.items() if k is not None]
    if pairs:
        lo = np.minimum(ida, idb)
        hi = np.maximum(ida, idb)
        own_wall = idb < 0
        for (i, j), v in pairs:
            out[(lo == i) & (hi == j) & ~own_wall] = v
    if not np.any(out > 0.0):
        return None
    return out


def pair_restitution(world, c):
    """e_n per contact (the pair material's, as :func:`pair_basics` gives it)."""
    from peclet.dem.materials import per_contact
    mats = world.materials
    if mats.active():
        e_c, _, _ = mats.per_contact(c.a, c.b, world.default_material, world.geometry())
    else:
        e_c, _, _ = per_contact(c.b, world.default_material, world.geometry())
    return np.asarray(e_c, np.float64)



class Candidates(NamedTuple):
    """The contacts that can touch until the next rebuild: ``a``, ``b``, ``shift``, ``feat``
    and ``keys`` (task order: the detection's rows, a composed pair's rows replaced by its
    patches), ``x_ref`` / ``q_ref`` the positions and quaternions they were found at, ``skin``
    the detection margin, ``radii`` (N,), and ``params`` the pair parameters (E*, G*, R*, m*,
    gamma, mu) per candidate. With composed particles: ``comp`` the rows that are patches and
    ``sph`` the others, and per patch ``mode`` (0 a patch tracked by ``u`` in a's home frame; 1
    / 2 a watched probe of a / of b, ``u`` in that body's frame) and ``first`` (its pair's
    first patch); ``comp`` None otherwise. ``mu_r`` the rolling friction per candidate, None
    when no candidate has any."""
    a: np.ndarray
    b: np.ndarray
    shift: np.ndarray
    feat: np.ndarray
    keys: np.ndarray
    x_ref: np.ndarray
    skin: float
    radii: np.ndarray
    params: tuple
    comp: np.ndarray = None
    sph: np.ndarray = None
    mode: np.ndarray = None
    u: np.ndarray = None
    first: np.ndarray = None
    q_ref: np.ndarray = None
    e_n: np.ndarray = None
    mu_r: np.ndarray = None


class Pairs(NamedTuple):
    """Contacts as :meth:`peclet.dem.contacts.WarmStart.keys_of` reads them."""
    a: np.ndarray
    b: np.ndarray
    feat: np.ndarray



def _probe_spacing(state, geo):
    """Per shape: the largest distance from a probe to its nearest other probe (0 for a
    sphere), cached per geometry."""
    kept = state.spacing
    if kept is not None and kept[0] is geo:
        return kept[1]
    from scipy.spatial import cKDTree
    nps = np.diff(np.append(geo.shape_p0, len(geo.probes)))
    out = np.zeros(len(geo.shape_kind))
    for s in range(len(out)):
        if nps[s] >= 2:
            p = geo.probes[geo.shape_p0[s]:geo.shape_p0[s] + nps[s]]
            d, _ = cKDTree(p).query(p, k=2)
            out[s] = float(d[:, 1].max())
    state.spacing = (geo, out)
    return out


def _home(x, R, p):
    """World points p (n, 3) in the frame of the body at x with rotation R (home -> world)."""
    return (p - x) @ R


def _composed_candidates(world, state, c, x, rot, geo, shape_of, skin, n_walls):
    """The candidate rows with every composed pair (a composed body on either side) replaced
    by its patches (:func:`seed_patches`), their feature ids (the probe nearest the patch
    point: of a, or of b offset by FEATURE_DIR when a is a sphere; FAILED_FEATURE added for a
    watched probe) and keys; the stored tangential histories of the composed pairs are carried
    over to the new keys, each old patch to the nearest new patch of its pair within twice the
    probe spacing plus the skin (both in the same body frame). Returns None when no pair is
    composed, else (a, b, shift, feat, keys, comp, sph, mode, u, first)."""
    from peclet.dem.contacts import _FEATURE_BITS, WarmStart
    from peclet.dem.narrowphase import FEATURE_DIR
    from peclet.dem.shapes import SCENE
    kind = geo.shape_kind[shape_of]
    bb = np.where(c.b >= 0, c.b, 0)
    comp_row = (kind[c.a] == SCENE) | ((c.b >= 0) & (kind[bb] == SCENE))
    if not comp_row.any():
        return None
    n = len(c.a)
    new = np.ones(n, bool)
    new[1:] = ((c.a[1:] != c.a[:-1]) | (c.b[1:] != c.b[:-1])
               | np.any(c.shift[1:] != c.shift[:-1], axis=1))
    g0 = np.flatnonzero(new)
    g1 = np.append(g0[1:], n)
    gcomp = comp_row[g0]
    cg = np.flatnonzero(gcomp)
    rows = np.concatenate([np.arange(g0[k], g1[k]) for k in cg])
    det_off = np.concatenate([[0], np.cumsum(g1[cg] - g0[cg])]).astype(np.int64)
    nps = probe_counts(geo)
    cnt, mode, u, probe = seed_patches(
        c.a[g0[cg]], c.b[g0[cg]], np.ascontiguousarray(c.shift[g0[cg]]), det_off,
        np.ascontiguousarray(c.point[rows]), np.ascontiguousarray(c.gap[rows]), float(skin),
        shapes_of(x, rot, shape_of, geo))
    too_many = np.flatnonzero(cnt > MAX_PATCHES)
    if len(too_many):
        # more patches than one pair may hold: the pair's contact is distributed
        cnt[too_many] = 1
        mode[too_many, 0] = MODE_DISTRIBUTED
        u[too_many, 0] = 0.0
        probe[too_many, 0] = -1
    spacing = _probe_spacing(state, geo)
    # the Mindlin and rolling histories travel together (columns 0-2 and 3-5)
    old_keys, old_xi = state.keys, np.hstack([state.xi, state.mr])
    mask = (1 << _FEATURE_BITS) - 1
    out_a, out_b, out_s, out_f, out_c = [], [], [], [], []
    p_mode, p_u, p_first = [], [], []
    carried_keys, carried_xi, dropped_pairs = [], [], []
    npatch = 0
    ci = 0
    for k in range(len(g0)):
        if not gcomp[k]:
            sl = slice(g0[k], g1[k])
            out_a.append(c.a[sl])
            out_b.append(c.b[sl])
            out_s.append(c.shift[sl])
            out_f.append(c.feat[sl])
            out_c.append(np.zeros(g1[k] - g0[k], bool))
            continue
        m = int(cnt[ci])
        ia, ib, sh = int(c.a[g0[k]]), int(c.b[g0[k]]), c.shift[g0[k]]
        md, uu, pr = mode[ci, :m], u[ci, :m], probe[ci, :m]
        ci += 1
        # the frame features live in: a's when a is composed, else b's (offset FEATURE_DIR)
        on_a = kind[ia] == SCENE
        fb = ia if on_a else ib
        fs = shape_of[fb]
        fx = x[fb] + (0.0 if on_a else sh)
        pts = geo.probes[geo.shape_p0[fs]:geo.shape_p0[fs] + nps[fs]]
        off = 0 if on_a else FEATURE_DIR
        # patch points in the feature frame
        world = x[ia] + uu @ rot[ia].T
        loc = _home(fx, rot[fb], world)
        feat = np.empty(m, np.int64)
        taken = set()
        for j in range(m):
            if md[j] == MODE_DISTRIBUTED:
                feat[j] = DIST_FEATURE
                continue
            if md[j] != 0:
                feat[j] = FAILED_FEATURE + (FEATURE_DIR if md[j] == 2 else 0) + int(pr[j])
                continue
            order = np.argsort(((pts - loc[j]) ** 2).sum(axis=1), kind="stable")
            f = next(int(o) for o in order if int(o) not in taken)
            taken.add(f)
            feat[j] = off + f
        pair_key = WarmStart.keys_of(Pairs(np.array([ia]), np.array([ib]),
                                            np.zeros(1, np.int64)), n_walls)[0]
        dropped_pairs.append(pair_key >> _FEATURE_BITS)
        new_keys = WarmStart.keys_of(Pairs(np.full(m, ia), np.full(m, ib), feat), n_walls)
        # carry the histories: old patch keys of this pair, by distance in the feature frame
        sel = np.flatnonzero(((old_keys >> _FEATURE_BITS) == (pair_key >> _FEATURE_BITS))
                             & ((old_keys & mask) < FAILED_FEATURE))
        live = np.flatnonzero(md == 0)
        # a distributed contact's history keeps its key (the pair and DIST_FEATURE)
        dk = WarmStart.keys_of(Pairs(np.array([ia]), np.array([ib]),
                                      np.array([DIST_FEATURE])), n_walls)[0]
        hit = np.flatnonzero(old_keys == dk)
        if len(hit):
            carried_keys.append(dk)
            carried_xi.append(old_xi[hit[0]])
        if len(sel) and len(live):
            of = (old_keys[sel] & mask) - off
            ok = (of >= 0) & (of < len(pts))
            sel, of = sel[ok], of[ok]
            d = np.sqrt(((loc[live][:, None, :] - pts[of][None, :, :]) ** 2).sum(axis=2))
            lim = 2.0 * spacing[fs] + skin
            cand_pairs = [(d[i, j], i, j) for i in range(len(live)) for j in range(len(sel))
                          if d[i, j] <= lim]
            used_new, used_old = set(), set()
            for _, i, j in sorted(cand_pairs):
                if i in used_new or j in used_old:
                    continue
                used_new.add(i)
                used_old.add(j)
                carried_keys.append(new_keys[live[i]])
                carried_xi.append(old_xi[sel[j]])
        out_a.append(np.full(m, ia, np.int64))
        out_b.append(np.full(m, ib, np.int64))
        out_s.append(np.tile(sh, (m, 1)))
        out_f.append(feat)
        out_c.append(np.ones(m, bool))
        p_mode.append(md)
        p_u.append(uu)
        p_first.append(np.full(m, npatch, np.int64))
        npatch += m
    a = np.concatenate(out_a).astype(np.int64)
    b = np.concatenate(out_b).astype(np.int64)
    shift = np.ascontiguousarray(np.concatenate(out_s).reshape(-1, 3), dtype=np.float64)
    feat = np.concatenate(out_f).astype(np.int64)
    isc = np.concatenate(out_c)
    keys = WarmStart.keys_of(Pairs(a, b, feat), n_walls)
    # the stored histories: the composed pairs' entries replaced by the carried ones
    keep = ~np.isin(old_keys >> _FEATURE_BITS, np.array(dropped_pairs, np.int64))
    nk = np.concatenate([old_keys[keep], np.array(carried_keys, np.int64)])
    nx = np.concatenate([old_xi[keep], np.array(carried_xi, np.float64).reshape(-1, 6)])
    o = np.argsort(nk, kind="stable")
    nx = nx[o]
    state.keys = nk[o]
    state.xi = np.ascontiguousarray(nx[:, :3])
    state.mr = np.ascontiguousarray(nx[:, 3:])
    return (a, b, shift, feat, keys, np.flatnonzero(isc), np.flatnonzero(~isc),
            np.concatenate(p_mode).astype(np.int64),
            np.ascontiguousarray(np.concatenate(p_u).reshape(-1, 3)),
            np.concatenate(p_first).astype(np.int64))


def _turn_angles(q, q_ref):
    """Per body: the angle (rad) of the rotation from quaternion q_ref to q."""
    chord = np.minimum(np.sqrt(((q - q_ref) ** 2).sum(axis=1)),
                       np.sqrt(((q + q_ref) ** 2).sum(axis=1)))
    return 4.0 * np.arcsin(np.minimum(0.5 * chord, 1.0))


def candidates(world, state, law, x, q, skin_frac, inv_mass):
    """The candidate list for positions ``x``: kept from the last substep while no pair can
    have closed the skin (twice the largest displacement since it was built below the skin,
    every wall static and 1-Lipschitz, no periodic axis; with composed particles, four times
    the largest surface displacement |dx| + R_bound x turn angle, the other half of the skin
    covering the probes' spacing), else rebuilt by the engine's detection with margin =
    ``skin_frac`` x the smallest radius; the pair parameters are the force ``law``'s. Every contact that touches is in the list either way,
    and its geometry is recomputed exactly at every substep (:func:`contact_geometry`,
    :func:`patch_geometry`); for spheres the schedule of rebuilds never changes a bit."""
    from peclet.core.geom.transforms import quats_to_matrices
    from peclet.dem.contacts import WarmStart
    from peclet.dem.shapes import SCENE
    cand = state.cand
    geo = world.geometry()
    shape_of = world.shape_table()[1]
    scene = geo.shape_kind[shape_of] == SCENE
    if cand is not None and len(cand.x_ref) == len(x) and not world.domain.periodic.any() \
            and not world.wall_motion.moving() and bool(np.all(geo.wall_lip)):
        d = np.sqrt(((x - cand.x_ref) ** 2).sum(axis=1))
        if cand.q_ref is None:
            if 2.0 * float(d.max(initial=0.0)) < cand.skin:
                return cand
        else:
            d = d + np.where(scene, cand.radii * _turn_angles(q, cand.q_ref), 0.0)
            if 4.0 * float(d.max(initial=0.0)) < cand.skin:
                return cand
    radii = world.radii()
    skin = skin_frac * float(radii.min())
    rot = np.ascontiguousarray(quats_to_matrices(q))
    c = world.detect(x, rot, skin)
    n_walls = len(world.walls)
    comp = _composed_candidates(world, state, c, x, rot, geo, shape_of, skin, n_walls) \
        if scene.any() else None
    if comp is None:
        cand = Candidates(c.a, c.b, np.ascontiguousarray(c.shift), c.feat,
                          WarmStart.keys_of(c, n_walls), x.copy(), skin, radii,
                          law.pair_parameters(world, c, inv_mass),
                          q_ref=q.copy() if scene.any() else None,
                          mu_r=pair_rolling(world, c, state) if law.rolling else None)
    else:
        a, b, shift, feat, keys, crow, srow, mode, u, first = comp
        cand = Candidates(a, b, shift, feat, keys, x.copy(), skin, radii,
                          law.pair_parameters(world, Pairs(a, b, feat), inv_mass),
                          crow, srow, mode, u, first, q.copy(),
                          pair_restitution(world, Pairs(a, b, feat)),
                          pair_rolling(world, Pairs(a, b, feat), state) if law.rolling else None)
    state.cand = cand
    return cand


