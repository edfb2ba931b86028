"""``pack(..., contact="hertz")`` and ``peclet pack --contact hertz``: the Hertz–Mindlin law
through the packing protocols (peclet.packing.bed.contact): units, the Rayleigh step rule, a
small rained column settling with Hertz overlaps, a checkpointed run resumed bit for bit,
and the refusals (API and command line)."""
import contextlib
import math

import numpy as np
import pytest

from peclet.cli import main
from peclet.core.validation import PecletArgumentError
from peclet.packing import Material, RainProtocol, pack, resume
from peclet.packing.bed.api import element_model, resolve_element
from peclet.packing.bed.contact import HertzContact, parse_contact

GLASS = Material(0.3, 0.0, 0.3)
RAIN = RainProtocol(drop=3.0, settle_steps=1500)


def test_units_and_the_rayleigh_rule():
    # 1e7 Pa, 1 mm, 2500 kg/m^3: the pressure unit is rho D x 1 m/s^2 = 2.5 Pa
    law = HertzContact.from_si(1e7, diameter=1e-3, density=2500.0)
    assert law.youngs == pytest.approx(4e6, rel=1e-12)
    assert HertzContact().youngs == law.youngs            # the LAMMPS column's default
    model = element_model(resolve_element("sphere"))
    # the Rayleigh time in bed units equals the physical one over T = sqrt(D / 1 m/s^2)
    g = 1e7 / (2.0 * 1.3)
    tr_si = math.pi * 5e-4 * math.sqrt(2500.0 / g) / (0.1631 * 0.3 + 0.8766)
    assert law.rayleigh_time(model) == pytest.approx(tr_si / math.sqrt(1e-3), rel=1e-12)
    k, sub, tr = law.schedule(model, 2e-3)
    assert sub <= 0.2 * tr < 2e-3 / (k - 1)               # the fewest substeps that meet it
    assert "substeps" in law.describe(model, 2e-3) and f"{k} substeps" in \
        law.describe(model, 2e-3)
    assert parse_contact(None) is None and parse_contact("impulse") is None
    assert parse_contact(law.to_spec()) == law


def _hertz_overlap(force, estar, rstar):
    """Hertz's static overlap under ``force``: F = 4/3 E* sqrt(R*) delta^1.5."""
    return (0.75 * force / (estar * math.sqrt(rstar))) ** (2.0 / 3.0)


@pytest.mark.heavy
def test_a_rained_column_settles_with_hertz_overlaps():
    law = HertzContact()
    res = pack("sphere", "column:4", count=40, protocol=RAIN, material=GLASS, seed=1,
               progress=False, contact=law)
    assert res.complete and res.landed
    assert res.sim.contact_engine.name == "hertz"
    assert res.spec["contact"] == law.to_spec()
    assert res.sim.get_positions()[:, 1].min() > 0.49     # no sphere through the floor
    m = math.pi / 6.0
    e_wall = law.youngs / (1.0 - law.poisson ** 2)        # a sphere on the rigid floor
    e_pair = law.youngs / (2.0 * (1.0 - law.poisson ** 2))
    deepest = res.sim.compute_overlaps()
    # the floor carries the whole weight over at most N contacts: the deepest contact holds
    # at least one sphere's weight; none holds more than the whole bed's
    lo = _hertz_overlap(m * 9.81, e_wall, 0.5)
    hi = _hertz_overlap(40 * m * 9.81, e_pair, 0.25)
    assert 0.9 * lo <= deepest <= hi, (lo, deepest, hi)
    v = np.asarray(res.sim.get_velocities())
    assert float(np.abs(v).max()) < 0.05                  # settled (D/time)


@pytest.mark.heavy
def test_a_hertz_checkpoint_resumes_bit_for_bit(tmp_path):
    kw = dict(count=12, protocol=RainProtocol(drop=2.0, settle_steps=800, calm_steps=30),
              material=GLASS, seed=4, progress=False, contact="hertz")
    full = pack("sphere", "column:3", **kw)
    part = pack("sphere", "column:3", max_steps=170, checkpoint_dir=tmp_path / "c",
                checkpoint_every=80, **kw)
    assert not part.complete
    res = resume(tmp_path / "c", progress=False)
    assert res.complete and res.steps == full.steps
    assert res.sim.contact_engine.name == "hertz"
    assert res.state_hash() == full.state_hash()
    assert res.sim.state_hash() == full.sim.state_hash()


@pytest.mark.parametrize("kw,name", [
    (dict(contact="hooke"), "contact"),
    (dict(contact={"law": "hertz", "youngs": -1.0}), "youngs"),
    (dict(contact={"law": "hertz", "poisson": 0.5}), "poisson"),
    (dict(contact={"law": "hertz", "rayleigh_fraction": 0.31}), "rayleigh_fraction"),
    (dict(contact={"law": "hertz", "young": 1.0}), "contact"),
    (dict(contact="hertz", material=Material(0.0, 0.0, 0.3)), "material.e_n"),
    (dict(contact="hertz", wall_material=Material(0.005, 0.0, 0.3)), "wall_material.e_n"),
    (dict(contact={"law": "hertz", "youngs": 1e14}), "youngs"),
])
def test_pack_refuses_a_bad_contact(kw, name):
    args = dict(count=6, protocol=RAIN, material=GLASS, progress=False, max_steps=0)
    args.update(kw)
    with pytest.raises(PecletArgumentError) as exc:
        pack("sphere", "column:2.5", **args)
    assert exc.value.argument == name


FAST = ["pack", "--element", "sphere", "--container", "column:2.5", "--count", "6",
        "--protocol", "rain", "--quiet"]

BAD = [
    (["--contact", "hooke"], None),                       # argparse's own refusal
    (["--youngs", "1e7Pa"], "--youngs"),                  # without --contact hertz
    (["--contact", "hertz", "--youngs", "-3"], "--youngs"),
    (["--contact", "hertz", "--youngs", "tenPa"], "--youngs"),
    (["--contact", "hertz", "--youngs", "1e20Pa"], "--youngs"),
    (["--contact", "hertz", "--poisson", "0.7"], "--poisson"),
    (["--contact", "hertz", "--rayleigh-fraction", "0.5"], "--rayleigh-fraction"),
    (["--contact", "hertz", "--youngs", "4e6", "--density", "2500"], "--density"),  # bed E
    (["--contact", "hertz", "--youngs", "1e7Pa", "--diameter", "0"], "--diameter"),
    (["--contact", "hertz", "--restitution", "0"], "--restitution"),
    (["--contact", "hertz", "--wall-restitution", "0.001"], "--wall-restitution"),
]


@pytest.mark.parametrize("args,flag", BAD, ids=[f"{b[1]}-{i}" for i, b in enumerate(BAD)])
def test_cli_refuses_bad_hertz_options(tmp_path, capsys, args, flag):
    out = tmp_path / "o"
    with pytest.raises(SystemExit) if flag is None else contextlib.nullcontext():
        code = main(FAST + ["--out", str(out)] + args)
        assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    if flag is not None:
        assert len(err) == 1 and err[0].startswith(f"peclet pack: error: {flag} must be"), err
    assert not out.exists()


def test_cli_refuses_hertz_with_grow_and_with_resume(tmp_path, capsys):
    code = main(["pack", "--element", "sphere", "--protocol", "grow", "--count", "20",
                 "--contact", "hertz", "--out", str(tmp_path / "g"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("peclet pack: error: --contact must be")
    code = main(["pack", "--resume", str(tmp_path), "--contact", "hertz"])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("peclet pack: error: --contact must be")



@pytest.mark.parametrize("keep", [True, False])
def test_an_appended_batch_keeps_the_hertz_histories(keep, monkeypatch):
    # appending a body (insert_bodies, as a rain batch does) keeps the Mindlin springs of the
    # bodies already in (their indices, hence their contact keys, are unchanged); without the
    # hook a change of N clears every history at the next substep
    from peclet.dem import Simulation
    from peclet.packing.bed.containers import parse_container
    from peclet.packing.bed.contact import advance
    from peclet.packing.bed.protocols import Body, insert_bodies, new_simulation

    if not keep:
        monkeypatch.setattr(Simulation, "keep_contact_histories", lambda self: None)
    model = element_model(resolve_element("sphere"))
    cont = parse_container("box:6").bound(1.0)
    sim, sid = new_simulation(model.register, cont, GLASS, GLASS, (10, 8), 9.81, 2e-3, 20.0, 2)
    body = Body(sid, model.mass, model.inv_inertia, model.bounding_radius, 1.0)
    HertzContact().configure(sim, model, 2e-3)
    q = np.array([[0.0, 0.0, 0.0, 1.0]])
    insert_bodies(sim, body, np.array([[1.0, 0.49989, 1.0]]), q, np.array([[1.0, 0.0, 0.0]]))
    for _ in range(5):
        advance(sim, 2e-3)
    hz = sim.world.hertz
    keys, xi = hz.keys.copy(), hz.xi.copy()
    assert len(keys) == 1 and np.linalg.norm(xi) > 0.0      # the sliding sphere's spring
    insert_bodies(sim, body, np.array([[4.0, 5.0, 4.0]]), q, np.zeros((1, 3)))
    assert (hz.n_bodies == 2) is keep
    np.testing.assert_array_equal(hz.keys, keys)
    np.testing.assert_array_equal(hz.xi, xi)


@pytest.mark.heavy
@pytest.mark.xfail(strict=True, reason="composed elements under pack(contact='hertz'): a "
                   "rained Raschig ring meets the floor with a distributed contact deeper than "
                   "DIST_DEEP_LIMIT within the first steps (HertzPatchError 'body 0 against "
                   "wall 0'); the patch path is not yet fit for rained rings")
def test_rained_raschig_rings_under_hertz():
    from peclet.dem.hertz import HertzPatchError

    try:
        res = pack("raschig_ring", "column:3", count=3, protocol=RainProtocol(
            drop=0.5, insert_every=1), material=GLASS, seed=1, progress=False,
            contact="hertz", max_steps=60)
    except HertzPatchError as exc:
        pytest.fail(str(exc))
    assert res.steps == 60
