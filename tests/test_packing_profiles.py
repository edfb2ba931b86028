"""Column analysis (peclet.packing.analysis.profiles) against closed forms and independent integrals."""
import math

import numpy as np
import pytest
from scipy import integrate

from peclet.core import geom
from peclet.core.validation import PecletArgumentError
from peclet.packing.analysis import profiles as P
from peclet.packing.bed.elements import sphere
from peclet.packing.bed.freeze import Pack

A = 0.5  # sphere radius: D = 1


def _probes():
    """The six poles plus a Fibonacci spiral: a touching sphere or plane meets a pole exactly."""
    k = np.arange(194) + 0.5
    th = np.arccos(1 - 2 * k / len(k))
    ph = math.pi * (1 + 5 ** 0.5) * k
    fib = np.column_stack([np.sin(th) * np.cos(ph), np.cos(th), np.sin(th) * np.sin(ph)])
    return A * np.vstack([np.eye(3), -np.eye(3), fib])


def sphere_pack(pos, box=(50.0, 50.0), quats=None):
    el = sphere(A)
    ni, nr, _, _ = el.builder.encode()
    pos = np.asarray(pos, float)
    q = np.tile([0.0, 0.0, 0.0, 1.0], (len(pos), 1)) if quats is None else quats
    return Pack(pos, q, box, el.envelope_volume, ni, nr, el.root, A, _probes(), 1.0,
                [1.0, 1.0, 1.0], el.envelope_root, el.envelope_volume)


def _lens(rho, d, r):
    """Area of disc(radius rho, centre at distance d) intersected with disc(radius r, centre 0)."""
    if rho <= 0 or r <= 0:
        return 0.0
    if d >= rho + r:
        return 0.0
    if d <= abs(r - rho):
        return math.pi * min(r, rho) ** 2
    a1 = rho * rho * math.acos((d * d + rho * rho - r * r) / (2 * d * rho))
    a2 = r * r * math.acos((d * d + r * r - rho * rho) / (2 * d * r))
    k = 0.5 * math.sqrt((-d + rho + r) * (d + rho - r) * (d - rho + r) * (d + rho + r))
    return a1 + a2 - k


def _shell_solid_fraction(d, yc, r_in, r_out, y_lo, y_hi):
    """Volume fraction of the annulus r_in < r < r_out, y_lo < y < y_hi inside a sphere of radius
    A whose centre is at distance d from the axis and height yc: integral of circle lenses."""
    def area(y):
        rho = math.sqrt(max(A * A - (y - yc) ** 2, 0.0))
        return _lens(rho, d, r_out) - _lens(rho, d, r_in)
    lo, hi = max(y_lo, yc - A), min(y_hi, yc + A)
    v = integrate.quad(area, lo, hi, epsabs=1e-12, limit=200)[0] if hi > lo else 0.0
    return v / (math.pi * (r_out ** 2 - r_in ** 2) * (y_hi - y_lo))


def test_radial_profile_of_one_sphere_at_the_wall_matches_the_lens_integral():
    R = 2.0
    # touching the wall (d = R - A) and centred in the height window
    pack = sphere_pack([[(R - A) * math.cos(0.7), 3.0, (R - A) * math.sin(0.7)]])
    n = 3000
    prof = P.radial_profile(pack, R, (0.0, 0.0), 2.4, 3.6, samples_per_shell=n, seed=3)
    assert len(prof["z"]) == 100 and np.all(np.diff(prof["z_edges"]) <= 0.02 + 1e-15)
    assert prof["z"][0] == pytest.approx(0.01)
    exact = np.array([1.0 - _shell_solid_fraction(R - A, 3.0, R - hi, R - lo, 2.4, 3.6)
                      for lo, hi in zip(prof["z_edges"][:-1], prof["z_edges"][1:])])
    se = np.sqrt(exact * (1 - exact) / n)
    # exact point tests: where the shell misses the sphere the estimate is exactly 1
    assert np.all(prof["eps"][exact == 1.0] == 1.0)
    assert np.all(np.abs(prof["eps"] - exact) <= 4.5 * se + 1e-12)
    assert exact.min() < 0.95  # the sphere is really seen


def test_radial_profile_of_a_ring_of_spheres_at_the_wall():
    R, m = 2.5, 7
    ang = 2 * math.pi * np.arange(m) / m
    pos = np.column_stack([(R - A) * np.cos(ang) + 1.0, np.full(m, 0.5),
                           (R - A) * np.sin(ang) - 2.0])
    n = 4000
    prof = P.radial_profile(sphere_pack(pos), R, (1.0, -2.0), 0.0, 1.0, samples_per_shell=n)
    e = prof["z_edges"]
    exact = np.array([1.0 - m * _shell_solid_fraction(R - A, 0.5, R - hi, R - lo, 0.0, 1.0)
                      for lo, hi in zip(e[:-1], e[1:])])
    se = np.sqrt(exact * (1 - exact) / n)
    assert np.all(np.abs(prof["eps"] - exact) <= 4.5 * se + 1e-12)
    # the ring's narrowest shell: at z = 1/2 the spheres' equators cut it
    k = int(np.argmin(exact))
    assert 0.4 < prof["z"][k] < 0.6


def _cubic_lattice(nx, ny):
    g = np.arange(nx) + 0.5
    X, Y, Z = np.meshgrid(g, np.arange(ny) + 0.5, g, indexing="ij")
    return sphere_pack(np.column_stack([X.ravel(), Y.ravel(), Z.ravel()]), box=(nx, nx))


def test_bulk_of_a_simple_cubic_lattice_is_one_minus_pi_over_six():
    pack = _cubic_lattice(3, 8)
    # zone [1, 7] in 6 windows of one lattice period each: every window's mean is exactly pi/6
    b = P.bulk(pack, P.periodic_section(pack), floor_y=0.0, top_y=8.0, crop=1.0, n_windows=6,
               samples_per_window=40_000, seed=5)
    assert np.allclose(b["windows"], [[k, k + 1] for k in range(1, 7)])
    phi = math.pi / 6
    assert abs(b["eps"] - (1 - phi)) < 4 * b["eps_se_sampling"]
    assert abs(b["f_env"] - phi) < 4 * b["f_env_se_sampling"]  # the sphere is its own envelope
    assert b["eps"] + b["f_env"] == pytest.approx(1.0, abs=1e-12)


def test_periodic_images_are_seen_and_a_column_is_not_periodic():
    # one sphere straddling the periodic box's x = 0 face: half of it is an image
    pack = sphere_pack([[0.2, 0.5, 0.5]], box=(2.0, 2.0))
    smp = P.PackSampler(pack, periodic=True)
    assert smp.solid([[1.9, 0.5, 0.5]])[0] and not smp.solid([[1.0, 0.5, 0.5]])[0]
    assert not P.PackSampler(pack, periodic=False).solid([[1.9, 0.5, 0.5]])[0]
    # a centre outside the box is the same periodic pack
    moved = P.PackSampler(sphere_pack([[-1.8, 0.5, 4.5]], box=(2.0, 2.0)), periodic=True)
    q = np.random.default_rng(0).uniform(-1, 3, (500, 3))
    assert np.array_equal(moved.solid(q), smp.solid(q))


def test_axial_profile_of_the_lattice_matches_the_sliced_sphere_area():
    pack = _cubic_lattice(2, 3)
    n = 6000
    prof = P.axial_profile(pack, P.periodic_section(pack), 0.0, 3.0, slab=0.1,
                           samples_per_slab=n, seed=2)
    assert len(prof["y"]) == 30
    lo, hi = prof["y_edges"][:-1], prof["y_edges"][1:]
    # slab mean of pi (A^2 - (y - yc)^2) per unit cell area, yc the nearest layer centre
    yc = np.floor(0.5 * (lo + hi)) + 0.5
    F = lambda y, c: math.pi * (A * A * (y - c) - (y - c) ** 3 / 3)  # noqa: E731
    sol = np.array([(F(min(h, c + A), c) - F(max(l_, c - A), c)) / (h - l_)
                    for l_, h, c in zip(lo, hi, yc)])
    exact = 1 - sol
    se = np.sqrt(exact * (1 - exact) / n)
    assert np.all(np.abs(prof["eps"] - exact) <= 4.5 * se + 1e-12)


def test_standard_errors_describe_the_scatter_and_shrink_like_one_over_root_n():
    pack = _cubic_lattice(2, 6)
    sec = P.periodic_section(pack)
    kw = dict(floor_y=0.0, top_y=6.0, crop=1.0, n_windows=4)
    runs = [P.bulk(pack, sec, samples_per_window=2000, seed=s, **kw) for s in range(24)]
    est = np.array([r["eps"] for r in runs])
    se = np.mean([r["eps_se_sampling"] for r in runs])
    # 24 draws: the sample std of a normal lies within a factor 0.6..1.45 of sigma with p > 0.99
    assert 0.6 < est.std(ddof=1) / se < 1.45
    big = P.bulk(pack, sec, samples_per_window=8000, seed=99, **kw)
    assert big["eps_se_sampling"] / se == pytest.approx(0.5, rel=0.05)


def test_orientation_to_axis_of_known_tilts():
    th = np.array([0.0, 0.3, 0.9, 1.2, math.pi / 2])
    q = np.column_stack([np.sin(th / 2), 0 * th, 0 * th, np.cos(th / 2)])  # tilt about x
    pack = sphere_pack(np.column_stack([th * 3, np.ones(5), np.zeros(5)]), quats=q)
    o = P.orientation_to_axis(pack, (0.0, 2.0, 0.0))
    assert np.allclose(o["cos"], np.abs(np.cos(th)), atol=1e-14)
    assert o["s2"] == pytest.approx(np.mean(1.5 * np.cos(th) ** 2 - 0.5), abs=1e-14)
    oz = P.orientation_to_axis(pack, (0.0, 0.0, 1.0))
    assert np.allclose(oz["cos"], np.abs(np.sin(th)), atol=1e-14)
    with pytest.raises(PecletArgumentError, match="axis"):
        P.orientation_to_axis(pack, (0, 0, 0))


def _walls(R, centre):
    b = geom.SceneBuilder()
    floor = b.add_leaf("half_space", [0.0, 1.0, 0.0, 0.0])
    cb = geom.SceneBuilder()
    col = cb.add_difference(cb.add_leaf("box", [50.0, 50.0, 50.0]),
                            cb.add_leaf("cone", [R, R, 60.0],
                                        translation=[centre[0], 0.0, centre[1]]))
    return [(b, floor), (cb, col)]


def test_coordination_counts_wall_contacts_and_ignores_images_in_a_column():
    R = 2.0
    walls = _walls(R, (R, R))
    assert walls[0][0].eval_root(walls[0][1], [[0.0, -1.0, 0.0]])[0] < 0  # the floor is solid
    pos = [[R, 0.5, R],            # on the floor, under the next one
           [R, 1.5, R],            # resting on the first only
           [0.5, 3.0, R],          # against the column wall at x = 0, and the next sphere
           [1.5, 3.0, R],          # touching the previous one only
           [3.5, 3.0, R]]          # against the opposite wall only (its image touches sphere 2)
    pack = sphere_pack(pos, box=(2 * R, 2 * R))
    c = P.coordination(pack, walls, gap=1e-9)
    assert c["wall"].tolist() == [1, 0, 1, 0, 1]
    assert c["elem"].tolist() == [1, 1, 1, 1, 0]
    assert c["rattlers"] == 0  # sphere 4 holds on the wall alone
    # read as a periodic box, spheres 2 and 4 touch through the x faces
    cp = P.coordination(pack, walls, gap=1e-9, periodic=True)
    assert cp["elem"].tolist() == [1, 1, 2, 1, 1]
    pos2 = np.array(pos)
    pos2[4] = [3.0, 6.0, R]        # now floating: a rattler
    c2 = P.coordination(sphere_pack(pos2, box=(2 * R, 2 * R)), walls, gap=1e-9)
    assert c2["total"].tolist() == [2, 1, 2, 1, 0] and c2["rattlers"] == 1
    with pytest.raises(PecletArgumentError, match="walls"):
        P.coordination(pack, [walls[0][0]])


def test_sphere_correlations_match_the_published_values():
    # Benyahia & O'Neill at N = 5, 8, 10 as quoted in issue 14
    assert np.round(P.benyahia_oneill_voidage([5, 8, 10]), 3).tolist() == [0.436, 0.411, 0.404]
    z = np.linspace(0, 2.5, 25001)
    e = P.de_klerk_voidage(z)
    assert e[0] == 1.0
    # the features the packed-bed literature reports (issue 14's bands)
    first = np.argmin(np.where(z < 0.8, e, 9))
    assert 0.45 <= z[first] <= 0.65 and 0.20 <= e[first] <= 0.27
    peak = np.argmax(np.where((z > 0.8) & (z < 1.2), e, -9))
    assert 0.50 <= e[peak] <= 0.62
    second = np.argmin(np.where((z > 1.2) & (z < 1.7), e, 9))
    assert 1.35 <= z[second] <= 1.55 and e[second] < 0.35


def test_bad_arguments_are_named():
    pack = sphere_pack([[0.0, 1.0, 0.0]])
    with pytest.raises(PecletArgumentError, match="shell_width"):
        P.radial_profile(pack, 2.0, (0, 0), 0, 2, shell_width=0.05)
    with pytest.raises(PecletArgumentError, match="column_radius"):
        P.radial_profile(pack, -1.0, (0, 0), 0, 2)
    with pytest.raises(PecletArgumentError, match="y_hi"):
        P.radial_profile(pack, 2.0, (0, 0), 2, 1)
    with pytest.raises(PecletArgumentError, match="crop"):
        P.bulk(pack, P.ColumnSection(2.0), crop=2.0)
    with pytest.raises(PecletArgumentError, match="periodic"):
        P.coordination(pack, periodic="False")


# ---------------------------------------------------------------------- figures
def test_rendered_sphere_covers_pi_over_four_of_its_square():
    from peclet.packing.output import bed_figures as F
    from peclet.packing.output.export import element_mesh

    pack = sphere_pack([[0.0, 0.0, 0.0]])
    img = F.render_bed(pack, element_mesh(pack, 0.03), [[0.2, 0.4, 0.8]], width=300,
                       supersample=1)
    # the view spans the bounding sphere's square: the disc covers pi/4 of it (orthographic)
    covered = (img < 0.999).any(axis=2).mean()
    assert covered == pytest.approx(math.pi / 4, abs=0.01)
    # shading only darkens the element colour: blue stays the largest channel
    lit = img[(img < 0.999).any(axis=2)]
    assert np.all(lit[:, 2] >= lit[:, 0]) and lit[:, 2].max() <= 0.8 + 1e-12


def test_the_nearer_element_hides_the_farther_one(tmp_path):
    from peclet.packing.output import bed_figures as F
    from peclet.packing.output.export import element_mesh

    # elev = 0, azim = 0: the viewer looks along -z; sphere 0 is in front of sphere 1
    pack = sphere_pack([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])
    img = F.render_bed(pack, element_mesh(pack, 0.04), [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
                       width=200, elev=0.0, azim=0.0, supersample=1)
    mid = img[img.shape[0] // 2, img.shape[1] // 2]
    assert mid[0] > 0.3 and mid[2] == 0.0
    path = F.bed_view(pack, element_mesh(pack, 0.06), tmp_path / "bed.png",
                      cutaway_center_xz=(0.0, 0.0), width=200)
    from matplotlib.image import imread
    assert imread(path).shape[2] in (3, 4)


def test_profile_figures_are_written(tmp_path):
    from matplotlib.image import imread

    from peclet.packing.output import bed_figures as F

    pack = sphere_pack([[1.5, 1.0, 0.0], [0.0, 1.0, 0.0], [-1.0, 2.0, 0.5]])
    prof = P.radial_profile(pack, 2.0, (0, 0), 0.5, 2.5, samples_per_shell=200)
    ax = P.axial_profile(pack, P.ColumnSection(2.0), 0.0, 3.0, samples_per_slab=200)
    b = P.bulk(pack, P.ColumnSection(2.0), top_y=3.0, crop=0.5, samples_per_window=500)
    for p in (F.radial_profile_figure(prof, tmp_path / "r.png", sphere=True),
              F.axial_profile_figure(ax, tmp_path / "a.png", bulk=b)):
        assert imread(p).shape[0] > 100
    assert sorted(x.name for x in tmp_path.iterdir()) == ["a.png", "r.png"]


def test_profiles_are_bitwise_the_same_at_one_and_two_threads():
    import numba

    pos = np.random.default_rng(4).uniform([0.6, 0.5, 0.6], [3.4, 3.5, 3.4], (12, 3))
    pack = sphere_pack(pos, box=(4.0, 4.0))
    old = numba.get_num_threads()
    try:
        out = []
        for t in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
            numba.set_num_threads(t)
            out.append(P.radial_profile(pack, 2.0, (2.0, 2.0), 0.5, 3.5,
                                        samples_per_shell=300)["eps"])
    finally:
        numba.set_num_threads(old)
    assert np.array_equal(out[0], out[1])


def test_a_fluid_section_counts_only_the_fluid_region():
    # a cubic lattice with its middle column of spheres replaced by a solid internal wall
    # x in [1, 2): over the fluid region the voidage is the lattice's 1 - pi/6; over the whole
    # cross-section it would be 1 - (2/3) pi/6
    full = _cubic_lattice(3, 8)
    keep = np.abs(full.positions[:, 0] - 1.5) > 0.25
    pack = sphere_pack(full.positions[keep], box=(3.0, 3.0))
    box = P.BoxSection((0.0, 0.0), (3.0, 3.0))
    fluid = P.FluidSection(box, lambda p: (p[:, 0] < 1.0) | (p[:, 0] >= 2.0))
    kw = dict(floor_y=0.0, top_y=8.0, crop=1.0, n_windows=6, samples_per_window=30_000, seed=4)
    b = P.bulk(pack, fluid, **kw)
    assert abs(b["eps"] - (1 - math.pi / 6)) < 4 * b["eps_se_sampling"]
    assert b["n_samples"] < 6 * 30_000 * 0.7                   # the wall's points not counted
    whole = P.bulk(pack, box, **kw)
    assert abs(whole["eps"] - (1 - 2 / 3 * math.pi / 6)) < 4 * whole["eps_se_sampling"]
    # an axial slab wholly inside an internal has no fluid: NaN, not a voidage
    plate = P.FluidSection(box, lambda p: np.abs(p[:, 1] - 4.0) > 0.2)
    prof = P.axial_profile(pack, plate, 3.6, 4.4, slab=0.2, samples_per_slab=500)
    assert np.isnan(prof["eps"][1]) and np.isnan(prof["eps"][2])
    assert np.all(np.isfinite(prof["eps"][[0, 3]]))
    with pytest.raises(PecletArgumentError, match="FluidSection"):
        P.FluidSection(box, "not callable")
