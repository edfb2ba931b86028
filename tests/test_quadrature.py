"""Implicit quadrature against closed forms, error estimates, principal frames, bad input.

Measured state (n = 8, tol = 1e-7): smooth leaves reach 1e-8..1e-9 relative in volume and
inertia with an error estimate that bounds the error; leaves with creases (box, tube, cone)
stall near 1e-5 with an estimate that does NOT bound the error. The issue's targets (1e-10 /
1e-8 and a bounding estimate everywhere) are recorded below as strict xfails.
"""
import numba
import numpy as np
import pytest

from peclet.core import geom
from peclet.core.geom.transforms import quat_to_matrix

Q = np.array([0.3, -0.5, 0.2, 0.78]) / np.linalg.norm([0.3, -0.5, 0.2, 0.78])
R = quat_to_matrix(Q)
T = np.array([0.07, -0.05, 0.11])
BOX = ([-0.75] * 3, [0.75] * 3)

# kind, params, volume, principal moments per unit mass (None: volume only)
CLOSED = {
    "sphere": ("sphere", [0.5], 4 / 3 * np.pi * 0.125, np.full(3, 0.4 * 0.25)),
    "ellipsoid": ("ellipsoid", [0.5, 0.35, 0.25], 4 / 3 * np.pi * 0.5 * 0.35 * 0.25,
                  np.array([0.35 ** 2 + 0.25 ** 2, 0.5 ** 2 + 0.25 ** 2, 0.5 ** 2 + 0.35 ** 2]) / 5),
    "capsule": ("capsule", [0.25, 0.3], np.pi * 0.0625 * 0.6 + 4 / 3 * np.pi * 0.25 ** 3, None),
    "torus": ("torus", [0.4, 0.12], 2 * np.pi ** 2 * 0.4 * 0.0144, None),
    "box": ("box", [0.3, 0.2, 0.4], 8 * 0.3 * 0.2 * 0.4,
            np.array([0.2 ** 2 + 0.4 ** 2, 0.3 ** 2 + 0.4 ** 2, 0.3 ** 2 + 0.2 ** 2]) / 3),
    "hollow_cylinder": ("hollow_cylinder", [0.5, 0.8, 0.15], np.pi * 0.8 * (0.25 - 0.35 ** 2),
                        None),
}
SMOOTH = ["sphere", "ellipsoid", "capsule", "torus"]
CREASED = ["box", "hollow_cylinder"]
_cache = {}


def measure(name, n=8, tol=1e-7):
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
    assert ev <= 2e-7
    assert abs(p.volume - CLOSED[name][2]) <= p.volume_error      # the estimate bounds it
    assert np.abs(p.com - T).max() <= 1e-7
    if ei is not None:
        assert ei <= 1e-7
        assert ei * np.abs(p.inertia).max() <= p.moment_error


@pytest.mark.parametrize("name", CREASED)
def test_creased_leaves_within_1e_4(name):
    p, ev, ei, V = measure(name)
    assert ev <= 1e-4
    if ei is not None:
        assert ei <= 2e-4


@pytest.mark.xfail(strict=True, reason="issue target 1e-10 on smooth leaves not reached: the "
                   "rule stalls near 1e-8..1e-9 (see module docstring)")
def test_target_smooth_volume_1e_10():
    assert max(measure(n)[1] for n in SMOOTH) <= 1e-10


@pytest.mark.xfail(strict=True, reason="creases inside one leaf still converge slowly: box and "
                   "tube errors ~1e-5 against the 1e-8 target")
def test_target_creased_volume_1e_8():
    assert max(measure(n)[1] for n in CREASED) <= 1e-8


@pytest.mark.xfail(strict=True, reason="on creased leaves the |I7 - I5| estimate misses the "
                   "crease error, so it does not bound the actual error")
def test_target_estimate_bounds_creased_error():
    for name in CREASED:
        p, ev, ei, V = measure(name)
        assert ev * V <= p.volume_error


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
