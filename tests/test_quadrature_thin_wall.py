"""A known limitation, kept visible: on a coarse top grid the quadrature can miss a piece of a
thin-walled element and report an error estimate far below its true error.

The Pall ring of wall t/D = 0.024 (the sweep's thinnest) at n = 12 gives s = 0.072793 with an
estimate of 1.1e-6, where n = 8, 16, 24 and 32 agree on 0.0732175 to 1e-9: the error is 4.2e-4,
400 times the estimate. The missing volume (3.3e-4 D^3) is 61% of one web bar, and the webs
(0.024 x 0.024 D across) are what ``body_properties``' docstring warns of: a piece narrower than
box / n (here 1.12 / 12 = 0.093 D) across both transverse axes can be found late or missed (n = 8
finds it by the luck of alignment). A plain tube of the same wall is right at n = 8, 12 and 16. The
documented limit holds; what is wrong is that the error estimate does not show it. The pipeline
measures at n = 32, where the figure is right."""
import pytest

from peclet.packing.bed.elements import pall_ring_of_thickness


def _s(n):
    el = pall_ring_of_thickness(0.024)
    lo, hi = el.bounds
    p = el.builder.body_properties(el.root, lo, hi, n=n, tol=1e-4)
    return p.volume / el.envelope_volume, p.volume_error / el.envelope_volume


@pytest.mark.heavy
def test_the_fine_grid_agrees_with_the_converged_ring():
    s8, e8 = _s(8)
    s16, e16 = _s(16)
    assert abs(s8 - s16) <= e8 + e16


@pytest.mark.heavy
@pytest.mark.xfail(strict=True, reason="n = 12 misses part of the thin ring: true error "
                   "4.2e-4 against an estimate of 1.1e-6 (surface_in_cell is a heuristic)")
def test_a_coarse_grid_error_estimate_bounds_its_error():
    s12, e12 = _s(12)
    s16, e16 = _s(16)
    assert abs(s12 - s16) <= e12 + e16


# the nightly's counterexample of 2026-11-28 (scripts/nightly, shard 2/4 of the quadrature
# certificate, after 444 examples): a thin box turned off the axes, in the certificate's box (its
# bounding ball grown 2%), n = 32. One cut cell holds a vertex where a wedge of the box starts;
# the wedge first showed at a u-probe 0.0097 above the vertex (its midpoint moving 14 times
# faster than it opens), the probe below had not looked there, and the scan placed the wedge's
# start at that probe: relative volume error 7.2e-5 at tol 1e-3, 1e-4 and 1e-5 alike, against
# an estimate of 6.8e-7. The u-bisection now goes below the probe that missed the wedge and
# follows it down from where it was seen (quadrature.breaks._locate_u): error 2e-11.
def _turned_thin_box(tol):
    import numpy as np

    from peclet.core.geom import SceneBuilder

    b = SceneBuilder()
    half = [0.1015625, 1.0, 0.1015625]
    root = b.add_leaf("box", half, rotation=[0.0, 0.20368027830878616, 0.17152023436529362,
                                             0.9638958208392285])
    c, r, _ = b.node_bound(root)
    p = b.body_properties(root, c - 1.02 * r, c + 1.02 * r, n=32, tol=tol)
    exact = 8.0 * float(np.prod(half))
    return abs(p.volume - exact), p.volume_error, exact


@pytest.mark.parametrize("tol", [1e-3, 1e-5])
def test_the_turned_thin_box_error_estimate_bounds_its_error(tol):
    err, est, vol = _turned_thin_box(tol)
    assert err <= est
    assert err <= tol * vol
