"""Issue 45, class 5: input that was accepted and answered wrong. Each case is now refused up
front (PecletArgumentError naming the argument and the reason) or flagged as documented, and
the in-range call next to it answers as before.

- a pour that ends with bodies still in the air (``protocols.in_air``, the landing rule);
- a radial profile about a centre outside the bed (``profiles.check_column_holds_bed``);
- an unbounded half-space as a particle (``scene_particle.check_bounded``);
- a drum of too few grains for a regime (``drum.MIN_GRAINS``);
- gravity that points away from the floor a protocol builds on (``protocols.check_gravity``,
  ``freeze.pack_to_simulation``).
"""
import math
import warnings

import numpy as np
import pytest

from peclet.cli import main
from peclet.core import geom
from peclet.core.validation import PecletArgumentError
from peclet.packing import Material, RainProtocol, pack
from peclet.packing.analysis import profiles as P
from peclet.packing.bed.api import landing_message
from peclet.packing.bed.containers import parse_container
from peclet.packing.bed.elements import sphere
from peclet.packing.bed.freeze import Pack
from peclet.packing.bed.protocols import (AIR_GAP, LandingWarning, check_gravity, in_air,
                                          new_simulation)
from peclet.packing.experiments.drum import (MIN_GRAINS, Drum, DrumSpec, classify,
                                             grain_count)

A = 0.5


def sphere_pack(pos, box=(50.0, 50.0)):
    """A pack of spheres of radius A at ``pos`` (the profiles tests' helper, with a shell,
    mass and inertia so that ``pack_to_simulation`` takes it)."""
    el = sphere(A)
    ni, nr, _, _ = el.builder.encode()
    pos = np.asarray(pos, float)
    return Pack(pos, np.tile([0.0, 0.0, 0.0, 1.0], (len(pos), 1)), box, el.envelope_volume,
                ni, nr, el.root, A, A * np.vstack([np.eye(3), -np.eye(3)]), 0.52,
                [1.0, 1.0, 1.0], el.envelope_root, el.envelope_volume)


def _refused(exc, argument, *words):
    assert exc.value.argument == argument, str(exc.value)
    for w in words:
        assert w in str(exc.value), str(exc.value)


# ---------------------------------------------------------------- (a) a pour still in the air
def test_in_air_finds_the_bodies_no_chain_links_to_the_floor():
    cont = parse_container("column:6")
    # a stack of three on the floor, one resting on the wall of nothing (floating), and a
    # pair floating together
    P0 = np.array([[3.5, 0.5, 3.5], [3.5, 1.5, 3.5], [3.5, 2.5, 3.5],
                   [2.0, 6.0, 2.0], [5.0, 9.0, 5.0], [5.0, 10.0, 5.0]])
    assert in_air(P0, 0.5, 1.0, cont).tolist() == [False] * 3 + [True] * 3
    # a body within the gap of a supported one is supported; just beyond it is not
    near = np.array([[3.5, 0.5, 3.5], [3.5, 1.5 + 0.99 * AIR_GAP, 3.5]])
    far = np.array([[3.5, 0.5, 3.5], [3.5, 1.5 + 1.01 * AIR_GAP, 3.5]])
    assert not in_air(near, 0.5, 1.0, cont).any()
    assert in_air(far, 0.5, 1.0, cont).tolist() == [False, True]
    assert in_air(np.zeros((0, 3)), 0.5, 1.0, cont).shape == (0,)


def test_in_air_links_bodies_across_the_periodic_box():
    cont = parse_container("box:3").bound(1.0)
    # body 1 rests on body 0 through the boundary x = 0 = 3 (its image at x = 3.2)
    P0 = np.array([[0.1, 0.5, 1.0], [2.95, 1.45, 1.0]])
    assert not in_air(P0, 0.5, 1.0, cont).any()
    assert in_air(P0, 0.5, 1.0, parse_container("walled:3,3").bound(1.0)).tolist() == \
        [False, True]


def test_the_landing_message_names_the_bodies_in_the_air():
    rec = dict(step=3, bodies=6, moving=0, max_speed=0.04, threshold=1.0, fall_time=None,
               landing_time=None, landed=False, in_air=6, air_step=203, air_gap=AIR_GAP,
               air_top=29.6)
    msg = landing_message(rec)
    assert "6 of 6 elements were still in the air when the run ended at step 203" in msg
    assert msg.startswith("the bed did not land")


@pytest.mark.heavy
def test_a_pour_that_ends_in_the_air_is_flagged_and_a_landed_one_is_not():
    # one batch inserted at rest 30 D up and quenched at once: at the quench's start the
    # bodies fall at 0.04 D/time (under the speed rule), and the quench holds them near 0.5
    # D/time, so the run ends with every body about 29 D in the air. Before: landed True.
    proto = RainProtocol(batch=6, speed=0.0, settle_steps=0)
    with pytest.warns(LandingWarning, match="still in the air"):
        res = pack("sphere", "column:8", count=6, protocol=proto, seed=1, progress=False)
    rec = res.state.landing
    assert res.landed is False and rec["moving"] == 0 and rec["in_air"] == 6
    assert rec["air_top"] > 20.0 and rec["air_step"] == res.steps
    with warnings.catch_warnings():
        warnings.simplefilter("error", LandingWarning)
        ok = pack("sphere", "column:3", count=8, protocol=RainProtocol(
            drop=3.0, settle_steps=3000, calm_steps=20, quench_steps=20),
            material=Material(e_n=0.3, e_t=0.0, mu=0.3), seed=2, progress=False)
    assert ok.landed is True and ok.state.landing["in_air"] == 0


# ---------------------------------------------------------------- (b) a centre outside the bed
BED = [[0.0, 0.5, 0.0], [0.6, 0.5, 1.0], [-1.0, 0.5, 0.3], [1.2, 1.4, -0.8]]


@pytest.mark.parametrize("centre", [(20.0, 20.0), (-6.0, 0.0), (0.0, 4.0)])
def test_a_radial_profile_about_a_centre_outside_the_bed_is_refused(centre):
    with pytest.raises(PecletArgumentError) as exc:
        P.radial_profile(sphere_pack(BED), 2.0, centre, 0.0, 2.0, samples_per_shell=50)
    _refused(exc, "center_xz", "holds the bed", "wholly outside", "every shell would read eps = 1")


def test_a_column_that_leaves_part_of_the_bed_outside_is_refused():
    # the axis 1.5 D off the bed's: element 2 lies wholly outside the column of radius 2
    with pytest.raises(PecletArgumentError) as exc:
        P.radial_profile(sphere_pack(BED), 2.0, (1.5, 0.0), 0.0, 2.0, samples_per_shell=50)
    _refused(exc, "center_xz", "1 of 4 elements in the span lie wholly outside", "element 2")
    assert "every shell" not in str(exc.value)


@pytest.mark.parametrize("span", [(5.0, 6.0), (-3.0, -1.0)])
def test_a_radial_profile_over_a_span_without_the_bed_is_refused(span):
    with pytest.raises(PecletArgumentError) as exc:
        P.radial_profile(sphere_pack(BED), 2.0, (0.0, 0.0), *span, samples_per_shell=50)
    _refused(exc, "y_lo", "meets the bed")


def test_the_radial_profile_of_a_bed_in_its_column_is_as_before():
    # every element inside the column: measured as before
    prof = P.radial_profile(sphere_pack(BED), 2.0, (0.0, 0.0), 0.0, 2.0, samples_per_shell=50,
                            seed=4)
    assert prof["eps"].min() < 1.0 and len(prof["z"]) == 100
    edge = sphere_pack([[2.0 + A - 1e-9, 0.5, 0.0]])      # reaching into the column
    P.radial_profile(edge, 2.0, (0.0, 0.0), 0.0, 1.0, samples_per_shell=10)


# ---------------------------------------------------------------- (c) an unbounded particle
def _build(b, root):
    from peclet.dem import scene_particle

    return scene_particle.build(b, root, bounds=([-0.5] * 3, [0.5] * 3), n=8,
                                shell_resolution=16, target_shell_points=64, tol=1e-4)


def test_a_half_space_is_refused_as_a_particle():
    b = geom.SceneBuilder()
    h = b.add_leaf("half_space", [0.0, 1.0, 0.0, 0.0])
    with pytest.raises(PecletArgumentError) as exc:
        _build(b, h)
    _refused(exc, "root", "bounded solid", "radius is inf", "half_space leaf is unbounded")


def test_a_union_with_a_far_half_space_is_refused_not_measured_as_its_sphere():
    # before: accepted, measured as the sphere inside the bounds, bounding radius inf
    b = geom.SceneBuilder()
    u = b.add_union(b.add_leaf("sphere", [0.3]), b.add_leaf("half_space", [0, -1, 0, -5.0]))
    with pytest.raises(PecletArgumentError) as exc:
        _build(b, u)
    _refused(exc, "root", "bounded solid", "a union with one is too")


def test_a_half_space_on_the_left_of_an_intersection_is_refused_with_the_cure():
    b = geom.SceneBuilder()
    s, h = b.add_leaf("sphere", [0.3]), b.add_leaf("half_space", [0, 1, 0, 0.1])
    with pytest.raises(PecletArgumentError) as exc:
        _build(b, b.add_intersection(h, s))
    _refused(exc, "root", "put the bounded operand on the left")
    # the same solid written the other way round is bounded and measured
    sp = _build(b, b.add_intersection(s, h))
    assert math.isfinite(sp.bounding_radius) and 0.0 < sp.volume < 4 / 3 * math.pi * 0.3 ** 3


def test_pack_refuses_an_unbounded_element():
    b = geom.SceneBuilder()
    h = b.add_leaf("half_space", [0, 1, 0, 0.0])
    with pytest.raises(PecletArgumentError) as exc:
        pack((b, h), "box:3.5", count=4, progress=False)
    _refused(exc, "element", "a bounded solid")


# ---------------------------------------------------------------- (d) a drum of one grain
ONE = dict(radius=3, length=2, fill=0.01, froude=0.01)


def test_a_drum_of_one_grain_is_refused_before_work():
    d = Drum(DrumSpec(**ONE).checked())
    assert d.count == 1
    with pytest.raises(PecletArgumentError) as exc:
        d.check_room()
    _refused(exc, "fill", f"at least {MIN_GRAINS} grains", "1 grain in a drum of radius 3 D",
             "no regime to classify")


def test_the_fewest_grains_a_drum_takes():
    def spec(fill):
        return DrumSpec(**dict(ONE, fill=fill)).checked()

    fills = np.linspace(0.01, 0.2, 400)
    counts = [grain_count(spec(f), Drum(spec(f)).grains) for f in fills]
    below = fills[counts.index(MIN_GRAINS) - 1]
    at = fills[counts.index(MIN_GRAINS)]
    with pytest.raises(PecletArgumentError, match=f"at least {MIN_GRAINS} grains"):
        Drum(spec(below)).check_room()
    Drum(spec(at)).check_room()


def test_peclet_drum_refuses_a_fill_of_too_few_grains(tmp_path, capsys):
    out = tmp_path / "run"
    rc = main(["drum", "--out", str(out), "--froude", "0.01", "--fill", "0.01", "--radius", "3",
               "--length", "2", "--quiet"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "\n" not in err and "--fill must be a fill of at least" in err, err
    assert not out.exists()


def test_classify_calls_a_bed_of_too_few_grains_undetermined():
    rest = dict(coverage=0.03, corotating=1.0, airborne=0.0, flowing=0.0, s_shape=math.nan,
                high=0.0)
    assert classify([rest] * 5)[0] == "slumping"                 # unchanged without a count
    assert classify([rest] * 5, grains=MIN_GRAINS)[0] == "slumping"
    regime, crit = classify([rest] * 5, grains=1)
    assert regime == "undetermined" and crit == dict(grains=1, min_grains=MIN_GRAINS)


# ---------------------------------------------------------------- (e) gravity pointing up
@pytest.mark.parametrize("g", [-9.81, 0.0, math.inf, math.nan, "9.81", True, None])
def test_a_gravity_magnitude_away_from_the_floor_is_refused(g):
    with pytest.raises(PecletArgumentError) as exc:
        check_gravity(g)
    _refused(exc, "gravity", "a finite number > 0", "towards the floor")
    if isinstance(g, float) and math.isfinite(g):
        assert "points up" in str(exc.value)


def test_pour_and_new_simulation_refuse_gravity_up_before_any_work():
    from peclet.packing.bed.pour import pour

    with pytest.raises(PecletArgumentError) as exc:
        pour(object(), n=4, gravity=-9.81, progress=False)      # not a particle: never read
    _refused(exc, "gravity", "points up")
    with pytest.raises(PecletArgumentError, match="gravity must be"):
        new_simulation(None, parse_container("box:3"), Material(), Material(), (10, 8), -9.81,
                       2e-3, 60.0, 4)
    assert check_gravity(9.81) == 9.81


@pytest.mark.parametrize("g", [(0.0, 9.81, 0.0), (0.0, 0.0, 0.0), (9.81, 0.0, 0.0)])
def test_pack_to_simulation_refuses_gravity_that_leaves_the_floor(g):
    from peclet.packing.bed.freeze import pack_to_simulation

    with pytest.raises(PecletArgumentError) as exc:
        pack_to_simulation(sphere_pack([[1.0, 0.5, 1.0]], box=(3.5, 3.5)), gravity=g)
    _refused(exc, "gravity", "towards the floor", "floor=False")


def test_pack_to_simulation_keeps_its_gravity_where_it_is_valid():
    from peclet.packing.bed.freeze import pack_to_simulation

    pk = sphere_pack([[1.0, 0.5, 1.0]], box=(3.5, 3.5))
    sim, _ = pack_to_simulation(pk)
    assert sim.world.gravity.tolist() == [0.0, -9.81, 0.0]
    sim, _ = pack_to_simulation(pk, gravity=(1.0, -9.0, 0.0))          # a tilt is taken
    assert sim.world.gravity.tolist() == [1.0, -9.0, 0.0]
    sim, _ = pack_to_simulation(pk, gravity=(0.0, 9.81, 0.0), floor=False)
    assert sim.world.gravity.tolist() == [0.0, 9.81, 0.0]
    with pytest.raises(PecletArgumentError, match="floor must be"):
        pack_to_simulation(pk, floor="yes")
