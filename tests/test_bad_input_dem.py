"""The DEM front door: every bad argument of peclet.dem.Simulation (setters, shapes, walls,
step, load) raises PecletArgumentError naming it, before any work; Simulation.load accepts
only consistent peclet saves (parametrized cases and Hypothesis fuzzing of mutated saves)."""
import os
import tempfile

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from peclet.core import geom
from peclet.core.validation import PecletArgumentError
from peclet.dem import Simulation


def _tree(kind="sphere", params=(0.3,), **kw):
    b = geom.SceneBuilder()
    r = b.add_leaf(kind, list(params), **kw)
    ni, nr, _, _ = b.encode()
    return ni, nr, r


def _two_spheres():
    sim = Simulation(1)
    sim.add_sphere_shape(0.5)
    sim.set_positions([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    sim.set_shape_ids([0, 0])
    return sim


NI, NR, ROOT = _tree()
SHELL = np.array([[0.3, 0, 0], [-0.3, 0, 0], [0, 0.3, 0], [0, -0.3, 0], [0, 0, 0.3],
                  [0, 0, -0.3]])
WALL = _tree("box", (5.0, 1.0, 5.0), translation=[0.0, -1.5, 0.0])


def _wall(**kw):
    args = dict(node_ints=WALL[0], node_reals=WALL[1], root=WALL[2], invert=False, e_n=0.5, mu=0.5)
    args.update(kw)
    return lambda s: s.add_analytic_wall(**args)


def _scene(**kw):
    args = dict(node_ints=NI, node_reals=NR, root=ROOT, shell_points=SHELL, bounding_radius=0.3)
    args.update(kw)
    return lambda s: s.add_scene_shape(**args)


def _call(name, *args):
    return lambda s: getattr(s, name)(*args)


BAD_CALLS = [
    # flags are bools, never strings or integers (issue 18, finding 3)
    ("periodicity 'False'", _call("enable_periodicity", "False", "False", "False"), "px"),
    ("periodicity int", _call("enable_periodicity", False, 1, False), "py"),
    ("periodicity None", _call("enable_periodicity", False, False, None), "pz"),
    ("wall invert 'no'", _wall(invert="no"), "invert"),
    ("wall invert 0", _wall(invert=0), "invert"),
    ("wall e_n 1.5", _wall(e_n=1.5), "e_n"),
    ("wall e_n nan", _wall(e_n=np.nan), "e_n"),
    ("wall mu -3", _wall(mu=-3.0), "mu"),
    ("wall mu inf", _wall(mu=np.inf), "mu"),
    ("wall root 5", _wall(root=5), "root"),
    ("wall root True", _wall(root=True), "root"),
    # materials
    ("restitution 7", _call("set_material_params", 7.0, 0.0, 0.5), "e_n"),
    ("restitution -0.1", _call("set_material_params", -0.1, 0.0, 0.5), "e_n"),
    ("restitution '0.5'", _call("set_material_params", "0.5", 0.0, 0.5), "e_n"),
    ("tangential 1.5", _call("set_material_params", 0.5, 1.5, 0.5), "e_t"),
    ("friction -3", _call("set_material_params", 0.5, 0.0, -3.0), "mu"),
    ("friction nan", _call("set_material_params", 0.5, 0.0, np.nan), "mu"),
    # bounded work (issue 18, finding 7)
    ("iterations 1e9", _call("set_solver_iterations", 10 ** 9, 10 ** 9), "position"),
    ("velocity iterations 1e9", _call("set_solver_iterations", 10, 10 ** 9), "velocity"),
    ("velocity iterations -1", _call("set_solver_iterations", 10, -1), "velocity"),
    ("iterations bool", _call("set_solver_iterations", True, 8), "position"),
    ("iterations 1.5", _call("set_solver_iterations", 1.5, 8), "position"),
    ("contact capacity 0", _call("set_contact_capacity", 0), "n"),
    ("contact capacity 1e12", _call("set_contact_capacity", 10 ** 12), "n"),
    ("margin 0", _call("set_contact_margin_fraction", 0.0), "fraction"),
    ("margin 100", _call("set_contact_margin_fraction", 100.0), "fraction"),
    # configuration
    ("gravity nan", _call("set_gravity", 0.0, np.nan, 0.0), "gy"),
    ("gravity string", _call("set_gravity", "0", 0.0, 0.0), "gx"),
    ("domain hi <= lo", _call("set_domain", (0, 0, 0), (1, 0, 1)), "hi"),
    ("domain 2 components", _call("set_domain", (0, 0), (1, 1, 1)), "lo"),
    ("domain nan", _call("set_domain", (0, np.nan, 0), (1, 1, 1)), "lo"),
    ("dt 0", _call("set_dt", 0.0), "dt"),
    ("dt inf", _call("set_dt", np.inf), "dt"),
    ("step dt -1", _call("step", -1.0), "dt"),
    ("step dt string", _call("step", "0.1"), "dt"),
    ("step without dt", _call("step"), "dt"),
    # shapes
    ("radius 0", _call("add_sphere_shape", 0.0), "radius"),
    ("radius nan", _call("add_sphere_shape", np.nan), "radius"),
    ("radius string", _call("add_sphere_shape", "1"), "radius"),
    ("scene no probes", _scene(shell_points=np.zeros((0, 3))), "shell_points"),
    ("scene nan probe", _scene(shell_points=np.full((2, 3), np.nan)), "shell_points"),
    ("scene radius -1", _scene(bounding_radius=-1.0), "bounding_radius"),
    ("scene root 9", _scene(root=9), "root"),
    # particles
    ("positions nan", _call("set_positions", np.full((2, 3), np.nan)), "positions"),
    ("positions (2, 2)", _call("set_positions", np.zeros((2, 2))), "positions"),
    ("positions string", _call("set_positions", "abc"), "positions"),
    ("inverse mass negative", _call("set_inv_mass", [1.0, -1.0]), "inv_mass"),
    ("inverse mass wrong N", _call("set_inv_mass", [1.0, 1.0, 1.0]), "inv_mass"),
    ("inverse inertia negative", _call("set_inv_inertia", [[1, 1, -1.0], [1, 1, 1]]),
     "inv_inertia"),
    ("inverse inertia nan", _call("set_inv_inertia", [[1, 1, np.nan], [1, 1, 1]]),
     "inv_inertia"),
    ("zero quaternion", _call("set_quaternions", [[0, 0, 0, 1.0], [0, 0, 0, 0]]), "quats"),
    ("nan quaternion", _call("set_quaternions", [[0, 0, 0, 1.0], [0, np.nan, 0, 1]]),
     "quats"),
    ("quaternion (2, 3)", _call("set_quaternions", np.ones((2, 3))), "quats"),
    ("velocity inf", _call("set_velocities", [[np.inf, 0, 0], [0, 0, 0]]), "velocities"),
    ("omega wrong N", _call("set_angular_velocities", np.zeros((3, 3))),
     "angular_velocities"),
    ("shape id 7", _call("set_shape_ids", [0, 7]), "ids"),
    ("shape id 0.5", _call("set_shape_ids", [0.5, 0.0]), "ids"),
    ("shape ids 2-D", _call("set_shape_ids", [[0], [0]]), "ids"),
]


@pytest.mark.parametrize("what, call, name", BAD_CALLS, ids=[c[0] for c in BAD_CALLS])
def test_bad_argument_is_refused_naming_it(what, call, name):
    sim = _two_spheres()
    before = (sim.get_positions(), sim.num_shapes(), sim.num_walls(), sim.step_count)
    with pytest.raises(PecletArgumentError) as err:
        call(sim)
    assert err.value.argument == name
    assert str(err.value).startswith(f"{name} must be ")
    after = (sim.get_positions(), sim.num_shapes(), sim.num_walls(), sim.step_count)
    assert np.array_equal(before[0], after[0]) and before[1:] == after[1:]


@pytest.mark.parametrize("capacity", [-1, True, "3", 10 ** 9, 2.5])
def test_bad_capacity_is_refused(capacity):
    with pytest.raises(PecletArgumentError, match="^capacity must be"):
        Simulation(capacity)


def test_string_flags_no_longer_flip_periodicity_or_walls():
    sim = _two_spheres()
    with pytest.raises(PecletArgumentError):
        sim.enable_periodicity("False", "False", "False")
    c = sim.detect_contacts()                       # not periodic: no domain needed
    assert len(c["depth"]) == 0


def test_quaternions_of_any_finite_magnitude_are_normalised():
    sim = _two_spheres()
    sim.set_quaternions([[1e200] * 4, [0.0, 0.0, 1e-200, 0.0]])
    np.testing.assert_array_equal(sim.get_quaternions(), [[0.5] * 4, [0, 0, 1, 0]])


# ---------------------------------------------------------------------------- Simulation.load

def _saved_state():
    sim = Simulation(1)
    sim.add_sphere_shape(0.5)
    sim.add_scene_shape(NI, NR, ROOT, SHELL, 0.3)
    sim.add_analytic_wall(*WALL, False, 0.4, 0.6)
    sim.set_domain((-3, -2, -3), (3, 6, 3))
    sim.enable_periodicity(True, False, False)
    sim.set_positions([[0.0, 0.0, 0.0], [0.95, 0.1, 0.0], [-1.2, 0.5, 0.3]])
    sim.set_shape_ids([0, 0, 1])
    sim.set_gravity(0.0, -9.81, 0.0)
    sim.set_dt(2e-3)
    for _ in range(5):
        sim.step()
    assert sim.num_contacts() > 0                 # the warm-start cache is not empty
    with tempfile.TemporaryDirectory() as d:
        p = os.path.join(d, "s.npz")
        sim.save(p)
        with np.load(p) as z:
            return {k: z[k] for k in z.files}


SAVE = _saved_state()


def _write(d, path):
    with open(path, "wb") as fh:
        np.savez(fh, **d)
    return path


def _mutated(**changes):
    d = {k: v.copy() for k, v in SAVE.items()}
    for k, v in changes.items():
        if v is None:
            del d[k]
        else:
            d[k] = v
    return d


def _with(key, fn):
    d = _mutated()
    d[key] = fn(d[key].copy())
    return d


def _set(a, idx, value):
    a[idx] = value
    return a


BAD_SAVES = [
    ("missing key", _mutated(quat=None), "quat"),
    ("claims 5000 particles, holds 3", _mutated(n=np.int64(5000)), "pos"),
    ("restitution 7", _with("material", lambda a: _set(a, 0, 7.0)), "e_n"),
    ("friction -3", _with("material", lambda a: _set(a, 2, -3.0)), "mu"),
    ("negative inverse mass", _with("inv_mass", lambda a: _set(a, 1, -1.0)), "inv_mass"),
    ("zero quaternion", _with("quat", lambda a: _set(a, 2, 0.0)), "quat"),
    ("nan quaternion", _with("quat", lambda a: _set(a, (0, 1), np.nan)), "quat"),
    ("non-unit quaternion", _with("quat", lambda a: a * 2.0), "quat"),
    ("nan position", _with("pos", lambda a: _set(a, (1, 1), np.nan)), "pos"),
    ("float32 positions", _with("pos", lambda a: a.astype(np.float32)), "pos"),
    ("negative inverse inertia", _with("inv_inertia", lambda a: _set(a, 0, -1.0)),
     "inv_inertia"),
    ("unknown key", _mutated(extra=np.zeros(1)), "keys"),
    ("wall invert 0.5", _with("wall0_prm", lambda a: _set(a, 0, 0.5)), "wall0_prm"),
    ("wall friction -1", _with("wall0_prm", lambda a: _set(a, 2, -1.0)), "mu"),
    ("iterations 1e9", _mutated(iters=np.array([10 ** 9, 8], np.int64)), "position"),
    ("version 4", _mutated(version=np.int64(4)), "version"),
    ("version 1 with the version 2 keys", _mutated(version=np.int64(1)), "keys"),
    ("version 0", _mutated(version=np.int64(0)), "version"),
    ("non-unit wall quaternion", _with("wall_motion", lambda a: _set(a, (0, 6), 2.0)),
     "wall_motion"),
    ("nan wall velocity", _with("wall_motion", lambda a: _set(a, (0, 7), np.nan)),
     "wall_motion"),
    ("material id 5000", _with("material_ids", lambda a: _set(a, 0, 5000)), "ids"),
    ("pair restitution 2", _mutated(pair_materials=np.array([[0.0, 1.0, 2.0, 0.0, 0.5]])),
     "e_n"),
    ("external forces of 2 rows for 3 bodies", _mutated(ext_force=np.zeros((2, 3))),
     "ext_force"),
    ("periodic as strings", _mutated(periodic=np.array(["True"] * 3)), "periodic"),
    ("domain (1, 3)", _with("domain", lambda a: a[:1]), "domain"),
    ("dt -1", _mutated(dt=np.array([-1.0])), "dt"),
    ("shape id out of range", _with("shape", lambda a: _set(a, 0, 5)), "shape"),
    ("unsorted warm start", _with("ws_keys", lambda a: a[::-1].copy()), "ws_keys"),
    ("warm start rows", _with("ws_lam", lambda a: a[:-1]), "ws_lam"),
    ("shape count 9", _mutated(n_shapes=np.int64(9)), "keys"),
    ("shape tree rows", _with("shape1_nr", lambda a: np.vstack([a, a])), "node_reals"),
]


@pytest.mark.parametrize("what, d, key", BAD_SAVES, ids=[c[0] for c in BAD_SAVES])
def test_load_refuses_an_inconsistent_save_naming_path_and_key(tmp_path, what, d, key):
    path = _write(d, tmp_path / "bad.npz")
    with pytest.raises(PecletArgumentError) as err:
        Simulation.load(path)
    assert err.value.argument == "path"
    msg = str(err.value)
    assert msg.startswith("path must be a peclet Simulation save")
    assert key in msg


def _pickled(path):
    d = _mutated()
    d["pos"] = np.array([{"x": 1}], dtype=object)
    return _write(d, path)


def _text(path):
    path.write_text("not a save\n")
    return path


def _npy(path):
    np.save(path, np.zeros(3))
    return path


def _truncated(path):
    _write(_mutated(), path)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    return path


@pytest.mark.parametrize("make", [_pickled, _text, _npy, _truncated, lambda p: p],
                         ids=["pickled", "text file", "npy file", "truncated", "missing"])
def test_load_refuses_files_that_are_not_saves(tmp_path, make):
    path = make(tmp_path / ("x.npy" if make is _npy else "x.npz"))
    with pytest.raises(PecletArgumentError, match="^path must be"):
        Simulation.load(path)


def test_an_unmutated_save_loads_and_resumes_bitwise(tmp_path):
    a = Simulation.load(_write(_mutated(), tmp_path / "a.npz"))
    b = Simulation.load(_write(_mutated(), tmp_path / "b.npz"))
    for _ in range(3):
        a.step()
        b.step()
    assert np.array_equal(a.get_positions(), b.get_positions())
    assert a.num_particles() == 3


def test_save_refuses_an_unwritable_path(tmp_path):
    with pytest.raises(PecletArgumentError, match="^path must be"):
        _two_spheres().save(tmp_path)               # a directory


# ---------------------------------------------------------------------------- fuzzing

_FLOAT_KEYS = [k for k, v in SAVE.items() if v.dtype == np.float64 and v.size]
_ROW_KEYS = [k for k, v in SAVE.items() if v.ndim >= 1]

_mutation = st.one_of(
    st.tuples(st.just("drop"), st.sampled_from(sorted(SAVE))),
    st.tuples(st.just("rows"), st.sampled_from(sorted(_ROW_KEYS)), st.sampled_from([-1, 1])),
    st.tuples(st.just("nan"), st.sampled_from(sorted(_FLOAT_KEYS)), st.integers(0, 10 ** 6)),
    st.tuples(st.just("dtype"), st.sampled_from(sorted(SAVE)),
              st.sampled_from([np.float32, np.int32, np.int64, np.float64, np.bool_])),
)


def _apply(d, m):
    kind, key = m[0], m[1]
    if key not in d:
        return
    a = d[key]
    if kind == "drop":
        del d[key]
    elif kind == "rows" and a.ndim >= 1:
        d[key] = a[:-1] if m[2] < 0 or len(a) == 0 else np.concatenate([a, a[-1:]])
    elif kind == "nan" and a.dtype.kind == "f" and a.size:
        a = a.copy()
        a.reshape(-1)[m[2] % a.size] = np.nan
        d[key] = a
    elif kind == "dtype":
        with np.errstate(all="ignore"):
            d[key] = a.astype(m[2])


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(_mutation, min_size=1, max_size=3))
def test_fuzzed_saves_load_cleanly_or_are_refused_clearly(mutations):
    d = _mutated()
    for m in mutations:
        _apply(d, m)
    with tempfile.TemporaryDirectory() as tmp:
        path = _write(d, os.path.join(tmp, "f.npz"))
        try:
            sim = Simulation.load(path)
        except PecletArgumentError as e:
            assert e.argument == "path" and str(e).startswith("path must be")
            return
    sim.step(1e-3)                                  # steps, with consistent sizes
    n = sim.num_particles()
    for get in ("get_positions", "get_velocities", "get_angular_velocities",
                "get_quaternions", "get_inv_inertia", "get_inv_mass", "get_shape_ids"):
        assert len(getattr(sim, get)()) == n
    assert np.all(np.isfinite(sim.get_positions()))


# ---------------------------------------------------------------------------- rolling friction

BAD_ROLLING = [
    ("mu_r -0.1", (-0.1,), "mu_r"),
    ("mu_r nan", (np.nan,), "mu_r"),
    ("mu_r 1.5", (1.5,), "mu_r"),
    ("mu_r string", ("0.1",), "mu_r"),
    ("material id 1024", (0.1, 1024, 0), "material_a"),
    ("material id -1", (0.1, 0, -1), "material_b"),
    ("one material id", (0.1, 3), "material_b"),
]


@pytest.mark.parametrize("what, args, name", BAD_ROLLING, ids=[c[0] for c in BAD_ROLLING])
def test_bad_rolling_friction_is_refused_naming_it(what, args, name):
    sim = _two_spheres()
    with pytest.raises(PecletArgumentError) as err:
        sim.set_rolling_friction(*args)
    assert err.value.argument == name
    assert str(err.value).startswith(f"{name} must be ")


def _rolling_save():
    sim = _two_spheres()
    sim.set_hertz_material(0, 1e7, 0.3)
    sim.set_rolling_friction(0.1)
    sim.set_rolling_friction(0.2, 0, 1)
    with tempfile.TemporaryDirectory() as d:
        p = os.path.join(d, "r.npz")
        sim.save(p)
        with np.load(p) as z:
            return {k: z[k] for k in z.files}


@pytest.mark.parametrize("key, value, named", [
    ("hertz_rolling", np.array([[-1.0, -1.0, 1.5]]), "mu_r"),
    ("hertz_rolling", np.array([[0.0, 0.5, 0.1]]), "hertz_rolling"),
    ("hertz_rolling", np.zeros((1, 2)), "hertz_rolling"),
    ("hertz_mr", np.zeros((3, 3)), "hertz_mr"),
    ("hertz_mr", None, "hertz_mr"),
    ("hertz_moduli", None, "hertz_moduli"),
])
def test_load_refuses_a_bad_rolling_save(tmp_path, key, value, named):
    d = _rolling_save()
    assert {"hertz_rolling", "hertz_mr"} <= set(d)
    if value is None:
        del d[key]
    else:
        d[key] = value
    with pytest.raises(PecletArgumentError) as err:
        Simulation.load(_write(d, tmp_path / "bad.npz"))
    assert err.value.argument == "path" and named in str(err.value)
    Simulation.load(_write(_rolling_save(), tmp_path / "good.npz"))   # unmutated: loads
