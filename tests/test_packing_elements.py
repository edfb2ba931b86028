"""Packing elements: certified by construction, validated, the page's ring bit for bit."""
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from peclet.packing.bed import elements as E

sys.path.insert(0, str(Path(__file__).parent))


def _mc_volume(el, n=400_000, seed=3):
    lo, hi = el.bounds
    p = np.random.default_rng(seed).uniform(lo, hi, size=(n, 3))
    f = (el.builder.eval_root(el.root, p) < 0).mean()
    v = np.prod(hi - lo)
    return v * f, v * math.sqrt(f * (1 - f) / n)


@pytest.mark.parametrize("name", sorted(E.ELEMENTS))
def test_every_element_is_certified_and_inside_its_bounds(name):
    el = E.ELEMENTS[name]()
    b, root = el                                   # unpacks as (builder, root)
    assert b is el.builder and root == el.root
    c, r, cert = b.node_bound(root)
    assert cert and math.isfinite(r)
    # Equation 1 on exterior probes, and no solid on the faces of the declared bounds
    chk = __import__("peclet.packing.analysis.geometry", fromlist=["x"]).certificate_check(b, root,
                                                                                  n=20_000)
    assert chk["violating"] == 0.0
    lo, hi = el.bounds
    g = np.random.default_rng(0)
    face = g.uniform(lo, hi, size=(6000, 3))
    for k in range(6000):
        a = k % 3
        face[k, a] = lo[a] if (k // 3) % 2 else hi[a]
    assert b.eval_root(root, face).min() > 0


@pytest.mark.parametrize("name,exact", [
    ("raschig_ring", math.pi * (0.5 ** 2 - 0.38 ** 2) * 1.0),
    ("berl_saddle", 0.5 * (math.pi * 0.2 ** 2) * (2 * math.pi * 0.5)),   # half a torus
    ("sphere", 4 / 3 * math.pi * 0.5 ** 3),
    ("solid_cylinder", math.pi * 0.25 * 1.0),
])
def test_closed_form_volumes(name, exact):
    v, se = _mc_volume(E.ELEMENTS[name]())
    assert abs(v - exact) < 5 * se


def test_intalox_is_the_inner_half_of_a_torus_shell():
    el = E.intalox_saddle(R=0.5, r=0.3, thickness=0.06)
    # Pappus: inner half (rho < R) of the annulus r_i < |(rho - R, y)| < r_o, halved by x <= 0
    ro, ri, R = 0.3, 0.24, 0.5
    ann = lambda a: (math.pi * a * a / 2) * 2 * math.pi * (R - 4 * a / (3 * math.pi))  # noqa
    exact = 0.5 * (ann(ro) - ann(ri))
    v, se = _mc_volume(el, n=800_000)
    assert abs(v - exact) < 5 * se


def test_pall_ring_is_the_pages_tree():
    import page_steps as ps

    b, root = E.pall_ring()
    q = np.random.default_rng(1).uniform(-0.8, 0.8, size=(50_000, 3))
    assert np.array_equal(b.eval_root(root, q), ps.b.eval_root(ps.ring, q))
    twin = E.pall_ring(certified=False)
    assert not twin.builder.node_bound(twin.root)[2]
    assert np.array_equal(np.sign(twin.builder.eval_root(twin.root, q)),
                          np.sign(b.eval_root(root, q)))


def test_sign_exact_twin_violates_equation_1_by_the_corner_ratio():
    from peclet.packing.analysis.geometry import certificate_check

    chk = certificate_check(*E.pall_ring(certified=False), n=50_000)
    assert chk["violating"] > 0.1
    # the max of two orthogonal half-space distances under-runs the corner distance by at most
    # 1/sqrt(2): the worst ratio can approach it but never go below
    assert 1 / math.sqrt(2) - 1e-9 <= chk["worst_ratio"] < 0.75


def test_envelopes():
    el = E.pall_ring()
    p = np.random.default_rng(2).uniform(-0.8, 0.8, size=(20_000, 3))
    inside = el.builder.eval_root(el.root, p) < 0
    in_env = el.builder.eval_root(el.envelope_root, p) <= 0
    assert np.all(in_env[inside])                  # the ring lies in its envelope
    assert el.envelope_volume == pytest.approx(math.pi * 0.25)
    assert E.berl_saddle().envelope_root is None


def test_sweep_ring_scales_the_webs():
    el = E.pall_ring_of_thickness(0.04)
    assert el.params["web_half"] == pytest.approx((0.46, 0.02, 0.02))
    assert el.builder.node_bound(el.root)[2]


@pytest.mark.parametrize("call,match", [
    (lambda: E.pall_ring(thickness=0.5), "thickness"),
    (lambda: E.pall_ring(thickness=-1), "thickness"),
    (lambda: E.pall_ring(n_windows=0), "n_windows"),
    (lambda: E.pall_ring(n_windows=2.5), "n_windows"),
    (lambda: E.pall_ring(window_y=0.6), "window_y"),
    (lambda: E.pall_ring(window_half=(0.05, 0.17, 0.13)), r"window_half\[0\]"),
    (lambda: E.pall_ring(window_half=(0.16, 0.5, 0.13)), r"window_half\[1\]"),
    (lambda: E.pall_ring(web_half=(0.49, 0.06, 0.06)), r"web_half\[0\]"),
    (lambda: E.pall_ring(web_half=(0.4, 0.06)), "web_half"),
    (lambda: E.raschig_ring(r_outer=float("nan")), "r_outer"),
    (lambda: E.berl_saddle(R=0.2, r=0.3), "'?r'?"),
    (lambda: E.intalox_saddle(thickness=0.4), "thickness"),
    (lambda: E.sphere(0), "radius"),
    (lambda: E.solid_cylinder(height="x"), "height"),
])
def test_bad_arguments_name_the_argument(call, match):
    with pytest.raises(ValueError, match=match):
        call()
