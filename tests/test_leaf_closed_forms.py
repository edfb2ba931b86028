"""The leaf table's closed-form mass properties against the engine's quadrature, and each other.

``closed_form_mass_properties`` is the one home of these formulas (tests, benchmarks and the
certificate read it), so each is checked against an independent computation: the implicit
quadrature at tol 1e-10 of the leaf itself, in its canonical frame. The quadrature never sees
the formulas; it only sees the sign of phi.
"""
import numpy as np
import pytest

from tiers import heavy_params

from peclet.core import geom
from peclet.core.geom.leaves import (LEAF_NAMES, ClosedForm, closed_form_mass_properties,
                                     leaf_spec)

# every leaf with a closed form, with parameters where no symmetry hides a wrong term (unequal
# radii, a frustum whose com is off the origin, a thick tube, a shell with a hole), and the
# half-extents of its canonical bounding box (a tight box: for the bound-only leaves no cell
# can be skipped, so empty box costs time)
CASES = {
    "sphere": ([0.45], [0.45, 0.45, 0.45]),
    "box": ([0.3, 0.2, 0.4], [0.3, 0.2, 0.4]),
    "ellipsoid": ([0.5, 0.35, 0.25], [0.5, 0.35, 0.25]),
    "hollow_cylinder": ([0.4, 0.6, 0.15], [0.4, 0.3, 0.4]),
    "hollow_cylinder_shell": ([0.45, 0.2, 0.7], [0.45, 0.45, 0.35]),
    "torus": ([0.4, 0.2], [0.6, 0.2, 0.6]),
    "capsule": ([0.25, 0.3], [0.25, 0.55, 0.25]),
    # the cone in its bounding ball's box: in its tight box (0.4, 0.3, 0.4) the engine
    # overflows its breakpoint slots at every tol (a known limitation, not a formula issue)
    "cone": ([0.4, 0.15, 0.3], [0.5, 0.5, 0.5]),
}
TOL = 1e-10


def _quadrature(kind, params, half):
    b = geom.SceneBuilder()
    r = b.add_leaf(kind, params)
    h = 1.02 * np.asarray(half)
    return b.body_properties(r, -h, h, n=32, tol=TOL)


@pytest.mark.parametrize("kind", heavy_params(sorted(CASES), "hollow_cylinder_shell"))
def test_closed_form_matches_quadrature(kind):
    params, half = CASES[kind]
    cf = closed_form_mass_properties(kind, params)
    p = _quadrature(kind, params, half)
    scale = np.abs(cf.inertia).max()
    ev = abs(p.volume - cf.volume) / cf.volume
    ec = np.abs(p.com - cf.com).max() / max(half)
    ei = np.abs(p.inertia - cf.inertia).max() / scale
    print(f"\n{kind}: volume {ev:.1e}, com {ec:.1e}, inertia {ei:.1e} (relative)")
    # the quadrature is asked for 1e-10 (measured: within 1e-13 on every case here); a wrong
    # term of a formula would be off by far more
    assert ev <= TOL
    assert ec <= TOL
    assert ei <= TOL


def test_every_row_with_a_closed_form_is_checked():
    """A leaf gaining a closed form must gain a case above; the two without one say None."""
    with_form = {n for n in LEAF_NAMES if leaf_spec(n).mass_properties is not None}
    assert with_form == set(CASES)
    assert closed_form_mass_properties("superquadric", [0.3, 0.2, 0.4, 0.5]) is None
    assert closed_form_mass_properties("half_space", [0.0, 1.0, 0.0, 0.1]) is None


def test_degenerate_members_agree_across_rows():
    """Rows that describe the same solid give the same numbers: a capsule of length 0 is a
    sphere, an ellipsoid with equal radii is a sphere, a cone with equal radii is a solid
    cylinder (a shell with no hole, turned from z to y), a cube is a box."""
    def same(a, b, perm=(0, 1, 2)):
        assert isinstance(a, ClosedForm) and isinstance(b, ClosedForm)
        assert np.isclose(a.volume, b.volume, rtol=1e-14, atol=0)
        p = list(perm)
        assert np.allclose(a.com[p], b.com, rtol=0, atol=1e-15)
        assert np.allclose(a.inertia[np.ix_(p, p)], b.inertia, rtol=1e-14, atol=0)

    sphere = closed_form_mass_properties("sphere", [0.3])
    same(closed_form_mass_properties("capsule", [0.3, 0.0]), sphere)
    same(closed_form_mass_properties("ellipsoid", [0.3, 0.3, 0.3]), sphere)
    same(closed_form_mass_properties("cone", [0.3, 0.3, 0.35]),
         closed_form_mass_properties("hollow_cylinder_shell", [0.3, 0.0, 0.7]), perm=(0, 2, 1))
    # a frustum upside down mirrors its com and keeps its moments
    up = closed_form_mass_properties("cone", [0.4, 0.1, 0.3])
    down = closed_form_mass_properties("cone", [0.1, 0.4, 0.3])
    assert np.isclose(up.com[1], -down.com[1], rtol=1e-14) and up.com[1] < 0.0
    assert np.allclose(up.inertia, down.inertia, rtol=1e-14, atol=0)


def test_bad_input_is_refused():
    with pytest.raises(ValueError):
        closed_form_mass_properties("teapot", [1.0])
    with pytest.raises(ValueError):
        closed_form_mass_properties("torus", [0.1, 0.2])     # r >= R
