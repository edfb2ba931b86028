"""Silo discharge (validation/silo.py) at a reduced size, against Beverloo's law.

The reduced case: one silo of Ds = 12.5 d (spheres 0.9-1.1 d, mu = 0.5, e = 0.4, dt = 4e-3,
the impulse engine, one thread), one settled fill (~1040 grains) shared by two orifices D0 = 5 d
and 6 d (Ds / D0 = 2.5 and 2.1), a head of only 3 d left at the window's end (the full run
keeps Ds, Janssen) and a window of 1.5 d of fill (about 350 grains per orifice). About 45 s of
CPU warm (measured: 45 s user, 170 s wall on a machine loaded 3-4x).

What is asserted, and why the tolerances are what they are:

- steady: the slopes of the window's two halves differ by less than 30% of the rate, and M(t)
  never leaves the fitted line by more than 5% of the window's mass. The rate of a silo this
  small fluctuates: the slopes of a window's four blocks (~90 grains each) scatter by 8-10%
  (one standard deviation, seen in this case and in the full run), so a half-slope
  difference scatters by ~10% and the full run's windows show -17% to +9%: 30% is 3 sigma. A
  clog (no rate at all) or a window still in the start-up fails it; a 5% line deviation is a
  burst or a stall of a tenth of the window.
- the rate grows with the orifice (more than 1.3 times from 5 to 6 d: Beverloo says 1.87).
- the ratio W(6) / W(5), each per its bulk density (the same bed here), is within 20% of
  Beverloo's ((6 - 1.5) / (5 - 1.5))^(5/2) = 1.874. The statistical part: each rate's standard
  error from four blocks is ~4-5%, so the ratio's is ~7%; 20% is 3 sigma. Beverloo's k is
  itself uncertain (k from 1 to 2 moves this ratio from 1.71 to 2.08), and the full run (each
  orifice in its own 2.5 D0 silo, head Ds) finds -8% for this pair. The tolerance is set from
  the scatter, not from our result (+0.6% at seed 1).
"""
import math

import numba
import pytest

from validation import silo

pytestmark = pytest.mark.heavy      # the heavy tier (conftest.py: --tier)


@pytest.fixture(scope="module")
def runs():
    old = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        return {D0: silo.discharge(D0, window=1.5, Ds=12.5, head=3.0, seed=1)
                for D0 in (5.0, 6.0)}
    finally:
        numba.set_num_threads(old)


def test_beverloo_formulas():
    # W = C rho_b sqrt(g) (D0 - k d)^(5/2) and its ratio, by hand
    assert silo.beverloo(6.0, 0.6) == pytest.approx(0.58 * 0.6 * math.sqrt(9.81) * 4.5 ** 2.5)
    assert silo.beverloo_ratio(6.0, 5.0) == pytest.approx((4.5 / 3.5) ** 2.5)
    # the fit recovers C and k from exact Beverloo points
    D0s = [5.0, 6.0, 8.0]
    W = [silo.beverloo(D, 0.6, C=0.5, k=2.0) for D in D0s]
    C, k = silo.fit_beverloo(D0s, W, [0.6] * 3)
    assert C == pytest.approx(0.5, rel=1e-9) and k == pytest.approx(2.0, rel=1e-9)
    # the slab volume of a sphere is exact: whole, half, and a cap of height r/2
    assert silo.sphere_slab_volume([0.0], 0.5, -1.0, 1.0)[0] == pytest.approx(math.pi / 6)
    assert silo.sphere_slab_volume([0.0], 0.5, 0.0, 1.0)[0] == pytest.approx(math.pi / 12)
    assert silo.sphere_slab_volume([0.0], 0.5, 0.25, 1.0)[0] == pytest.approx(
        math.pi * 0.25 ** 2 * (3 * 0.5 - 0.25) / 3)


def test_bad_input_is_refused():
    with pytest.raises(silo.PecletArgumentError, match="D0"):
        silo.discharge(1.0)
    with pytest.raises(silo.PecletArgumentError, match="D0s"):
        silo.fit_beverloo([5.0, 5.0], [1.0, 1.0], [0.6, 0.6])


def test_discharge_is_steady(runs):
    for D0, r in runs.items():
        assert not r["clogged"] and r["W"] is not None, (D0, r["time"])
        assert abs(r["half_diff"]) < 0.30, (D0, r["half_slopes"], r["block_slopes"])
        assert r["max_dev"] < 0.05, (D0, r["max_dev"])
        assert 0.55 < r["phi_b"] < 0.65, r["phi_b"]       # a poured random bed


def test_rate_grows_with_the_orifice_as_beverloo_says(runs):
    a, b = runs[6.0], runs[5.0]
    ours = (a["W"] / a["rho_b"]) / (b["W"] / b["rho_b"])
    bev = silo.beverloo_ratio(6.0, 5.0)
    assert ours > 1.3, ours
    assert abs(ours / bev - 1.0) < 0.20, (ours, bev, a["W"], b["W"])
