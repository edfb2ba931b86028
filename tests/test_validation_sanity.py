"""The DEM sanity scorecard (validation/sanity.py), one test per item, reduced where the full
case is slow: the deep bed runs 3 x 3 x 40 instead of 5 x 5 x 40 (its columns carry no load
sideways, so each column's figures are the same), the drop and the incline fewer cases.
Units: m, s, kg, g = 9.81 m/s^2. Single-threaded (the engine's state is bitwise the same at any
thread count)."""
import math

import pytest

from validation import sanity


@pytest.fixture(autouse=True)
def one_thread():
    with sanity.numba_threads(1):
        yield


def _check(rows):
    for r in rows:
        assert r["passed"], (f"{r['case']}: ours {r['ours']!r}, expected {r['expected']!r}, "
                             f"error {r['error']:.3g} > tol {r['tol']:.3g} ({r['tol_basis']})")


@pytest.mark.parametrize("e", [0.0, 0.25, 0.5, 0.75, 1.0])
def test_binary_restitution(e):
    [r] = sanity.item_binary(es=(e,))
    _check([r])
    assert r["momentum_error"] < 1e-12


# A drop from 1 m at dt = 2e-4 reaches the floor at a phase where the contact would end the
# last approach step within the slop (5e-4 r) of the floor: before the solver counted such a
# contact as an impact, the speculative bound stopped the sphere at the slop with the speed
# (gap - slop) / dt and restitution acted on what was left (apex ratio 0.1753 for 0.25).
# All 8 impact phases at e = 0.7 are checked too (item_drop's phases).
def test_drop_bounce_on_a_plane():
    _check(sanity.item_drop(es=(0.5,), surfaces=("plane",), phases=0))


def test_drop_bounce_on_a_csg_floor():
    _check(sanity.item_drop(es=(0.9,), surfaces=("csg",), phases=0))


@pytest.mark.heavy
def test_drop_bounce_at_every_impact_phase():
    _check(sanity.item_drop(es=(0.7,), surfaces=("plane",), phases=8))


def test_slide_to_roll():
    rows = sanity.item_slide_to_roll(mus=(0.5,))
    _check(rows)
    assert rows[0]["expected"] == pytest.approx(3.0 * 5 / 7)
    assert rows[1]["expected"] == pytest.approx(2 * 3.0 / (7 * 0.5 * sanity.G))
    assert abs(rows[0]["omega_r"] - rows[0]["ours"]) < 1e-9   # rolling: v = omega r
    assert abs(rows[0]["height_error"]) < 1e-6


def test_static_column_of_six():
    _check(sanity.item_column())


def test_spin_with_friction():
    rows = sanity.item_spin()
    _check(rows)
    assert rows[0]["expected"] == pytest.approx(2 / 7 * 3.0)     # topspin: 2/7 omega0 r
    assert rows[2]["expected"] == pytest.approx(-5 / 7)           # the draw shot comes back


def test_deep_bed_comes_to_rest_without_sinking():
    rows = sanity.item_deep_bed(nx=3)
    _check(rows)
    assert rows[2]["expected"] == 79.0                            # 40 layers x 2 - r


def test_incline_stick_slip_and_kinetic_slide():
    rows = sanity.item_incline(sticks=(0.4,), slides=(0.33, 0.2))
    _check(rows)
    th = math.radians(20.0)
    assert 0.33 < math.tan(th) < 0.4                              # the gate is straddled
    assert rows[-1]["expected"] == pytest.approx(sanity.G * (math.sin(th)
                                                             - 0.2 * math.cos(th)))
    assert rows[-1]["slid"] > 0.5                                 # it really slides
    assert max(r.get("max_omega", 0.0) for r in rows) < 1e-2     # slides, does not tumble
