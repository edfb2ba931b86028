"""The one marching-cubes surface (peclet.core.geom.mesh): closed forms and closure."""
import math

import numpy as np
import pytest

from peclet.core.geom.builder import SceneBuilder
from peclet.core.geom.mesh import surface_mesh
from peclet.core.validation import PecletArgumentError


def _edge_use(faces):
    """How many faces use each undirected edge (a closed surface: every count is 2)."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    _, counts = np.unique(np.sort(e, axis=1), axis=0, return_counts=True)
    return counts


def _volume(verts, faces):
    """Enclosed volume by the divergence theorem (signed tetrahedra from the origin)."""
    t = verts[faces]
    return abs(float(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum()) / 6.0)


def _euler(verts, faces):
    return len(verts) - len(_edge_use(faces)) + len(faces)


def _sphere(r=0.5, **kw):
    b = SceneBuilder()
    return b, b.add_leaf("sphere", [r], **kw)


def test_sphere_area_and_volume_converge_to_closed_forms():
    b, root = _sphere(0.5)
    errs = []
    for n in (21, 41):
        v, f, area = surface_mesh(b, root, [-0.6] * 3, [0.6] * 3, n)
        errs.append((abs(area - math.pi) / math.pi, abs(_volume(v, f) - math.pi / 6) / (math.pi / 6)))
    # second order: halving h cuts both errors by about 4 (allow 2.5 for the lattice's phase)
    assert errs[1][0] < 0.01 and errs[1][0] < errs[0][0] / 2.5
    assert errs[1][1] < 0.01 and errs[1][1] < errs[0][1] / 2.5


def test_inside_the_box_the_surface_is_closed_with_the_right_topology():
    b = SceneBuilder()
    torus = b.add_leaf("torus", [0.35, 0.12])
    for root, chi in ((torus, 0), (_sphere_in(b), 2)):
        v, f, _ = surface_mesh(b, root, [-0.6] * 3, [0.6] * 3, 33)
        assert np.all(_edge_use(f) == 2)
        assert _euler(v, f) == chi


def _sphere_in(b):
    return b.add_leaf("sphere", [0.4], translation=[0.05, -0.02, 0.03])


def test_a_solid_cut_by_the_box_is_closed_on_the_box_face():
    # a sphere centred on the box face z = 0: the closed mesh is the half ball
    b, root = _sphere(0.5)
    v, f, area = surface_mesh(b, root, [-0.6, -0.6, 0.0], [0.6, 0.6, 0.6], 49)
    assert np.all(_edge_use(f) == 2)
    assert _euler(v, f) == 2
    assert v[:, 2].min() >= -1e-12          # the cut sits on the box face, not below it
    half_ball = 2.0 * math.pi * 0.5 ** 3 / 3.0
    assert _volume(v, f) == pytest.approx(half_ball, rel=0.01)
    assert area == pytest.approx(2 * math.pi * 0.25 + math.pi * 0.25, rel=0.01)
    # close=False leaves the same surface open at the cut: only the hemisphere's area
    v2, f2, area2 = surface_mesh(b, root, [-0.6, -0.6, 0.0], [0.6, 0.6, 0.6], 49, close=False)
    assert np.any(_edge_use(f2) == 1)
    assert area2 == pytest.approx(2 * math.pi * 0.25, rel=0.01)


def test_closing_does_not_touch_a_surface_already_inside_the_box():
    b, root = _sphere(0.5)
    a = surface_mesh(b, root, [-0.6] * 3, [0.6] * 3, 25)
    c = surface_mesh(b, root, [-0.6] * 3, [0.6] * 3, 25, close=False)
    assert np.array_equal(a[0], c[0]) and np.array_equal(a[1], c[1]) and a[2] == c[2]


def test_narrow_band_bake_gives_the_exact_bake_mesh():
    # a Lipschitz root is baked in a narrow band; a non-Lipschitz copy (an ellipsoid with
    # equal radii is the same sphere but not certified Lipschitz) is baked exactly
    b = SceneBuilder()
    s = b.add_leaf("sphere", [0.45])
    e = b.add_leaf("ellipsoid", [0.45, 0.45, 0.45])
    assert b.is_lipschitz(s) and not b.is_lipschitz(e)
    lo, hi = [-0.55, -0.5, -0.6], [0.5, 0.55, 0.5]
    sp = (np.array(hi) - np.array(lo)) / 30
    full = b.bake(s, lo, sp, [31] * 3)
    band = b.bake(s, lo, sp, [31] * 3, band=float(np.linalg.norm(sp)))
    assert not np.array_equal(full, band)   # the band really skipped work
    from skimage import measure
    m1 = measure.marching_cubes(full.reshape((31,) * 3, order="F"), 0.0, spacing=tuple(sp))
    m2 = surface_mesh(b, s, lo, hi, 31)
    assert np.array_equal(m1[0] + np.array(lo), m2[0]) and np.array_equal(m1[1], m2[1])


@pytest.mark.parametrize("kw, name", [
    (dict(n=2), "n"), (dict(n=2000), "n"), (dict(n=True), "n"), (dict(n="33"), "n"),
    (dict(lo=[0.0, 0.0]), "lo"), (dict(lo=[math.nan, 0, 0]), "lo"),
    (dict(hi=[-0.6, 0.6, 0.6]), "hi"), (dict(close="no"), "close"),
])
def test_bad_arguments_name_themselves(kw, name):
    b, root = _sphere(0.5)
    args = dict(lo=[-0.6] * 3, hi=[0.6] * 3, n=9)
    args.update(kw)
    with pytest.raises(PecletArgumentError, match=rf"^{name} must"):
        surface_mesh(b, root, **args)


def test_no_surface_in_the_box_is_an_error():
    b, root = _sphere(0.1)
    with pytest.raises(ValueError, match="no surface"):
        surface_mesh(b, root, [1.0] * 3, [2.0] * 3, 9)
