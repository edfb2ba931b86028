"""Implicit quadrature against closed forms, error estimates, principal frames, bad input.

Measured state (n = 8, tol = 1e-9): smooth leaves (sphere, ellipsoid, capsule, torus) reach
<= 1e-11 relative in volume and <= 2e-12 in inertia; box, hollow cylinder and cone <= 1e-10;
every reported estimate bounds its error. NOT reached: a box at an *arbitrary* rotation — for
some rotations a piece of the solid narrower than the probe spacing (the wedge at a box vertex
inside a cell) is still missed and the error stays near 1e-7..1e-6 with a small estimate (a
strict xfail below).
"""
import sys

import numba
import numpy as np
import pytest

from peclet.core import geom
from peclet.core.geom.transforms import quat_to_matrix

Q = np.array([0.3, -0.5, 0.2, 0.78]) / np.linalg.norm([0.3, -0.5, 0.2, 0.78])
R = quat_to_matrix(Q)
T = np.array([0.07, -0.05, 0.11])
BOX = ([-0.75] * 3, [0.75] * 3)


def _capsule_moments(a, L):
    """Principal moments per unit volume of a capsule about y (radius a, half-length L)."""
    vc = np.pi * a * a * 2 * L
    vh = 2.0 / 3.0 * np.pi * a ** 3                       # one hemisphere
    iy = vc * a * a / 2 + 2 * vh * 0.4 * a * a
    ix = vc * (a * a / 4 + L * L / 3) + 2 * vh * (0.4 * a * a + L * L + 0.75 * a * L)
    return np.array([ix, iy, ix]) / (vc + 2 * vh)


def _tube_moments(ro, h, t):
    ri = ro - t
    return np.array([(ro ** 2 + ri ** 2) / 4 + h * h / 12, (ro ** 2 + ri ** 2) / 2,
                     (ro ** 2 + ri ** 2) / 4 + h * h / 12])


# kind, params, volume, principal moments per unit mass in the leaf frame (None: volume only)
CLOSED = {
    "sphere": ("sphere", [0.5], 4 / 3 * np.pi * 0.125, np.full(3, 0.4 * 0.25)),
    "ellipsoid": ("ellipsoid", [0.5, 0.35, 0.25], 4 / 3 * np.pi * 0.5 * 0.35 * 0.25,
                  np.array([0.35 ** 2 + 0.25 ** 2, 0.5 ** 2 + 0.25 ** 2, 0.5 ** 2 + 0.35 ** 2]) / 5),
    "capsule": ("capsule", [0.25, 0.3], np.pi * 0.0625 * 0.6 + 4 / 3 * np.pi * 0.25 ** 3,
                _capsule_moments(0.25, 0.3)),
    "torus": ("torus", [0.4, 0.12], 2 * np.pi ** 2 * 0.4 * 0.0144,
              np.array([0.4 ** 2 / 2 + 5 / 8 * 0.12 ** 2, 0.4 ** 2 + 0.75 * 0.12 ** 2,
                        0.4 ** 2 / 2 + 5 / 8 * 0.12 ** 2])),
    "box": ("box", [0.3, 0.2, 0.4], 8 * 0.3 * 0.2 * 0.4,
            np.array([0.2 ** 2 + 0.4 ** 2, 0.3 ** 2 + 0.4 ** 2, 0.3 ** 2 + 0.2 ** 2]) / 3),
    "hollow_cylinder": ("hollow_cylinder", [0.5, 0.8, 0.15], np.pi * 0.8 * (0.25 - 0.35 ** 2),
                        _tube_moments(0.5, 0.8, 0.15)),
    # frustum about y: r = 0.4 at y = -0.3, r = 0.2 at y = +0.3
    "cone": ("cone", [0.4, 0.2, 0.3], np.pi * 0.6 / 3 * (0.16 + 0.08 + 0.04), None),
}
SMOOTH = ["sphere", "ellipsoid", "capsule", "torus"]
CREASED = ["box", "hollow_cylinder", "cone"]
_cache = {}


def measure(name, n=8, tol=1e-9):
    """(props, relative volume error, relative inertia error or None, exact volume)."""
    key = (name, n, tol)
    if key not in _cache:
        kind, prm, V, I = CLOSED[name]
        b = geom.SceneBuilder()
        r = b.add_leaf(kind, prm, translation=T, rotation=Q)
        p = b.body_properties(r, *BOX, n=n, tol=tol)
        ev = abs(p.volume - V)
        ei = None
        if I is not None:
            Iw = p.mass * (R @ np.diag(I) @ R.T)
            ei = np.abs(p.inertia - Iw).max() / np.abs(Iw).max()
        _cache[key] = (p, ev / V, ei, V)
    return _cache[key]


@pytest.mark.parametrize("name", SMOOTH)
def test_smooth_leaves_offset_and_rotated(name):
    p, ev, ei, V = measure(name)
    assert ev <= 1e-10
    assert ev * V <= p.volume_error                        # the estimate bounds it
    assert np.abs(p.com - T).max() <= 1e-9
    assert ei <= 1e-9
    assert ei * np.abs(p.inertia).max() <= p.moment_error


@pytest.mark.parametrize("name", CREASED)
def test_creased_leaves_offset_and_rotated(name):
    p, ev, ei, V = measure(name)
    assert ev <= 1e-8
    assert ev * V <= p.volume_error
    if ei is not None:
        assert ei <= 1e-8
        assert ei * np.abs(p.inertia).max() <= p.moment_error


def test_rotated_box_principal_axes_within_1e_6_rad():
    p, ev, ei, V = measure("box")
    order = np.argsort(CLOSED["box"][3])
    for k in range(3):
        cosang = abs(p.axes[:, k] @ R[:, order[k]])
        assert np.arccos(min(1.0, cosang)) < 1e-6


@pytest.mark.xfail(strict=True, reason="features thinner than the probe spacing (the wedge at a "
                   "box vertex inside a cut cell) can still be missed: at some rotations the "
                   "error stays ~1e-7..1e-6 and the estimate does not see it")
def test_box_at_random_rotations_1e_8():
    rng = np.random.default_rng(0)
    worst = 0.0
    for _ in range(8):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        b = geom.SceneBuilder()
        r = b.add_leaf("box", [0.3, 0.2, 0.4], translation=rng.uniform(-0.1, 0.1, 3), rotation=q)
        p = b.body_properties(r, *BOX, n=8, tol=1e-9)
        worst = max(worst, abs(p.volume - 0.192) / 0.192)
    assert worst <= 1e-8


@pytest.mark.parametrize("name", ["sphere", "torus"])
def test_convergence_order_on_smooth_leaves(name):
    """Top-level cells halved (tol loose, so no adaptive refinement): order >= 4."""
    kind, prm, V, _ = CLOSED[name]
    b = geom.SceneBuilder()
    r = b.add_leaf(kind, prm, translation=T, rotation=Q)
    rows = []
    for n in (6, 12, 24):
        p = b.body_properties(r, *BOX, n=n, tol=1e-3)
        assert p.diagnostics["max_depth"] == 0
        rows.append((n, abs(p.volume - V) / V))
    print(f"\n{name}: n, relative volume error, observed order")
    for (n0, e0), (n1, e1) in zip([(None, None)] + rows[:-1], rows):
        print(f"  {n1:3d}  {e1:.3e}  {'' if e0 is None else f'{np.log2(e0 / e1):.2f}'}")
    order = np.log2(rows[0][1] / rows[-1][1]) / 2          # over two halvings
    assert order >= 4.0


def test_pall_ring_converges_to_1e_9():
    """Step 3 done right: two tolerances agree to 1e-9 relative, the coarse estimate bounds
    the difference (volume and principal moments)."""
    sys.path.insert(0, __file__.rsplit("/", 1)[0])
    from page_steps import b, ring
    coarse = b.body_properties(ring, *BOX, n=8, tol=1e-7)
    fine = b.body_properties(ring, *BOX, n=8, tol=1e-9)
    dv = abs(coarse.volume - fine.volume)
    assert dv / fine.volume <= 1e-9
    assert dv <= coarse.volume_error
    dI = np.abs(coarse.principal - fine.principal).max()
    assert dI / fine.principal.max() <= 1e-9
    assert dI <= coarse.moment_error
    # the page's unconverged figures are NOT reproduced: ours differ from them by > 1e-4
    assert abs(fine.volume - 0.268032) > 1e-5


def test_ellipsoid_principal_axes_and_frame():
    p, ev, ei, V = measure("ellipsoid")
    # ascending moments; the columns of axes are the body axes x, y, z rotated by Q
    assert np.allclose(p.principal / p.mass, np.sort(CLOSED["ellipsoid"][3]), rtol=1e-7)
    order = np.argsort(CLOSED["ellipsoid"][3])
    for k in range(3):
        cosang = abs(p.axes[:, k] @ R[:, order[k]])
        assert np.arccos(min(1.0, cosang)) < 1e-6
    assert np.linalg.det(p.axes) > 0
    assert np.allclose(geom.quat_to_matrix(p.quat), p.axes, atol=1e-12)


def test_sphere_gets_the_identity_frame():
    b = geom.SceneBuilder()
    r = b.add_leaf("sphere", [0.5], translation=T)
    p = b.body_properties(r, *BOX, n=6, tol=1e-6)
    assert np.array_equal(p.axes, np.eye(3)) or np.allclose(p.axes, np.eye(3), atol=1e-12)


def test_principal_frame_is_an_exact_copy():
    b = geom.SceneBuilder()
    r = b.add_leaf("ellipsoid", [0.5, 0.35, 0.25], translation=T, rotation=Q)
    home, p = b.principal_frame(r, *BOX, n=6, tol=1e-6)
    kind, left, right, prm, t, q, s = b.node(home)
    assert (kind, left, right) == b.node(r)[:3] and np.array_equal(prm, b.node(r)[3])
    pts = np.random.default_rng(0).uniform(-0.6, 0.6, (2000, 3))
    # phi_home(x) = phi(A x + com)
    assert np.allclose(b.eval_root(home, pts), b.eval_root(r, pts @ p.axes.T + p.com),
                       atol=1e-13)
    c, rad, _ = b.node_bound(home)
    assert np.linalg.norm(c) < 1e-6          # the ellipsoid's centre is its com


def test_bits_do_not_depend_on_threads():
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("needs NUMBA_NUM_THREADS >= 2")
    b = geom.SceneBuilder()
    r = b.add_difference(b.add_leaf("torus", [0.4, 0.12], rotation=Q),
                         b.add_leaf("box", [0.2, 0.2, 0.6]))
    out = []
    old = numba.get_num_threads()
    try:
        for t in (1, 2):
            numba.set_num_threads(t)
            p = b.body_properties(r, *BOX, n=6, tol=1e-5)
            out.append((p.volume, p.volume_error, *p.inertia.ravel()))
    finally:
        numba.set_num_threads(old)
    assert out[0] == out[1]


def test_bad_input():
    b = geom.SceneBuilder()
    s = b.add_leaf("sphere", [0.5])
    with pytest.raises(ValueError, match="box does not contain the solid"):
        b.body_properties(s, [-0.4] * 3, [0.6] * 3)
    with pytest.raises(ValueError, match="hi must exceed lo"):
        b.body_properties(s, [1.0] * 3, [0.6] * 3)
    with pytest.raises(ValueError, match="lo must be 3 finite"):
        b.body_properties(s, [np.nan, 0, 0], [0.6] * 3)
    with pytest.raises(ValueError, match="density"):
        b.body_properties(s, *BOX, density=0.0)
    with pytest.raises(ValueError, match="resolution"):
        b.body_properties(s, *BOX, n=1)
    hole = b.add_difference(s, b.add_leaf("sphere", [0.55]))
    with pytest.raises(ValueError, match="empty solid"):
        b.body_properties(hole, *BOX, n=4)
