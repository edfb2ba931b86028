"""peclet_verify's grid-leaf strategies and properties (issue 41): random CSG trees sampled onto
grid leaves keep their source's sign beyond one cell diagonal and Equation 1 for the measured
ball; a planted grid that lies (a shifted lattice) is caught."""
from hypothesis import HealthCheck, given, settings

from peclet_verify.geometry.recipes import IDENTITY, LeafCall, TreeRecipe
from peclet_verify.geometry.sampled import (SampledTree, equation1_report, sampled_trees,
                                            sign_violations)

SETTINGS = settings(max_examples=25, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow])


@SETTINGS
@given(sampled_trees())
def test_grid_keeps_its_sources_sign_beyond_one_cell(sample):
    bad, judged = sign_violations(sample)
    assert len(bad) == 0, (sample.snippet(), bad[:3])


@SETTINGS
@given(sampled_trees())
def test_equation1_holds_for_the_measured_ball(sample):
    rep = equation1_report(sample)
    assert rep is None or rep["violating"] == 0.0, (sample.snippet(), rep)


class ShiftedGrid(SampledTree):
    """A planted liar: the grid of its source moved three cells along x."""

    def build(self):
        b, src, g, h = super().build()
        return b, src, b.add_reframed(g, translation=[3.0 * h, 0.0, 0.0]), h


def test_the_sign_property_catches_a_shifted_grid():
    liar = ShiftedGrid(TreeRecipe(LeafCall("sphere", (1.0,), IDENTITY)), cells=20)
    bad, judged = sign_violations(liar)
    assert judged > 1000 and len(bad) > 50
    honest = SampledTree(liar.source, liar.cells)
    assert len(sign_violations(honest)[0]) == 0


# ---------------------------------------------------------------- grids of meshes
def _ball(cells=14):
    from peclet_verify.mass.meshes import MeshSolid
    return MeshSolid("icosphere", (("radius", 0.6),), (0.0, 0.0, 0.0, 1.0), (0.1, 0.0, 0.0),
                     cells)


def test_a_mesh_grid_passes_the_mass_certificate():
    from peclet_verify.mass.meshes import grid_mass_certificate
    res = grid_mass_certificate(_ball())
    assert res.passed and 0.0 < res.worst <= 1.0, res
    assert abs(res.details["volume_rel_error"]) < 0.02


def test_the_mass_certificate_catches_a_grid_in_the_wrong_units():
    # a planted maker that reads the mesh in the wrong units (x 2 about the origin)
    from peclet.core.geom.grids import grid_from_mesh
    from peclet_verify.mass.meshes import grid_mass_certificate

    def wrong_units(b, mesh, spacing):
        return grid_from_mesh(b, mesh, spacing=spacing, scale=2.0)
    res = grid_mass_certificate(_ball(), make_grid=wrong_units)
    assert not res.passed and res.worst > 1.0 and "volume" in res.counterexample
    assert res.details["volume_rel_error"] > 6.0          # 2^3 - 1, as measured


def test_the_monte_carlo_difference_is_the_solids_difference():
    # band_sample's estimate of (grid solid - mesh solid) for a sphere grown by 5 %: the
    # exact difference of two concentric balls, within its stated 5 sigma
    import math

    import numpy as np
    import trimesh

    from peclet_verify.mass.meshes import band_sample
    m = trimesh.creation.icosphere(subdivisions=4, radius=0.6)
    v, f = np.asarray(m.vertices), np.asarray(m.faces)
    band, diff, sigma = band_sample(v, f, lambda p: np.linalg.norm(p, axis=1) - 0.63,
                                    np.zeros(3), 0.05)
    exact = 4.0 / 3.0 * math.pi * (0.63 ** 3) - m.volume
    assert abs(diff[0] - exact) <= sigma[0] and sigma[0] < 0.1 * exact
    assert np.all(np.abs(diff[1]) <= sigma[1])          # symmetric: no first moment
