"""Bad input to the packing front door: load_pack / save_pack / Pack, the progress bar, and the
figures' backend. Each case asserts a PecletArgumentError naming the argument, or a documented
acceptance with the value it must give (issue 18 items 4 and 8, issue 13 item 5)."""
import os
import subprocess
import sys
import zipfile

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from peclet.core.validation import PecletArgumentError
from peclet.packing.bed import elements as E
from peclet.packing.bed.freeze import Pack, load_pack, save_pack
from peclet.packing.bed.progress import Progress

N = 6


def good_fields(n=N):
    """The fields of a valid pack of ``n`` page rings (as save_pack writes them)."""
    el = E.pall_ring()
    ni, nr, _, _ = el.builder.encode()
    g = np.random.default_rng(0)
    q = g.normal(size=(n, 4))
    return dict(positions=np.c_[g.uniform(0, 3.5, n), g.uniform(0.5, 3, n), g.uniform(0, 3.5, n)],
                quaternions=q / np.linalg.norm(q, axis=1)[:, None], box=np.array([3.5, 3.5]),
                ring_volume=np.float64(0.268), node_ints=ni, node_reals=nr,
                home_root=np.int32(el.root), bounding_radius=np.float64(0.72),
                shell=g.uniform(-0.5, 0.5, (40, 3)), mass=np.float64(0.268),
                inv_inertia=np.array([20.8, 20.7, 20.1]), envelope_root=np.int32(el.envelope_root),
                envelope_volume=np.float64(el.envelope_volume), axis_home=np.array([0., 1., 0.]))


@pytest.fixture(scope="module")
def base():
    return good_fields()


def write_npz(path, fields):
    with open(path, "wb") as fh:
        np.savez(fh, **fields)
    return path


def assert_refused(path, *needles):
    with pytest.raises(PecletArgumentError) as e:
        load_pack(path)
    msg = str(e.value)
    assert e.value.argument == "path" and "\n" not in msg
    assert msg.startswith("path must be a peclet pack file")
    for s in needles:
        assert s in msg, msg
    return msg


def _mut(**changes):
    def f(d):
        d = dict(d)
        for k, v in changes.items():
            if v is None:
                d.pop(k)
            else:
                d[k] = v(d[k]) if callable(v) else v
        return d
    return f


def _nan_row(a):
    a = np.array(a, dtype=np.float64)
    a[1, 0] = np.nan
    return a


MUTATIONS = {
    # the issue's own findings
    "positions (36, 4) from 48 x 3": (_mut(positions=np.zeros((36, 4))), "positions"),
    "NaN positions": (_mut(positions=_nan_row), "positions"),
    "infinite box": (_mut(box=np.array([np.inf, 3.5])), "box"),
    "zero quaternion": (_mut(quaternions=lambda q: np.r_[q[:-1], np.zeros((1, 4))]), "zero"),
    "node_ints of 2 columns": (_mut(node_ints=lambda a: a[:, :2]), "node_ints"),
    "node_reals of 15 columns": (_mut(node_reals=lambda a: a[:, :15]), "node_reals"),
    "node_reals one row short": (_mut(node_reals=lambda a: a[:-1]), "node_reals"),
    # more of the same family
    "quaternions one row short": (_mut(quaternions=lambda q: q[:-1]), "quaternions"),
    # found by the fuzz below: a small array's repr spans lines; the message must not
    "two quaternion rows": (_mut(quaternions=lambda q: q[:2]), "shape (2, 4)"),
    "home_root as a float pair": (_mut(home_root=np.array([1.0, 2.0])), "home_root"),
    "NaN quaternion": (_mut(quaternions=_nan_row), "quaternions"),
    "negative box": (_mut(box=np.array([-1.0, 3.5])), "box"),
    "box of 3 sides": (_mut(box=np.array([3.5, 3.5, 3.5])), "box"),
    "home_root out of range": (_mut(home_root=np.int32(10 ** 6)), "home_root"),
    "envelope_root -2": (_mut(envelope_root=np.int32(-2)), "envelope_root"),
    "node_ints stored as float": (_mut(node_ints=lambda a: a.astype(float)), "node_ints"),
    "home_root stored as float": (_mut(home_root=np.float64(3.0)), "home_root"),
    "ring_volume < 0": (_mut(ring_volume=np.float64(-0.2)), "ring_volume"),
    "bounding_radius 0": (_mut(bounding_radius=np.float64(0.0)), "bounding_radius"),
    "ring_volume an array": (_mut(ring_volume=np.array([0.2, 0.3])), "ring_volume"),
    "bool positions": (_mut(positions=lambda a: a > 1), "positions"),
    "complex positions": (_mut(positions=lambda a: a + 0j), "positions"),
    "string box": (_mut(box=np.array(["3.5", "3.5"])), "box"),
    "NaN shell probe": (_mut(shell=_nan_row), "shell"),
    "negative inverse inertia": (_mut(inv_inertia=np.array([1.0, -1.0, 1.0])), "inv_inertia"),
    "zero axis": (_mut(axis_home=np.zeros(3)), "axis_home"),
    "negative mass": (_mut(mass=np.float64(-1.0)), "mass"),
    "no rings": (_mut(positions=np.zeros((0, 3)), quaternions=np.zeros((0, 4))), "positions"),
    "unknown node kind": (_mut(node_ints=lambda a: np.r_[a[:-1], [[999, -1, -1]]]),
                          "node_ints"),
    "child after parent": (_mut(node_ints=lambda a: np.r_[a[:-1], [[a[-1, 0], 10 ** 5, 0]]]),
                           "node_ints"),
}
for _k in ("positions", "quaternions", "box", "ring_volume", "node_ints", "node_reals",
           "home_root", "bounding_radius"):
    MUTATIONS[f"missing {_k}"] = (_mut(**{_k: None}), "missing fields")


@pytest.mark.parametrize("case", sorted(MUTATIONS))
def test_load_pack_refuses_an_inconsistent_file(tmp_path, base, case):
    mutate, needle = MUTATIONS[case]
    assert_refused(write_npz(tmp_path / "p.npz", mutate(base)), needle)


def test_load_pack_refuses_files_that_are_not_packs(tmp_path, base):
    (tmp_path / "t.npz").write_text("hello, not a pack")
    assert_refused(tmp_path / "t.npz", "pickled")    # numpy's guess for a text file
    np.save(tmp_path / "a.npy", np.zeros((4, 3)))
    assert_refused(tmp_path / "a.npy", ".npy")
    (tmp_path / "z.npz").write_bytes(b"PK\x03\x04 torn zip")
    assert_refused(tmp_path / "z.npz")
    with zipfile.ZipFile(tmp_path / "e.npz", "w") as z:     # a zip with no arrays in it
        z.writestr("readme.txt", "x")
    assert_refused(tmp_path / "e.npz", "missing fields")
    assert_refused(tmp_path / "nope.npz", "no such file")
    assert_refused(tmp_path, "no such file")                # a directory
    with pytest.raises(PecletArgumentError, match="path"):
        load_pack(12)


def test_load_pack_never_unpickles(tmp_path, base):
    d = dict(base)
    d["positions"] = np.array([{"x": 1}] * N, dtype=object)
    with open(tmp_path / "p.npz", "wb") as fh:
        np.savez(fh, **d)                    # numpy pickles object arrays
    assert_refused(tmp_path / "p.npz", "positions")
    with open(tmp_path / "q.npz", "wb") as fh:
        np.savez(fh, **dict(base, evil=np.array([object()], dtype=object)))
    # an extra pickled field is never read (only the pack's own fields are)
    assert load_pack(tmp_path / "q.npz").n == N


def test_load_pack_documented_acceptances(tmp_path, base):
    # huge and tiny quaternions are directions: normalised exactly, not overflowed to zero
    q = np.array(base["quaternions"])
    d = dict(base, quaternions=np.r_[q[:-2], 1e200 * q[-2:-1], 1e-200 * q[-1:]])
    pk = load_pack(write_npz(tmp_path / "q.npz", d))
    assert np.allclose(pk.quaternions, q, rtol=0, atol=4e-16)
    assert np.allclose(np.linalg.norm(pk.quaternions, axis=1), 1.0, rtol=0, atol=4e-16)
    # unknown extra fields are ignored; the page's float32 file is widened
    d = {k: (v.astype(np.float32) if v.dtype.kind == "f" else v) for k, v in base.items()}
    pk = load_pack(write_npz(tmp_path / "f.npz", dict(d, comment=np.array([1, 2]))))
    assert pk.positions.dtype == np.float64
    assert np.array_equal(pk.positions, base["positions"].astype(np.float32).astype(float))


def test_save_pack_refuses_nan_and_bad_targets_and_writes_nothing(tmp_path, base):
    pk = Pack(**good_fields())
    pk.positions[2, 1] = np.nan               # changed after construction
    with pytest.raises(PecletArgumentError, match="pack.positions"):
        save_pack(tmp_path / "p.npz", pk)
    with pytest.raises(PecletArgumentError, match="pack"):
        save_pack(tmp_path / "p.npz", dict(base))
    ok = Pack(**base)
    (tmp_path / "d.npz").mkdir()
    with pytest.raises(PecletArgumentError, match="directory"):
        save_pack(tmp_path / "d.npz", ok)
    (tmp_path / "f").write_text("x")
    with pytest.raises(PecletArgumentError, match="is a file"):
        save_pack(tmp_path / "f" / "p.npz", ok)
    assert sorted(os.listdir(tmp_path)) == ["d.npz", "f"]


@pytest.mark.parametrize("mask", [0o022, 0o002, 0o077])
def test_saved_pack_respects_the_umask(tmp_path, base, mask):
    old = os.umask(mask)
    try:
        path = save_pack(tmp_path / "p.npz", Pack(**base))
    finally:
        os.umask(old)
    assert os.stat(path).st_mode & 0o777 == 0o666 & ~mask


def test_pack_constructor_names_the_field(base):
    with pytest.raises(PecletArgumentError, match="^positions must"):
        Pack(**dict(base, positions=np.zeros((36, 4))))
    with pytest.raises(PecletArgumentError, match="^quaternions must"):
        Pack(**dict(base, quaternions=np.zeros((N, 4))))


# ---- Hypothesis: mutated saves load as a clear error or a consistent pack

def _consistent(pk):
    n = pk.n
    assert n >= 1 and pk.positions.shape == (n, 3) and pk.positions.dtype == np.float64
    assert np.all(np.isfinite(pk.positions))
    assert pk.quaternions.shape == (n, 4)
    assert np.allclose(np.linalg.norm(pk.quaternions, axis=1), 1.0, rtol=0, atol=1e-12)
    assert pk.box.shape == (2,) and np.all(np.isfinite(pk.box)) and np.all(pk.box > 0)
    assert 0 <= pk.home_root < len(pk.node_ints) and -1 <= pk.envelope_root < len(pk.node_ints)
    assert pk.node_reals.shape == (len(pk.node_ints), 16)
    b = pk.builder()                                   # the tree decodes and evaluates
    assert np.all(np.isfinite(b.eval_root(pk.home_root, pk.positions[:2] - pk.positions[0])))
    assert np.all(np.isfinite(pk.shell)) and pk.shell.shape[1] == 3


_KEYS = sorted(good_fields(2))


@st.composite
def mutations(draw):
    key = draw(st.sampled_from(_KEYS))
    kind = draw(st.sampled_from(["drop", "rows", "nan", "dtype", "inf"]))
    return key, kind, draw(st.integers(-3, 3)), draw(st.sampled_from(
        [np.float32, np.int64, np.int16, np.bool_, np.complex128, np.float16]))


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(muts=st.lists(mutations(), min_size=1, max_size=3))
def test_fuzzed_saves_give_a_clear_error_or_a_consistent_pack(tmp_path, base, muts):
    d = {k: np.array(v) for k, v in base.items()}
    for key, kind, k, dtype in muts:
        if key not in d:
            continue
        a = d[key]
        if kind == "drop":
            del d[key]
        elif kind == "rows" and a.ndim:
            d[key] = a[:max(0, len(a) + k)] if k < 0 else np.concatenate([a] + [a[:1]] * k)
        elif kind in ("nan", "inf") and a.dtype.kind == "f" and a.size:
            a = a.copy()
            a.flat[abs(k) % a.size] = np.nan if kind == "nan" else -np.inf
            d[key] = a
        elif kind == "dtype":
            d[key] = a.astype(dtype)
    path = write_npz(tmp_path / "fuzz.npz", d)
    try:
        pk = load_pack(path)
    except PecletArgumentError as e:
        assert e.argument == "path" and "\n" not in str(e)
        return
    _consistent(pk)


# ---- the progress bar (tqdm behind the pour's interface)

def test_progress_shows_the_time_left_and_the_phase_and_is_quiet_when_disabled():
    import io

    s = io.StringIO()
    bar = Progress(40, "pall-ring pour ", stream=s, log_interval=0.0)
    for i in range(50):                               # past the total: clamped
        bar.update(1, "pour" if i < 20 else "tap")
    bar.close()
    text = s.getvalue()
    assert bar.done == 40 and "40/40" in text and "pall-ring pour:" in text
    assert "<" in text.splitlines()[-1] or "<" in text       # [elapsed<remaining, rate]
    assert "tap" in text and "pour" in text
    q = io.StringIO()
    quiet = Progress(40, "x", stream=q, enabled=False)
    quiet.update(10, "pour")
    quiet.close()
    assert q.getvalue() == "" and quiet.done == 10


@pytest.mark.parametrize("kw,name", [(dict(total=-1), "total"), (dict(total=True), "total"),
                                     (dict(total=3, enabled="False"), "enabled"),
                                     (dict(total=3, hz=0), "hz")])
def test_progress_refuses_bad_arguments(kw, name):
    with pytest.raises(PecletArgumentError, match=f"^{name} must"):
        Progress(**kw)


# ---- figures leave the user's matplotlib backend alone

@pytest.mark.parametrize("backend", ["svg", "template"])
def test_importing_the_pipeline_and_drawing_keeps_the_backend(tmp_path, backend):
    code = (
        "import sys, matplotlib\n"
        "before = matplotlib.get_backend()\n"
        "import peclet.packing.page.pipeline\n"
        "from peclet.packing.output import figures as F\n"
        "import numpy as np\n"
        "F.orientation_histogram(np.linspace(0, 1, 30), sys.argv[1])\n"
        "after = matplotlib.get_backend()\n"
        "print(before, after, 'matplotlib.pyplot' in sys.modules)\n")
    env = dict(os.environ, MPLBACKEND=backend)
    r = subprocess.run([sys.executable, "-c", code, str(tmp_path / "o.png")], env=env,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    before, after, pyplot = r.stdout.split()
    assert before.lower() == backend and after == before and pyplot == "False"
    with open(tmp_path / "o.png", "rb") as fh:
        assert fh.read(8) == b"\x89PNG\r\n\x1a\n"
