"""peclet.packing.pack: the page's protocol through the general API, containers, rain,
checkpoint/resume, and every bad argument refused before any work."""
import json
import os

import numpy as np
import pytest

from peclet.core import geom
from peclet.core.validation import PecletArgumentError
from peclet.packing import Container, Material, PageProtocol, RainProtocol, pack, resume
from peclet.packing.bed import api
from peclet.packing.bed import checkpoint as ckpt
from peclet.packing.bed.elements import sphere
from peclet.packing.bed.pour import pour

SMALL_RAIN = RainProtocol(drop=3.0, settle_steps=3000, calm_steps=20, quench_steps=20)
GLASS = Material(e_n=0.3, e_t=0.0, mu=0.3)


def test_page_protocol_through_pack_is_pour_bit_for_bit():
    # pour() is the page's path (its pack hash is pinned by scripts/fingerprint.py); pack()
    # with the page protocol in the page's box must give the same bits
    proto = PageProtocol().scaled(0.04)
    model = api.element_model(sphere())
    pr = pour(model, n=10, box=3.5, seed=3, protocol=proto, progress=False)
    res = pack("sphere", "box:3.5", count=10, protocol=proto, seed=3, progress=False)
    assert np.array_equal(res.pack.positions, pr.positions)
    assert np.array_equal(res.pack.quaternions, pr.quaternions)
    assert res.ke == pr.ke and res.steps == proto.total_steps and res.complete


def test_rain_fills_a_column_inside_its_walls():
    res = pack("sphere", "column:3", count=24, protocol=SMALL_RAIN, material=GLASS, seed=2,
               progress=False)
    c, P = res.container, res.pack.positions
    r = np.hypot(P[:, 0] - c.center_xz[0], P[:, 2] - c.center_xz[1])
    assert res.complete and res.pack.n == 24 and res.state.inserted == 24
    # rigid contacts: no sphere crosses the wall or the floor by more than the solver's slop
    assert np.all(r + 0.5 <= c.radius + 2e-3) and np.all(P[:, 1] >= 0.5 - 2e-3)
    # settled: the stop criterion (KE per element below ke_tol m g D) or the quench held
    m = res.element.mass
    assert res.ke[-1] / (24 * m * 9.81) < SMALL_RAIN.ke_tol
    # the pack's box is the analysis period: images of one side stay clear of the other
    assert res.pack.box[0] >= 2 * c.radius + 1.0


def test_walled_box_and_tree_container_hold_their_elements():
    short = RainProtocol(drop=3.0, settle_steps=300, quench_steps=20)
    res = pack("sphere", "walled:3,2", count=8, protocol=short, material=GLASS, seed=4,
               progress=False)
    P, (cx, cz) = res.pack.positions, res.container.center_xz
    assert np.all(np.abs(P[:, 0] - cx) <= 1.5 - 0.5 + 2e-3)
    assert np.all(np.abs(P[:, 2] - cz) <= 1.0 - 0.5 + 2e-3)
    # a user's container: the fluid region is a cylinder of radius 1.4 standing on y = 0
    b = geom.SceneBuilder()
    root = b.add_leaf("cone", [1.4, 1.4, 6.0], translation=[0.0, 6.0, 0.0])
    res = pack("sphere", (b, root), count=8, protocol=short, material=GLASS, seed=4,
               progress=False)
    phi = b.eval_root(root, res.pack.positions)
    assert res.pack.n == 8 and np.all(phi <= -0.5 + 2e-3)


def test_state_hash_is_the_same_at_one_and_two_threads():
    import numba
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("needs 2 Numba threads")
    kw = dict(count=8, protocol=SMALL_RAIN, material=GLASS, seed=7, progress=False)
    h1 = pack("sphere", "column:2.5", threads=1, **kw).state_hash()
    h2 = pack("sphere", "column:2.5", threads=2, **kw).state_hash()
    assert h1 == h2


@pytest.mark.parametrize("protocol", [SMALL_RAIN, PageProtocol().scaled(0.04)],
                         ids=["rain", "page"])
def test_resume_finishes_bit_for_bit(tmp_path, protocol):
    kw = dict(count=8, protocol=protocol, material=GLASS, seed=11, progress=False)
    full = pack("sphere", "column:3", **kw)
    part = pack("sphere", "column:3", max_steps=130, checkpoint_dir=tmp_path / "c",
                checkpoint_every=50, **kw)
    assert not part.complete and part.steps == 130
    assert json.loads((tmp_path / "c" / ckpt.POINTER).read_text())["step"] == 100
    done = resume(tmp_path / "c", progress=False)
    assert done.complete and done.steps == full.steps
    assert done.state_hash() == full.state_hash()
    assert np.array_equal(np.asarray(done.ke), np.asarray(full.ke))


def test_interrupt_during_a_checkpoint_leaves_the_last_one_intact(tmp_path, monkeypatch):
    kw = dict(count=10, protocol=SMALL_RAIN, material=GLASS, seed=12, progress=False)
    full = pack("sphere", "column:3", **kw)
    real_write = ckpt.write
    calls = []

    def write(path, sim, state):
        calls.append(state.step)
        if len(calls) == 2:   # Ctrl-C in the middle of the second checkpoint's files
            real_save = sim.save

            def save(p):
                real_save(p)
                raise KeyboardInterrupt
            sim.save = save
        return real_write(path, sim, state)
    monkeypatch.setattr(ckpt, "write", write)
    with pytest.raises(KeyboardInterrupt):
        pack("sphere", "column:3", checkpoint_dir=tmp_path / "c", checkpoint_every=40, **kw)
    monkeypatch.setattr(ckpt, "write", real_write)
    ptr = json.loads((tmp_path / "c" / ckpt.POINTER).read_text())
    assert ptr["step"] == 40
    assert [f for f in os.listdir(tmp_path / "c") if f.startswith("ckpt-")] == [ptr["latest"]]
    assert resume(tmp_path / "c", progress=False).state_hash() == full.state_hash()


def _no_build(monkeypatch):
    def fail(*a, **k):
        raise AssertionError("the element was measured before the arguments were checked")
    monkeypatch.setattr(api, "element_model", fail)


BAD = [
    (dict(element="pall_rng"), "element"),
    (dict(element=3), "element"),
    (dict(element="/nonexistent/tree.npz"), "element"),
    (dict(container="cylinder:5"), "container"),
    (dict(container="column:1.2"), "container"),
    (dict(container="column:nan"), "container"),
    (dict(container="walled:4"), "container"),
    (dict(container="box:-3"), "container"),
    (dict(count=0), "count"),
    (dict(count=2.5), "count"),
    (dict(count=True), "count"),
    (dict(protocol="drop"), "protocol"),
    (dict(material=Material.__new__(Material)), None),
    (dict(material=(0.2, 0.0, -0.1)), "material.mu"),
    (dict(wall_material=(1.5, 0.0, 0.3)), "wall_material.e_n"),
    (dict(seed=-1), "seed"),
    (dict(progress="False"), "progress"),
    (dict(threads="2"), "threads"),
    (dict(threads=0), "threads"),
    (dict(max_steps=-5), "max_steps"),
    (dict(checkpoint_every=10), "checkpoint_dir"),
    (dict(element="intalox_saddle", container="column:1.5", protocol="rain"), "container"),
]


@pytest.mark.parametrize("kw,name", [b for b in BAD if b[1] is not None],
                         ids=[b[1] + "-" + str(i) for i, b in enumerate(BAD) if b[1]])
def test_bad_arguments_are_refused_before_any_work(monkeypatch, kw, name):
    _no_build(monkeypatch)
    args = dict(element="sphere", container="column:3", count=5, progress=False)
    args.update(kw)
    with pytest.raises(PecletArgumentError) as e:
        pack(**args)
    assert str(e.value).startswith(name + " must be")


def test_material_and_protocol_fields_are_checked():
    with pytest.raises(PecletArgumentError, match="^mu must be"):
        Material(mu=-0.1)
    with pytest.raises(PecletArgumentError, match="^e_n must be"):
        Material(e_n=1.2)
    with pytest.raises(PecletArgumentError, match="^insert_every must be"):
        RainProtocol(insert_every=0)
    with pytest.raises(PecletArgumentError, match="^drop must be"):
        RainProtocol(drop=float("nan"))


def test_a_closed_container_does_not_enclose_the_insertion_zone(monkeypatch):
    _no_build(monkeypatch)
    b = geom.SceneBuilder()   # a closed box 3 D wide, 1 D tall: no room 4 D above its floor
    root = b.add_leaf("box", [1.5, 0.5, 1.5], translation=[0.0, 0.5, 0.0])
    with pytest.raises(PecletArgumentError, match="^container must be a container that "
                                                   "encloses the insertion zone"):
        pack("sphere", (b, root), count=5, protocol="rain", progress=False)


def test_resume_refuses_what_is_not_a_checkpoint(tmp_path, monkeypatch):
    _no_build(monkeypatch)
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "checkpoint.json").write_text("{}")
    for d in (tmp_path / "nothing", tmp_path, tmp_path / "x"):
        with pytest.raises(PecletArgumentError, match="^checkpoint_dir must be"):
            resume(d, progress=False)
    # a checkpoint directory is not reused by a fresh run
    c = tmp_path / "c"
    ckpt.init(c, {"x": 1}, {"a": np.zeros(1)})
    ckpt.mark_started(c)
    with pytest.raises(PecletArgumentError, match="^checkpoint_dir must be"):
        pack("sphere", "column:3", count=3, checkpoint_dir=c, progress=False)


def test_user_elements_and_their_diameter(tmp_path):
    b = geom.SceneBuilder()
    root = b.add_leaf("sphere", [0.8])
    el = api.resolve_element((b, root))
    assert api.element_diameter(el) == pytest.approx(1.6)
    ni, nr, _, _ = b.encode()
    np.savez(tmp_path / "t.npz", node_ints=ni, node_reals=nr, root=root)
    el2 = api.resolve_element(str(tmp_path / "t.npz"))
    assert np.array_equal(el2.builder.encode()[1], nr)
    assert api.element_diameter(api.resolve_element("pall_ring")) == 1.0
    assert api.element_diameter(api.resolve_element("berl_saddle")) == 1.0
    # container sizes are in element diameters
    c = Container.column(4).bound(1.6)
    assert c.radius == pytest.approx(3.2)
