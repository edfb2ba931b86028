"""Saving and loading a :class:`peclet.dem.Simulation` (.npz, no pickles).

A save holds the whole simulation: bodies, shapes, walls, parameters, clock and the warm-start
cache, so that a loaded simulation resumes a run bit for bit. :func:`load` trusts nothing in the
file: every key, dtype, row count and range is checked (through the same validated setters a
user calls), and anything that is not a consistent peclet save -- a missing or unknown key, a
count that disagrees with the rows, restitution 7, a negative inverse mass, a zero quaternion,
pickled content, a file that is not an .npz -- raises ONE :class:`PecletArgumentError`
naming ``path`` and saying what is wrong.
"""
from __future__ import annotations

import os

import numpy as np

from peclet.core.files import atomic_write, check_writable_path
from peclet.core.geom.transforms import quat_norm
from peclet.core.validation import PecletArgumentError, check_int
from peclet.dem.shapes import SceneShape

FORMAT_VERSION = 3
#: Version 1 saves (before moving walls, per-pair materials and external loads) still load.
_V2_KEYS = ("wall_motion", "material_ids", "wall_material_ids", "pair_materials",
            "ext_force", "ext_torque")
#: Version 3 adds the bodies' scales (version 2 saves load with every scale 1).
_V3_KEYS = ("scales",)
#: Present (all four) only in a save of a simulation that used the Hertz engine
#: (peclet/dem/hertz.py): its moduli per material id and the tangential history, so a Hertz
#: run resumes bitwise. A save without them loads as before.
_HERTZ_KEYS = ("hertz_moduli", "hertz_keys", "hertz_xi", "hertz_n")
#: Present (both, with the Hertz keys) only in a save of a simulation whose rolling friction
#: was set (Simulation.set_rolling_friction): the settings (rows material_a, material_b, mu_r;
#: -1, -1 for every pair) and the rolling spring torque per history key.
_ROLLING_KEYS = ("hertz_rolling", "hertz_mr")
#: Present (all three) only in a save of a simulation with sleeping on (peclet/dem/sleep.py):
#: its threshold and each body's flag and count, so that a sleeping run resumes bitwise.
_SLEEP_KEYS = ("sleep_params", "sleep_asleep", "sleep_count")
#: Present (all three, plus the law's history as ``law_h_<name>``) only in a save of a
#: simulation whose contact law (Simulation.set_contact_law) is not the impulse default: the
#: law's registry name, its parameters' names and values (peclet.dem.engine).
_LAW_KEYS = ("law_name", "law_param_names", "law_params")
_LAW_HISTORY = "law_h_"
_WHAT = "a peclet Simulation save"
#: A saved quaternion is unit to a few ulps; one farther than this was not written by save.
_UNIT_TOL = 1e-12

_BASE_KEYS = ("version", "n", "pos", "vel", "omega", "quat", "shape", "inv_mass",
              "inv_inertia", "material", "iters", "gravity", "periodic", "domain", "dt",
              "step_count", "time", "margin_fraction", "ws_keys", "ws_lam", "slot_capacity",
              "capacity_hint", "n_shapes", "n_walls")


def to_arrays(sim):
    """The save's arrays of ``sim`` (a dict of numpy arrays, no objects)."""
    b, dom, mat = sim.world.bodies, sim.world.domain, sim.world.default_material
    d = {
        "version": np.int64(FORMAT_VERSION), "n": np.int64(b.n), "pos": b.pos, "vel": b.vel,
        "omega": b.omega, "quat": b.quat, "shape": b.shape, "inv_mass": b.inv_mass,
        "inv_inertia": b.inv_inertia, "material": np.array([mat.e_n, mat.e_t, mat.mu]),
        "iters": np.array([sim.world.pos_iters, sim.world.vel_iters], np.int64),
        "gravity": sim.world.gravity, "periodic": dom.periodic,
        "domain": np.stack([dom.lo, dom.hi]) if dom.lo is not None else np.zeros((0, 3)),
        "dt": np.array([] if sim.world.dt is None else [sim.world.dt]),
        "step_count": np.int64(sim.world.step_count), "time": np.float64(sim.world.time),
        "margin_fraction": np.float64(sim.world.margin_fraction),
        "ws_keys": sim.world.warm.keys, "ws_lam": sim.world.warm.lam,
        "slot_capacity": np.int64(sim.world.detector.slot_capacity),
        "capacity_hint": np.int64(sim.world.capacity_hint),
        "n_shapes": np.int64(len(sim.world.shapes)), "n_walls": np.int64(len(sim.world.walls)),
    }
    ids, wids, pairs = sim.world.materials.arrays(b.n)
    d.update({"wall_motion": sim.world.wall_motion.arrays(), "material_ids": ids,
              "wall_material_ids": wids, "pair_materials": pairs,
              "ext_force": sim.world.ext_force if sim.world.ext_force is not None else np.zeros((0, 3)),
              "ext_torque": sim.world.ext_torque if sim.world.ext_torque is not None
              else np.zeros((0, 3)),
              "scales": sim.world.scales.values if sim.world.scales.values is not None
              else np.zeros(0)})
    hz = sim.world.hertz
    if hz.moduli or len(hz.keys) or hz.rolling:
        d.update(zip(_HERTZ_KEYS, hz.arrays()))
    if hz.rolling:
        d.update(zip(_ROLLING_KEYS, hz.rolling_arrays()))
    if sim.world.sleep.on:
        d.update(zip(_SLEEP_KEYS, sim.world.sleep.arrays()))
    eng = sim.contact_engine
    if eng.name != "impulse":
        names = sorted(eng.parameters)
        d.update({"law_name": np.array(eng.name), "law_param_names": np.array(names, dtype=str),
                  "law_params": np.array([float(eng.parameters[k]) for k in names])})
        d.update({_LAW_HISTORY + k: v for k, v in eng.history(sim.world).items()})
    for i, s in enumerate(sim.world.shapes):
        scene = isinstance(s, SceneShape)
        d[f"shape{i}_kind"] = np.int64(1 if scene else 0)
        d[f"shape{i}_radius"] = np.float64(s.radius)
        if scene:
            d[f"shape{i}_ni"] = s.node_ints
            d[f"shape{i}_nr"] = s.node_reals
            d[f"shape{i}_root"] = np.int64(s.root)
            d[f"shape{i}_shell"] = s.shell
    for i, w in enumerate(sim.world.walls):
        d[f"wall{i}_ni"] = w.node_ints
        d[f"wall{i}_nr"] = w.node_reals
        d[f"wall{i}_root"] = np.int64(w.root)
        d[f"wall{i}_prm"] = np.array([float(w.invert), w.e, w.mu])
    return d


def save(sim, path):
    """Write ``sim`` to ``path`` (.npz) atomically (a temporary file renamed over the target)."""
    check_writable_path(path, "path")
    d = to_arrays(sim)

    def write(tmp):
        with open(tmp, "wb") as fh:          # a file object: np.savez would append ".npz"
            np.savez(fh, **d)
    atomic_write(path, write)


def _read(path):
    # every member of the .npz as an array; pickles and non-npz files are refused
    try:
        p = os.fspath(path)
    except TypeError:
        raise PecletArgumentError("path", "a file path", path) from None
    if not os.path.isfile(p):
        raise PecletArgumentError("path", "an existing file (" + _WHAT + ")", p)
    try:
        z = np.load(p, allow_pickle=False)
    except Exception as e:                      # not .npy/.npz, pickled, truncated, ...
        raise PecletArgumentError("path", _WHAT, p, f"unreadable as .npz: {e}") from None
    if not isinstance(z, np.lib.npyio.NpzFile):
        raise PecletArgumentError("path", _WHAT, p, "a single .npy array, not an .npz")
    try:
        with z:
            return {k: z[k] for k in z.files}
    except Exception as e:                      # a member that is pickled or corrupt
        raise PecletArgumentError("path", _WHAT, p, f"unreadable member: {e}") from None


def _arr(d, key, dtype, shape):
    # the member ``key`` with exactly this dtype kind and shape (None = any length)
    a = d[key]
    if a.dtype != np.dtype(dtype):
        raise PecletArgumentError(key, f"{np.dtype(dtype).name} data", str(a.dtype))
    if a.ndim != len(shape) or any(s is not None and s != t for s, t in zip(shape, a.shape)):
        raise PecletArgumentError(key, f"an array of shape {shape}", a.shape)
    return a


def _scalar(d, key, lo, hi):
    a = _arr(d, key, np.int64, ())
    return check_int(key, int(a), lo, hi)


def _required_keys(d):
    n_shapes = _scalar(d, "n_shapes", 0, len(d))
    n_walls = _scalar(d, "n_walls", 0, len(d))
    keys = set(_BASE_KEYS)
    if "version" in d and d["version"].shape == () and d["version"].dtype.kind == "i" \
            and int(d["version"]) >= 2:
        keys.update(_V2_KEYS)
        if int(d["version"]) >= 3:
            keys.update(_V3_KEYS)
    if "hertz_moduli" in d:
        keys.update(_HERTZ_KEYS)
    if "hertz_rolling" in d:
        keys.update(_HERTZ_KEYS + _ROLLING_KEYS)
    if "sleep_params" in d:
        keys.update(_SLEEP_KEYS)
    if "law_name" in d:
        keys.update(_LAW_KEYS)
        keys.update(k for k in d if k.startswith(_LAW_HISTORY))
    for i in range(n_shapes):
        keys.update({f"shape{i}_kind", f"shape{i}_radius"})
        if f"shape{i}_kind" in d and d[f"shape{i}_kind"].shape == () \
                and d[f"shape{i}_kind"].dtype.kind == "i" and int(d[f"shape{i}_kind"]) == 1:
            keys.update({f"shape{i}_ni", f"shape{i}_nr", f"shape{i}_root", f"shape{i}_shell"})
    for i in range(n_walls):
        keys.update({f"wall{i}_ni", f"wall{i}_nr", f"wall{i}_root", f"wall{i}_prm"})
    return keys, n_shapes, n_walls


def _rebuild(cls, d):
    if "version" in d:                  # a version we do not read is named before the keys
        _scalar(d, "version", 1, FORMAT_VERSION)
    for k in ("n_shapes", "n_walls"):
        if k not in d:
            raise PecletArgumentError(k, "present", "missing")
    keys, n_shapes, n_walls = _required_keys(d)
    missing = sorted(keys - set(d))
    extra = sorted(set(d) - keys)
    if missing or extra:
        raise PecletArgumentError("keys", "exactly those of a save",
                                  {"missing": missing[:5], "unknown": extra[:5]})
    version = _scalar(d, "version", 1, FORMAT_VERSION)
    sim = cls(_scalar(d, "capacity_hint", 0, cls.MAX_CAPACITY))
    for i in range(n_shapes):
        kind = _scalar(d, f"shape{i}_kind", 0, 1)
        radius = float(_arr(d, f"shape{i}_radius", np.float64, ()))
        if kind == 0:
            sim.add_sphere_shape(radius)
        else:
            sim.add_scene_shape(d[f"shape{i}_ni"], _arr(d, f"shape{i}_nr", np.float64, (None, 16)),
                                _scalar(d, f"shape{i}_root", 0, 2 ** 31),
                                _arr(d, f"shape{i}_shell", np.float64, (None, 3)), radius)
    for i in range(n_walls):
        inv, e, mu = _arr(d, f"wall{i}_prm", np.float64, (3,))
        if inv not in (0.0, 1.0):
            raise PecletArgumentError(f"wall{i}_prm[0]", "0 or 1 (invert)", float(inv))
        sim.add_analytic_wall(d[f"wall{i}_ni"], _arr(d, f"wall{i}_nr", np.float64, (None, 16)),
                              _scalar(d, f"wall{i}_root", 0, 2 ** 31), bool(inv), float(e),
                              float(mu))
    sim.set_material_params(*(float(v) for v in _arr(d, "material", np.float64, (3,))))
    sim.set_solver_iterations(*(int(v) for v in _arr(d, "iters", np.int64, (2,))))
    sim.set_gravity(*(float(v) for v in _arr(d, "gravity", np.float64, (3,))))
    sim.enable_periodicity(*(bool(v) for v in _arr(d, "periodic", np.bool_, (3,))))
    dom = _arr(d, "domain", np.float64, (None, 3))
    if len(dom) not in (0, 2):
        raise PecletArgumentError("domain", "an array of shape (0, 3) or (2, 3)", dom.shape)
    if len(dom):
        sim.set_domain(dom[0], dom[1])
    dt = _arr(d, "dt", np.float64, (None,))
    if len(dt) > 1:
        raise PecletArgumentError("dt", "an array of shape (0,) or (1,)", dt.shape)
    if len(dt):
        sim.set_dt(float(dt[0]))
    sim.set_contact_margin_fraction(float(_arr(d, "margin_fraction", np.float64, ())))
    _load_bodies(sim, d)
    _load_warm_start(sim, d)
    if version >= 2:
        _load_v2(sim, d, n_walls)
    if version >= 3:
        sc = _arr(d, "scales", np.float64, (None,))
        if len(sc) not in (0, sim.world.bodies.n):
            raise PecletArgumentError("scales", f"0 or {sim.world.bodies.n} entries", len(sc))
        if len(sc):
            sim.world.scales.values = sim.world.scales.checked(sc, sim.world.bodies.n)  # masses as saved
    if "hertz_moduli" in d:
        _load_hertz(sim, d)
    if "sleep_params" in d:
        sim.world.sleep.load(_arr(d, "sleep_params", np.float64, (2,)),
                        _arr(d, "sleep_asleep", np.int64, (None,)),
                        _arr(d, "sleep_count", np.int64, (None,)), sim.world.bodies.n)
    sim.world.step_count = _scalar(d, "step_count", 0, 2 ** 62)
    t = float(_arr(d, "time", np.float64, ()))
    if not np.isfinite(t):
        raise PecletArgumentError("time", "a finite number", t)
    sim.world.time = t
    sim.world.detector.slot_capacity = _scalar(d, "slot_capacity", 1, 2 ** 40)
    if "law_name" in d:
        _load_law(sim, d)
    sim.world.check_ready()
    return sim


def _load_law(sim, d):
    # the contact law and its parameters through the user's setter, then its history
    name, names = d["law_name"], d["law_param_names"]
    if name.dtype.kind != "U" or name.shape != () or names.dtype.kind not in "U" \
            or names.ndim != 1:
        raise PecletArgumentError("law_name", "a law name and its parameter names (text)",
                                  str(name.dtype))
    values = _arr(d, "law_params", np.float64, (len(names),))
    params = {str(k): float(v) for k, v in zip(names, values)}
    if "substeps" in params:
        params["substeps"] = int(params["substeps"])
    sim.set_contact_law(str(name), **params)
    hist = {k[len(_LAW_HISTORY):]: d[k] for k in d if k.startswith(_LAW_HISTORY)}
    for k, v in hist.items():
        if v.dtype.kind == "f" and not np.all(np.isfinite(v)):
            raise PecletArgumentError(_LAW_HISTORY + k, "finite numbers", "non-finite entries")
    sim.contact_engine.restore(sim.world, hist)


def _load_bodies(sim, d):
    # validated like the setters, but stored as saved (no renormalisation: bitwise resume)
    n = _scalar(d, "n", 0, 2 ** 40)
    rows = {k: _arr(d, k, np.float64, (n, c) if c else (n,))
            for k, c in (("pos", 3), ("vel", 3), ("omega", 3), ("quat", 4), ("inv_mass", 0),
                         ("inv_inertia", 3))}
    shape = _arr(d, "shape", np.int64, (n,)).astype(np.int64)
    for k in ("pos", "vel", "omega", "quat", "inv_mass"):
        if not np.all(np.isfinite(rows[k])):
            raise PecletArgumentError(k, "finite numbers (no NaN or inf)", "non-finite entries")
    if np.any(rows["inv_mass"] < 0.0):
        raise PecletArgumentError("inv_mass", "entries >= 0", float(rows["inv_mass"].min()))
    ii = rows["inv_inertia"]
    default = np.isnan(ii).all(axis=1)
    if not (np.all(np.isfinite(ii[~default])) and np.all(ii[~default] >= 0.0)):
        raise PecletArgumentError("inv_inertia", "rows of finite entries >= 0 (or all NaN: "
                                  "the default)", "a bad row")
    norms = np.array([quat_norm(q) for q in rows["quat"]])
    bad = np.flatnonzero(~(np.abs(norms - 1.0) <= _UNIT_TOL))
    if len(bad):
        raise PecletArgumentError("quat", "unit quaternions (x, y, z, w)", rows["quat"][bad[0]],
                                  f"row {bad[0]}")
    if n and (shape.min() < 0 or shape.max() >= len(sim.world.shapes)):
        raise PecletArgumentError("shape", f"shape ids in [0, {len(sim.world.shapes)})",
                                  (int(shape.min()), int(shape.max())))
    b = sim.world.bodies
    b.resize(n)
    b.pos, b.vel, b.omega, b.quat = (rows[k].copy() for k in ("pos", "vel", "omega", "quat"))
    b.inv_mass, b.inv_inertia, b.shape = rows["inv_mass"].copy(), ii.copy(), shape


def _load_v2(sim, d, n_walls):
    # moving walls, material ids and pairs, external loads: through the validating setters
    rows = _arr(d, "wall_motion", np.float64, (n_walls, 16))
    if not np.all(np.isfinite(rows)):
        raise PecletArgumentError("wall_motion", "finite numbers", "non-finite entries")
    for i in range(n_walls):
        q = rows[i, 3:7]
        if not abs(quat_norm(q) - 1.0) <= _UNIT_TOL:
            raise PecletArgumentError("wall_motion", "unit wall quaternions", q.tolist(),
                                      f"wall {i}")
        sim.set_wall_velocity(i, rows[i, 7:10], rows[i, 10:13], rows[i, 13:16])
    sim.world.wall_motion.load(rows)                     # as saved, no renormalisation: bitwise resume
    n = sim.world.bodies.n
    sim.set_material_ids(_arr(d, "material_ids", np.int64, (n,)))
    wids = _arr(d, "wall_material_ids", np.int64, (n_walls,))
    for i, k in enumerate(wids.tolist()):
        sim.set_wall_material_id(i, k)
    for a, b, e_n, e_t, mu in _arr(d, "pair_materials", np.float64, (None, 5)).tolist():
        if a != int(a) or b != int(b):
            raise PecletArgumentError("pair_materials", "integer material ids", (a, b))
        sim.set_pair_material(int(a), int(b), e_n, e_t, mu)
    if not sim.world.materials.pairs and not np.any(sim.world.materials.body_ids):
        sim.world.materials.body_ids = None          # the defaults, as a fresh simulation has
    for key, setter in (("ext_force", sim.set_external_forces),
                        ("ext_torque", sim.set_external_torques)):
        a = _arr(d, key, np.float64, (None, 3))
        if len(a) not in (0, n):
            raise PecletArgumentError(key, f"0 or {n} rows", len(a))
        if len(a):
            setter(a)


def _load_hertz(sim, d):
    # moduli through the validating setter; the history as saved (bitwise resume)
    for mid, e, nu in _arr(d, "hertz_moduli", np.float64, (None, 3)).tolist():
        if mid != int(mid):
            raise PecletArgumentError("hertz_moduli", "integer material ids", mid)
        sim.set_hertz_material(int(mid), e, nu)
    keys = _arr(d, "hertz_keys", np.int64, (None,)).astype(np.int64)
    xi = _arr(d, "hertz_xi", np.float64, (len(keys), 3))
    if not np.all(np.isfinite(xi)):
        raise PecletArgumentError("hertz_xi", "finite numbers", "non-finite entries")
    if len(keys) > 1 and not np.all(np.diff(keys) >= 0):
        raise PecletArgumentError("hertz_keys", "sorted", "unsorted keys")
    hz = sim.world.hertz
    hz.keys, hz.xi = keys, xi.copy()
    hz.mr = np.zeros((len(keys), 3))
    hz.n_bodies = _scalar(d, "hertz_n", -1, 2 ** 40)
    if "hertz_rolling" in d:
        for a, b, mu_r in _arr(d, "hertz_rolling", np.float64, (None, 3)).tolist():
            if (a, b) == (-1.0, -1.0):
                sim.set_rolling_friction(mu_r)
            elif a != int(a) or b != int(b):
                raise PecletArgumentError("hertz_rolling", "integer material ids", (a, b))
            else:
                sim.set_rolling_friction(mu_r, int(a), int(b))
        mr = _arr(d, "hertz_mr", np.float64, (len(keys), 3))
        if not np.all(np.isfinite(mr)):
            raise PecletArgumentError("hertz_mr", "finite numbers", "non-finite entries")
        hz.mr = mr.copy()


def _load_warm_start(sim, d):
    keys = _arr(d, "ws_keys", np.int64, (None,)).astype(np.int64)
    lam = _arr(d, "ws_lam", np.float64, (len(keys), 4))
    if not np.all(np.isfinite(lam)):
        raise PecletArgumentError("ws_lam", "finite numbers", "non-finite entries")
    if len(keys) > 1 and not np.all(np.diff(keys) > 0):
        raise PecletArgumentError("ws_keys", "strictly increasing", "unsorted keys")
    sim.world.warm.keys, sim.world.warm.lam = keys, lam.copy()


def load(cls, path):
    """A ``cls`` rebuilt from the save at ``path``; :class:`PecletArgumentError` naming ``path``
    for anything that is not a consistent peclet Simulation save."""
    d = _read(path)
    try:
        return _rebuild(cls, d)
    except PecletArgumentError as e:
        raise PecletArgumentError("path", _WHAT, os.fspath(path), str(e)) from None
    except (ValueError, TypeError, IndexError, KeyError, OverflowError) as e:
        # a check this loader lacks must still end in the one clear message, not deep inside
        raise PecletArgumentError("path", _WHAT, os.fspath(path),
                                  f"{type(e).__name__}: {e}") from None
