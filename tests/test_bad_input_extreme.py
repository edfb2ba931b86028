"""Extreme finite numbers (issue 45, class 3): radii of 1e300 or 1e-300, scales of 1e-300, wall
angular speeds of 1e300, inverse masses that overflow when inverted... are refused by the
setter that receives them, naming the argument and the accepted range
(:mod:`peclet.dem.limits`), instead of failing later as an overflow, a "math domain error" or
an error about an internal array; a step's error names the user's input; on the command line
each is one ``error:`` line and exit code 2. In-range extremes keep working."""
import subprocess
import sys

import numpy as np
import pytest

from peclet.cli import main
from peclet.core import geom
from peclet.core.validation import PecletArgumentError
from peclet.dem import Simulation
from peclet.dem.guards import StepError
from peclet.dem import limits as L
from peclet.packing.bed.elements import parse_element


def _two(r=0.5):
    sim = Simulation(2)
    sim.add_sphere_shape(r)
    sim.set_positions([[0.0, 0.0, 0.0], [3.0 * r, 0.0, 0.0]])
    return sim


def _walled(r=0.5):
    sim = _two(r)
    b = geom.SceneBuilder()
    root = b.add_leaf("box", [5.0, 0.5, 5.0], translation=[0.0, -2.0, 0.0])
    ni, nr, _, _ = b.encode()
    sim.add_analytic_wall(ni, nr, root, False, 0.5, 0.5)
    return sim


def _scene_args(bounding_radius):
    b = geom.SceneBuilder()
    root = b.add_leaf("sphere", [0.3])
    ni, nr, _, _ = b.encode()
    return ni, nr, root, [[0.3, 0.0, 0.0], [0.0, 0.3, 0.0]], bounding_radius


def _scales_after(inv_mass, scale):
    sim = _two()
    sim.set_inv_mass(inv_mass)
    sim.set_scales([1.0, scale])


def _subnormal():
    return float(np.nextafter(0.0, 1.0) * 2 ** 20)          # ~5e-318, a subnormal


# (call on a fresh two-sphere simulation, the argument the error must name, a phrase)
SETTER_CASES = [
    ("radius 1e300", lambda s: s.add_sphere_shape(1e300), "radius", "[1e-100, 1e+100]"),
    ("radius 1e-300", lambda s: s.add_sphere_shape(1e-300), "radius", "r^3 and r^5"),
    ("radius subnormal", lambda s: s.add_sphere_shape(1e-310), "radius", "[1e-100"),
    ("radius 1e7 beside 0.5", lambda s: s.add_sphere_shape(1e7), "radius", "factor 1e+06"),
    ("radius 1e-7 beside 0.5", lambda s: s.add_sphere_shape(1e-7), "radius", "factor 1e+06"),
    ("scene bounding radius 1e300", lambda s: s.add_scene_shape(*_scene_args(1e300)),
     "bounding_radius", "[1e-100, 1e+100]"),
    ("scene bounding radius 1e10", lambda s: s.add_scene_shape(*_scene_args(1e10)),
     "bounding_radius", "factor"),
    ("scales 1e-300", lambda s: s.set_scales([1.0, 1e-300]), "scales", "at least 1e-06"),
    ("scales subnormal", lambda s: s.set_scales([_subnormal(), 1.0]), "scales", "(0, 1000]"),
    ("uniform scale 1e-300", lambda s: s.set_scales_uniform(1e-300), "scale", "1e-06"),
    ("scale whose inverse mass overflows", lambda s: _scales_after([1.0, 1e99], 0.01),
     "scales", "inverse mass the scale implies"),
    ("inv_mass 1e-320", lambda s: s.set_inv_mass([1e-320, 1.0]), "inv_mass", "0 or in"),
    ("inv_mass 1e300", lambda s: s.set_inv_mass([1.0, 1e300]), "inv_mass", "body 1"),
    ("inv_inertia 1e300", lambda s: s.set_inv_inertia([[1.0] * 3, [1.0, 1e300, 1.0]]),
     "inv_inertia", "1e+100]"),
    ("inv_inertia 1e-320", lambda s: s.set_inv_inertia([[1e-320] * 3, [1.0] * 3]),
     "inv_inertia", "[1e-100"),
    ("velocity 1e300", lambda s: s.set_velocities([[1e300, 0, 0], [0, 0, 0]]), "velocities",
     "norm <= 1e+100"),
    ("velocity whose square overflows", lambda s: s.set_velocities([[0, 0, 0], [1e200] * 3]),
     "velocities", "row 1"),
    ("angular velocity 1e300", lambda s: s.set_angular_velocities([[0, 0, 1e300], [0] * 3]),
     "angular_velocities", "rad/time"),
    ("position 1e300", lambda s: s.set_positions([[1e300, 0, 0], [0, 0, 0]]), "positions",
     "magnitude <= 1e+100"),
    ("domain 1e300", lambda s: s.set_domain([-1e300] * 3, [1e300] * 3), "lo", "1e+100"),
    ("domain side 1e-300", lambda s: s.set_domain([0.0] * 3, [1e-300] * 3), "hi",
     "at least 1e-100"),
    ("dt 1e-300", lambda s: s.set_dt(1e-300), "dt", "[1e-100, 1e+100]"),
    ("dt 1e300", lambda s: s.set_dt(1e300), "dt", "[1e-100, 1e+100]"),
    ("dt subnormal", lambda s: s.set_dt(1e-320), "dt", "time step"),
    ("step dt 1e-300", lambda s: s.step(1e-300), "dt", "[1e-100"),
    ("wall angular 1e300", lambda s: s.set_wall_velocity(0, angular=(0, 0, 1e300)), "angular",
     "rad/time"),
    ("wall angular 1e200", lambda s: s.set_wall_velocity(0, angular=(1e200, 0, 0)), "angular",
     "norm <= 1e+100"),
    ("wall linear 1e300", lambda s: s.set_wall_velocity(0, linear=(1e300, 0, 0)), "linear",
     "length/time"),
    ("wall centre 1e300", lambda s: s.set_wall_velocity(0, (0, 0, 0), (0, 0, 1.0),
                                                        (1e300, 0, 0)), "center", "1e+100"),
    ("wall translation 1e300", lambda s: s.set_wall_transform(0, (0, 1e300, 0)),
     "translation", "1e+100"),
]


@pytest.mark.parametrize("call,argument,phrase", [c[1:] for c in SETTER_CASES],
                         ids=[c[0] for c in SETTER_CASES])
def test_a_setter_refuses_an_extreme_number_naming_it(call, argument, phrase):
    sim = _walled()
    before = sim.state_hash(), sim.get_inv_mass().tolist(), sim.get_scales().tolist()
    with pytest.raises(PecletArgumentError) as ex:
        call(sim)
    assert ex.value.argument == argument
    assert str(ex.value).startswith(f"{argument} must be"), str(ex.value)
    assert phrase in str(ex.value), str(ex.value)
    assert (sim.state_hash(), sim.get_inv_mass().tolist(), sim.get_scales().tolist()) == before


def test_a_refused_scale_changes_no_mass():
    sim = _two()
    sim.set_inv_mass([1.0, 1e99])
    with pytest.raises(PecletArgumentError, match="^scales"):
        sim.set_scales([1.0, 0.01])
    assert sim.get_inv_mass().tolist() == [1.0, 1e99]
    assert sim.get_scales().tolist() == [1.0, 1.0]


def test_a_scale_whose_radius_leaves_the_size_ratio_is_refused():
    sim = _two()
    sim.add_sphere_shape(100.0)                 # radii [0.5, 100] in use
    with pytest.raises(PecletArgumentError, match=r"^scales .*factor 1e\+06") as ex:
        sim.set_scales([1e-5, 1.0])             # 5e-6 against 100: a ratio of 2e7
    assert "body 0" in str(ex.value)


def test_a_fast_wall_is_refused_when_the_step_starts_naming_the_wall():
    sim = _walled()
    sim.set_wall_velocity(0, angular=(0.0, 0.0, 1e50))     # within the setter's bound
    with pytest.raises(PecletArgumentError) as ex:
        sim.step(1e-3)
    msg = str(ex.value)
    assert msg.startswith("wall 0's velocity (set_wall_velocity) must be a surface speed"), msg
    assert "speed bound" in msg and "inv_inertia_body" not in msg
    assert sim.step_count == 0


def test_a_stepped_overflow_names_the_gravity_not_an_internal_array():
    sim = _two()
    sim.set_gravity(0.0, -1e300, 0.0)           # any finite gravity is accepted
    with pytest.raises(StepError) as ex:
        sim.step(1e-3)
    msg = str(ex.value)
    assert msg.startswith("step 1: particle 0 moves at 1e+297"), msg   # not "inf"
    assert "set_gravity" in msg and "dt = 0.001" in msg
    assert sim.step_count == 0


def test_a_stepped_speed_is_reported_without_overflow():
    sim = _two()
    sim.set_velocities([[0.0, 0.0, 0.0], [5e99, 0.0, 0.0]])       # |v| <= 1e100: accepted
    with pytest.raises(StepError, match=r"particle 1 moves at 5e\+99 > the bound"):
        sim.step(1e-3)


# ------------------------------------------------------------------ in range still works
@pytest.mark.parametrize("r", [1e-6, 1e6])
def test_in_range_extreme_radii_step(r):
    sim = _two(r)
    sim.set_velocities([[r, 0.0, 0.0], [-r, 0.0, 0.0]])     # one radius per unit time
    sim.set_dt(1e-3)
    for _ in range(3):
        sim.step()
    assert np.all(np.isfinite(sim.get_positions()))
    assert sim.step_count == 3


def test_the_bounds_themselves_are_accepted():
    sim = _two()
    sim.set_inv_mass([L.MIN_INVERSE, L.MAX_INVERSE])
    sim.set_inv_inertia([[0.0, L.MIN_INVERSE, 1.0], [L.MAX_INVERSE, 0.0, 1.0]])
    sim.set_dt(L.MIN_DT)
    sim.set_dt(L.MAX_DT)
    sim.set_velocities([[L.MAX_SPEED, 0, 0], [0, 0, 0]])
    sim.set_domain([-L.MAX_LENGTH] * 3, [L.MAX_LENGTH] * 3)
    s = Simulation()
    assert s.add_sphere_shape(L.MIN_LENGTH) == 0
    t = Simulation()
    assert t.add_sphere_shape(L.MAX_LENGTH) == 0
    u = _two()
    u.set_inv_mass([1.0, 1.0])
    u.set_scales([L.MIN_SCALE, 1.0])
    assert u.get_inv_mass()[0] == pytest.approx(1e18)


# ------------------------------------------------------------------ the command line
CLI_CASES = [
    (["pack", "--element", "sphere:radius=1e300"], "--element", "[1e-06, 1e+06]"),
    (["pack", "--element", "sphere:radius=1e-300"], "--element", "radius = 1e-300"),
    (["pack", "--element", "pall_ring:height=1e300"], "--element", "height = 1e+300"),
    (["pack", "--element", "pall_ring:thickness=1e-300"], "--element", "thickness"),
    (["pack", "--element", "solid_cylinder:height=1e-4"], "--element", "factor 1000"),
    (["pack", "--element", "raschig_ring:r_outer=1e-300,height=1e-300,thickness=1e-301"],
     "--element", "r_outer = 1e-300"),
    (["pack", "--container", "box:1e300"], "--container", "[1.5, 10000]"),
    (["pack", "--container", "column:1e300"], "--container", "[1.5, 10000]"),
    (["pack", "--protocol", "rain", "--drop", "1e300"], "--drop", "[0, 10000]"),
    (["drum", "--rpm", "1e-300"], "--rpm", "Froude number in (0, 100]"),
    (["pack", "--protocol", "grow", "--rate", "1e-300"], "--rate", ">= 0.0001"),
    (["stir", "--omega", "1e-300"], "--omega", "e+297 days"),        # not "inf days"
    (["drum", "--froude", "1", "--element", "berl_saddle:R=1e300,r=1e299"], "--element",
     "R = 1e+300"),
]


@pytest.mark.parametrize("argv,option,phrase", CLI_CASES, ids=[" ".join(c[0]) for c in CLI_CASES])
def test_the_command_line_prints_one_line_and_exits_2(tmp_path, capsys, argv, option, phrase):
    out = tmp_path / "run"
    rc = main(argv + ["--out", str(out)])
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert rc == 2, err
    assert len(lines) == 1, err
    assert lines[0].startswith(f"peclet {argv[0]}: error: {option} must"), err
    assert phrase in lines[0], err
    assert not out.exists()


@pytest.mark.parametrize("argv,option", [
    (["pack", "--element", "sphere:radius=1e300"], "--element"),
    (["pack", "--container", "column:1e300"], "--container"),
    (["drum", "--rpm", "1e-300"], "--rpm"),
])
def test_through_a_real_interpreter_no_traceback(tmp_path, argv, option):
    out = tmp_path / "run"
    r = subprocess.run([sys.executable, "-m", "peclet.cli"] + argv + ["--out", str(out)],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert lines[0].startswith(f"peclet {argv[0]}: error: {option} must"), r.stderr


@pytest.mark.parametrize("text", ["sphere:radius=1e-6", "sphere:radius=1e6",
                                  "raschig_ring:r_outer=1e-3,height=2e-3,thickness=2.4e-4"])
def test_in_range_element_lengths_are_accepted(text):
    kind, params = parse_element(text, "--element")
    assert kind in text and params


# ------------------------------------------------------------------ composed particles
def _small_solid():
    b = geom.SceneBuilder()
    return b, b.add_leaf("sphere", [0.3])


@pytest.mark.parametrize("bounds", [([-1e300] * 3, [1e300] * 3), ([0.0] * 3, [1e-300] * 3)])
def test_scene_particle_refuses_extreme_bounds_before_measuring(bounds):
    from peclet.dem import scene_particle

    b, root = _small_solid()
    with pytest.raises(PecletArgumentError, match=r"^bounds must be a box with coordinates"):
        scene_particle.build(b, root, bounds=bounds)


@pytest.mark.heavy
@pytest.mark.parametrize("density", [1e300, 1e-300])
def test_scene_particle_refuses_a_density_whose_mass_leaves_float64(density):
    from peclet.dem import scene_particle

    b, root = _small_solid()
    with pytest.raises(PecletArgumentError, match=r"^density must be a density giving") as ex:
        scene_particle.build(b, root, bounds=([-0.4] * 3, [0.4] * 3), n=8, shell_resolution=16,
                             target_shell_points=64, tol=1e-4, density=density)
    assert "mass" in str(ex.value)
