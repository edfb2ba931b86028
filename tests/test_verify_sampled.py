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
