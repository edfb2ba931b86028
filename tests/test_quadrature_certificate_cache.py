"""The quadrature certificate's shared levels (``quadrature_convergence(..., fast=True)``,
the default) against the straightforward path, on a fixed set: every level's answer bitwise,
every verdict, figure and text; a planted cell bias fails both alike. (Unit tests of the
certificate, so they live here and not among the certificates in properties/.)"""
import numpy as np
import pytest

from peclet_verify.geometry import strategies as GS
from peclet_verify.mass import properties as MP


# The fixed set covers each closed-form kind, turned,
# moved and scaled; a hollow cylinder whose finer levels refine below the top cells (so
# refined cells are shared too) and an ellipsoid (not 1-Lipschitz: no cell is skipped).
_TURN = (0.0, 0.3826834323650898, 0.0, 0.9238795325112867)      # 45 degrees about y
_TILT = (0.43118496557631325, 0.20504077712179916, 0.011061957500049454, 0.8785871830811722)
FIXED = tuple(GS.TreeRecipe(GS.LeafCall(kind, params, GS.Transform(*tr)))
              for kind, params, tr in (
    ("sphere", (0.9,), ((0.1, -0.2, 0.3), _TURN, 1.3)),
    ("box", (0.7574911184666108, 0.3333333333333333, 0.46788019249360036),
     ((0, 0, 0), _TURN, 1.0)),
    ("capsule", (0.7088595417085108, 0.7954567335312224), ((-0.74, 0.0, 0.0), _TILT, 2.0)),
    ("torus", (0.8, 0.3), ((0.28, -0.43, 0.27), _TURN, 1.9)),
    ("hollow_cylinder", (0.20000000000000004, 1.2970187783435716, 0.058802003761394016),
     ((0, 0, 0), (0, 0, 0, 1), 1.0)),
    ("ellipsoid", (0.5881391467103029, 0.5178983859620064, 0.1138048349333264),
     ((0.0, 0.0, -0.9183475376119201), _TURN, 0.5818781811126971)),
))
TOLS = (1e-3, 1e-4, 1e-5)


def _box(recipe):
    b, root = recipe.build()
    c, r, _ = b.node_bound(root)
    return b, root, c - 1.02 * r, c + 1.02 * r


@pytest.mark.heavy
def test_shared_levels_are_bitwise_the_separate_ones(monkeypatch):
    from peclet.core.geom.quadrature import refine
    from peclet_verify.mass.properties import reference_measure
    counted = {"n": 0}
    integrate = refine.integrate_cells

    def counting(*args, **kw):
        counted["n"] += len(args[5])
        return integrate(*args, **kw)
    monkeypatch.setattr(refine, "integrate_cells", counting)
    refined = False
    for recipe in FIXED:
        b, root, lo, hi = _box(recipe)
        alone, cells = [], []
        for tol in TOLS:
            counted["n"] = 0
            alone.append(reference_measure(b, root, lo, hi, tol))
            cells.append(counted["n"])
        separate, finest = sum(cells), cells[-1]
        refined = refined or finest > 512
        cache = {}
        counted["n"] = 0
        shared = [reference_measure(b, root, lo, hi, tol, cache=cache) for tol in TOLS]
        for tol, (v, com, mom), (vs, coms, moms) in zip(TOLS, alone, shared):
            assert v == vs and np.array_equal(com, coms) and np.array_equal(mom, moms), \
                (recipe, tol)
        # the shared levels integrate each cell once: at least the finest level's cells,
        # fewer than the levels did apart
        assert finest <= counted["n"] < separate, (recipe, counted["n"], separate, finest)
    assert refined, "no example of the fixed set refines below its top cells"


@pytest.mark.heavy
def test_fast_certificate_gives_the_same_verdicts():
    statuses = set()
    for recipe in FIXED:
        # the default thresholds, and strict ones under which some examples fail (not on the
        # ellipsoid: it costs as much as the rest together)
        for kw in ({}, {"rtol": 1e-9, "slack": 0.05})[:1 if recipe.kinds == ("ellipsoid",)
                                                        else 2]:
            ref = MP.quadrature_convergence(recipe, fast=False, **kw)
            fast = MP.quadrature_convergence(recipe, **kw)
            assert (fast.status, fast.worst, fast.worst_name, fast.counterexample,
                    fast.details) == (ref.status, ref.worst, ref.worst_name,
                                      ref.counterexample, ref.details), (recipe, kw)
            statuses.add((bool(kw), ref.status))
    assert statuses == {(False, "passed"), (True, "passed"), (True, "failed")}, statuses


def test_body_properties_cache_must_be_a_dict():
    from peclet.core.validation import PecletArgumentError
    b, root, lo, hi = _box(FIXED[0])
    with pytest.raises(PecletArgumentError, match="cache"):
        b.body_properties(root, lo, hi, tol=1e-3, cache=[])


def test_planted_cell_bias_fails_both_paths(monkeypatch):
    """A planted engine bug below the cache (every cell's volume 1e-3 too large) fails the
    certificate the same way on both paths: the shared cells carry the bug, they do not hide
    it."""
    from peclet.core.geom.quadrature import refine
    integrate = refine.integrate_cells

    def biased(*args, **kw):
        mom, err, code = integrate(*args, **kw)
        mom[:, 0] *= 1.0 + 1e-3
        return mom, err, code
    monkeypatch.setattr(refine, "integrate_cells", biased)
    for recipe in FIXED[:2]:
        ref = MP.quadrature_convergence(recipe, fast=False)
        fast = MP.quadrature_convergence(recipe)
        assert ref.status == fast.status == "failed", (recipe, ref, fast)
        assert (fast.worst, fast.worst_name, fast.counterexample) == \
            (ref.worst, ref.worst_name, ref.counterexample)
        assert "every level within 10 x tol: False" in fast.counterexample
