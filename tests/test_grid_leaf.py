"""The grid leaf (kind 0): a sampled field in the flat encoding (issue 41).

References are independent of the kernel: SciPy's RegularGridInterpolator for the trilinear
interpolant, closed forms for the spheres, trimesh for the mesh's volume."""
import functools

import numpy as np
import pytest
import trimesh
from scipy.interpolate import RegularGridInterpolator

from peclet.core import geom
from peclet.core.geom import grids
from peclet.core.geom.leaves import DATA
from peclet.core.geom.sampled import lattice_points
from peclet.core.validation import PecletArgumentError


def sphere_values(h=0.1, n=29, r=1.0):
    x, y, z = lattice_points((n, n, n), h)
    X, Y, Z = np.meshgrid(x, y, z, indexing="ij")
    return np.sqrt(X ** 2 + Y ** 2 + Z ** 2) - r, (x, y, z)


def reference_field(values, axes, p):
    """The module's stated field: trilinear inside, box distance plus the clamped value."""
    lo = np.array([a[0] for a in axes])
    hi = np.array([a[-1] for a in axes])
    c = np.clip(p, lo, hi)
    f = RegularGridInterpolator(axes, values, method="linear")(c)
    return np.linalg.norm(p - c, axis=1) + f


def test_field_is_the_stated_trilinear_interpolant_and_extension():
    values, axes = sphere_values()
    b = geom.SceneBuilder()
    t = np.array([0.3, -0.2, 0.1])
    g = b.add_grid(values, 0.1, translation=t)
    p = np.random.default_rng(1).uniform(-3.0, 3.0, (20_000, 3))
    ref = reference_field(values, axes, p - t)
    assert np.abs(b.eval_root(g, p) - ref).max() < 1e-12


def test_gradient_is_the_interpolants_derivative():
    values, _ = sphere_values()
    b = geom.SceneBuilder()
    g = b.add_grid(values, 0.1)
    p = np.random.default_rng(2).uniform(-2.0, 2.0, (2000, 3))
    # keep points a step away from the cell faces (the gradient jumps there) and the box
    frac = (p + 1.4) / 0.1 - np.floor((p + 1.4) / 0.1)
    p = p[np.all((frac > 0.01) & (frac < 0.99), axis=1) & np.all(np.abs(np.abs(p) - 1.4) > 1e-3,
                                                                  axis=1)]
    _, grad = b.eval_root_grad(g, p)
    e = 1e-7
    fd = np.column_stack([(b.eval_root(g, p + e * d) - b.eval_root(g, p - e * d)) / (2 * e)
                          for d in np.eye(3)])
    assert np.abs(grad - fd).max() < 1e-6


def test_equation1_ball_is_measured_and_holds():
    values, _ = sphere_values()
    b = geom.SceneBuilder()
    g = b.add_grid(values, 0.1, translation=[1.0, 2.0, 3.0], scale=2.0)
    c, r, certified = b.node_bound(g)
    assert np.allclose(c, [1.0, 2.0, 3.0]) and 2.0 <= r < 2.0 * (1.0 + 1e-9)
    assert not certified and not b.is_lipschitz(g)       # never culled: not 1-Lipschitz
    rep = geom.check_equation1(b, g, n=100_000, extent=2.0)
    assert rep["violating"] == 0.0


def test_encoding_carries_the_samples_as_data_rows():
    values, _ = sphere_values(n=9, h=0.35)
    b = geom.SceneBuilder()
    g = b.add_grid(values, 0.35)
    box = b.add_leaf("box", [0.5, 0.5, 2.0])
    d = b.add_difference(g, box)
    ni, nr, _, _ = b.encode()
    n_rows = -(-values.size // 16)
    assert (ni[:n_rows, 0] == DATA).all() and ni[g, 0] == 0 and g == n_rows
    p = np.random.default_rng(3).uniform(-2, 2, (5000, 3))
    b2 = geom.SceneBuilder.decode(ni, nr)
    assert np.array_equal(b2.eval_root(d, p), b.eval_root(d, p))
    b32 = geom.SceneBuilder.decode(ni, nr.astype(np.float32))      # the page's float32 call
    assert np.abs(b32.eval_root(d, p) - b.eval_root(d, p)).max() < 1e-6
    with pytest.raises(PecletArgumentError, match="data row"):
        b.node_bound(0)
    with pytest.raises(PecletArgumentError, match="data row"):
        b.add_union(0, g)


def test_reframed_copies_share_one_data_block():
    values, _ = sphere_values(n=9, h=0.35)
    b = geom.SceneBuilder()
    g = b.add_grid(values, 0.35)
    u = b.add_union(g, b.add_reframed(g, translation=[3.0, 0, 0]))
    prog = b.program(u)
    assert (prog.leaf_kind == DATA).sum() == -(-values.size // 24)
    p = np.array([[3.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    assert np.allclose(b.eval_root(u, p), b.eval_root(g, [[0.0, 0, 0]])[0])


@pytest.mark.parametrize("bad, match", [
    (lambda v: v[:1], "samples per axis"),
    (lambda v: np.where(v > 1.0, np.nan, v), "finite"),
    (lambda v: v - 5.0, "faces"),
    (lambda v: v + 5.0, "< 0"),
])
def test_bad_samples_are_refused_by_name(bad, match):
    values, _ = sphere_values(n=9, h=0.35)
    with pytest.raises(PecletArgumentError, match=match) as e:
        geom.SceneBuilder().add_grid(bad(values), 0.35)
    assert e.value.argument == "values"
    with pytest.raises(PecletArgumentError, match="spacing"):
        geom.SceneBuilder().add_grid(values, 0.0)


def test_callable_and_npz_place_the_solid_where_the_source_has_it(tmp_path):
    b = geom.SceneBuilder()
    c = np.array([0.5, -1.0, 2.0])
    g = grids.grid_from_callable(b, lambda p: np.linalg.norm(p - c, axis=1) - 0.8,
                                 c - 0.8, c + 0.8, 0.05)
    probe = c + np.array([[0.0, 0.0, 0.0], [0.8, 0, 0], [0, 0, 1.5]])
    assert np.allclose(b.eval_root(g, probe), [-0.8, 0.0, 0.7], atol=5e-3)
    values, _ = sphere_values(n=21, h=0.1, r=0.8)
    path = grids.save_grid(tmp_path / "ct.npz", values, 0.1, origin=[0.0, 0.0, 0.0])
    g2 = grids.grid_from_npz(b, path)
    assert abs(b.eval_root(g2, [[1.0, 1.0, 1.0]])[0] + 0.8) < 1e-12      # centre of the lattice
    with pytest.raises(PecletArgumentError, match="phi"):
        grids.grid_from_callable(b, lambda p: np.linalg.norm(p, axis=1) - 3.0, [-1] * 3,
                                 [1] * 3, 0.1)


def test_mesh_sphere_from_a_real_stl_file(tmp_path):
    path = tmp_path / "ball.stl"
    trimesh.creation.icosphere(subdivisions=5, radius=1.0).export(path)
    b = geom.SceneBuilder()
    g = grids.grid_from_mesh(b, path, spacing=0.1)
    p = np.random.default_rng(4).normal(size=(4000, 3))
    p *= (np.random.default_rng(5).uniform(0.7, 1.3, len(p)) / np.linalg.norm(p, axis=1))[:, None]
    exact = np.linalg.norm(p, axis=1) - 1.0
    # the mesh's chordal error (subdivision 5: ~1.2e-3) plus the trilinear error at h = 0.1
    assert np.abs(b.eval_root(g, p) - exact).max() < 0.02
    ref = grids.mesh_mass_properties(path)
    assert abs(ref.volume / (4 / 3 * np.pi) - 1) < 3e-3


def test_bad_meshes_get_a_clear_error(tmp_path):
    box = trimesh.creation.box()
    opened = trimesh.Trimesh(box.vertices, box.faces[:-1])
    with pytest.raises(PecletArgumentError, match="closed mesh"):
        grids.grid_from_mesh(geom.SceneBuilder(), opened)
    with pytest.raises(PecletArgumentError, match="with triangles"):
        grids.grid_from_mesh(geom.SceneBuilder(), (np.zeros((0, 3)), np.zeros((0, 3), int)))
    with pytest.raises(PecletArgumentError, match="existing"):
        grids.grid_from_mesh(geom.SceneBuilder(), tmp_path / "missing.stl")
    inside_out = trimesh.Trimesh(box.vertices, box.faces[:, ::-1])
    b = geom.SceneBuilder()
    g = grids.grid_from_mesh(b, inside_out, spacing=0.05)                 # repaired, stated
    assert b.eval_root(g, [[0.0, 0.0, 0.0]])[0] < -0.45


def test_pack_element_from_a_mesh_file_with_options(tmp_path):
    from peclet.packing.bed.api import resolve_element
    path = tmp_path / "pellet.stl"
    trimesh.creation.icosphere(subdivisions=3, radius=12.5).export(path)     # 25 mm, in mm
    with pytest.raises(PecletArgumentError, match="scale=0.04"):
        resolve_element(str(path))
    el = resolve_element(f"{path}:scale=0.04,resolution=0.1")
    c, r, _ = el.builder.node_bound(el.root)
    assert el.name == "pellet.stl" and 0.5 <= r < 0.56
    assert el.builder.eval_root(el.root, [[0.0, 0.0, 0.0]])[0] < -0.45
    with pytest.raises(PecletArgumentError, match="KEY in"):
        resolve_element(f"{path}:colour=3")


def test_pack_element_from_a_saved_grid(tmp_path):
    from peclet.packing.bed.api import resolve_element
    values, _ = sphere_values(n=15, h=0.1, r=0.5)
    path = grids.save_grid(tmp_path / "bean.npz", values, 0.1, origin=[-0.7, -0.7, -0.7])
    el = resolve_element(str(path))
    assert abs(el.builder.eval_root(el.root, [[0.0, 0.0, 0.0]])[0] + 0.5) < 1e-12


@functools.lru_cache(maxsize=1)
def _sphere_twins():
    """(grid sphere particle, analytic sphere particle): r 0.5, the grid at h 0.05 = R/10, both
    measured and shelled by scene_particle.build the same way."""
    from peclet.dem import scene_particle

    def particle(grid):
        b = geom.SceneBuilder()
        if grid:
            r = grids.grid_from_callable(b, lambda p: np.linalg.norm(p, axis=1) - 0.5,
                                         [-0.5] * 3, [0.5] * 3, 0.05)
        else:
            r = b.add_leaf("sphere", [0.5])
        return scene_particle.build(b, r, bounds=([-0.8] * 3, [0.8] * 3), n=16, tol=1e-6,
                                    target_shell_points=400, shell_resolution=40)
    return particle(True), particle(False)


def _rebound(sp, hertz=False):
    """Head-on rebound (separation over approach speed) of two copies of ``sp``, e = 0.5."""
    from peclet.dem import Simulation
    sim = Simulation(2)
    sim.set_gravity(0.0, 0.0, 0.0)
    sim.set_material_params(0.5, 0.0, 0.0)
    sid = sp.register(sim)
    gap = 0.502 if hertz else 0.6
    sim.set_positions(np.array([[-gap, 0.0, 0.0], [gap, 0.0, 0.0]]))
    sim.set_shape_ids(np.array([sid, sid], np.int32))
    sim.set_quaternions(np.tile([0.0, 0.0, 0.0, 1.0], (2, 1)))
    sim.set_inv_mass(np.full(2, 1.0 / sp.mass))
    sim.set_inv_inertia(np.tile(1.0 / sp.principal, (2, 1)))
    sim.set_velocities(np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]]))
    if hertz:                   # E 1e7, density 1: contact time ~1.5e-3, 1e-5 steps
        sim.set_hertz_material(0, 1e7, 0.3)
        sim.set_contact_law("hertz")
        sim.set_dt(1e-5)
        sim.advance(2000)
    else:
        sim.set_dt(1e-3)
        for _ in range(300):
            sim.step()
    v = sim.get_velocities()
    return (v[1, 0] - v[0, 0]) / 2.0


@pytest.mark.heavy
def test_grid_sphere_particles_collide_like_their_analytic_twins():
    """Impulse engine: two grid spheres (r 0.5, h 0.05 = R/10) head-on rebound like two
    analytic sphere leaves built the same way (e = 0.5 asked). Measured: 0.459 against 0.486
    at R/10; at R/4 (h 0.125) 0.345, the interpolant's normals ~10 deg off the radius turning
    the impulse sideways."""
    grid, exact = _sphere_twins()
    assert abs(grid.volume / exact.volume - 1.0) < 0.01          # the interpolant at R/10
    e_grid, e_exact = _rebound(grid), _rebound(exact)
    assert 0.4 < e_grid < 0.55 and abs(e_grid - e_exact) < 0.05, (e_grid, e_exact)


@pytest.mark.heavy
@pytest.mark.xfail(strict=True, reason="Hertz engine with a grid leaf: measured rebound 0.387 "
                   "against 0.49996 for the analytic twin (e = 0.5 asked). Suspected cause: "
                   "R* comes from the surfaces' curvatures, which for a trilinear interpolant "
                   "jump from cell to cell, so the force law changes during the contact and "
                   "is not conservative; not yet fixed (issue 41)")
def test_grid_sphere_particles_rebound_in_the_hertz_engine():
    grid, exact = _sphere_twins()
    h_grid, h_exact = _rebound(grid, hertz=True), _rebound(exact, hertz=True)
    assert abs(h_exact - 0.5) < 0.02 and abs(h_grid - h_exact) < 0.05, (h_grid, h_exact)


def test_container_from_a_vessel_mesh(tmp_path):
    from peclet.packing.bed.containers import parse_container
    path = tmp_path / "vessel.stl"
    trimesh.creation.cylinder(radius=60.0, height=200.0).export(path)      # mm: 12 x 40 D
    c = parse_container(f"{path}:scale=0.1,resolution=0.25")
    assert c.kind == "tree"
    b = geom.SceneBuilder.decode(c.tree[0], c.tree[1])
    phi = b.eval_root(c.tree[2], [[0.0, 0.0, 0.0], [5.0, 0.0, 0.0], [7.0, 0.0, 0.0]])
    assert phi[0] < -5.5 and phi[1] < 0 < phi[2]
    with pytest.raises(PecletArgumentError, match="container"):
        parse_container(f"{tmp_path / 'none.stl'}")


def test_lattice_aligned_quadrature_measures_the_same_solid():
    """One top quadrature cell per lattice cell (grids.quadrature_layout) against a box with
    four lattice cells in each top cell: the same trilinear solid, so the same volume within
    the unaligned run's error estimate."""
    b = geom.SceneBuilder()
    g = grids.grid_from_callable(b, lambda p: np.linalg.norm(p, axis=1) - 1.0, [-1.0] * 3,
                                 [1.0] * 3, 0.25)
    lo, hi, n = grids.quadrature_layout(b, g)
    dims = b.node(g)[3][1:4]
    assert dims[0] == dims[1] == dims[2] and n == 4 * (dims[0] - 1)
    aligned = b.body_properties(g, lo, hi, n=n, tol=1e-6)
    coarse = b.body_properties(g, lo, hi, n=n // 4, tol=1e-6)
    assert abs(aligned.volume - coarse.volume) <= 2 * coarse.volume_error + 1e-12
    assert abs(aligned.volume / (4 / 3 * np.pi) - 1) < 0.05          # the interpolant at h 0.25
    assert grids.quadrature_layout(b, b.add_reframed(g, rotation=[0, 0, 0.6, 0.8])) is None


def test_a_simulation_with_a_grid_shape_and_wall_saves_and_resumes_bitwise(tmp_path):
    """The samples travel in the node arrays: a checkpoint of a run with a grid particle and a
    grid wall resumes to the same bits (persistence needs nothing of its own for grids)."""
    from peclet.dem import Simulation
    b = geom.SceneBuilder()
    g = grids.grid_from_callable(b, lambda p: np.linalg.norm(p, axis=1) - 0.5, [-0.5] * 3,
                                 [0.5] * 3, 0.125)
    shell = np.random.default_rng(0).normal(size=(200, 3))
    shell *= 0.5 / np.linalg.norm(shell, axis=1)[:, None]
    wb = geom.SceneBuilder()
    floor = grids.grid_from_callable(wb, lambda p: np.maximum(np.abs(p[:, 1] + 0.5) - 0.5,
                                                              np.abs(p[:, [0, 2]]).max(1) - 3),
                                     [-3.0, -1.0, -3.0], [3.0, 0.0, 3.0], 0.25)
    sim = Simulation(3)
    sid = sim.add_scene_shape(*b.encode()[:2], g, shell, 0.5)
    sim.add_analytic_wall(*wb.encode()[:2], floor, False, 0.5, 0.3)
    sim.set_positions(np.array([[0.0, 0.7, 0.0], [1.2, 0.9, 0.0], [-1.2, 1.4, 0.3]]))
    sim.set_shape_ids(np.full(3, sid, np.int32))
    sim.set_quaternions(np.tile([0.0, 0.0, 0.0, 1.0], (3, 1)))
    sim.set_inv_mass(np.ones(3))
    sim.set_inv_inertia(np.full((3, 3), 10.0))
    sim.set_dt(2e-3)
    for _ in range(100):
        sim.step()
    assert sim.get_positions()[:, 1].min() > 0.3          # resting on the grid floor
    sim.save(tmp_path / "run.npz")
    again = Simulation.load(tmp_path / "run.npz")
    for s in (sim, again):
        for _ in range(50):
            s.step()
    assert sim.state_hash() == again.state_hash()


def test_a_refused_grid_leaves_the_builder_as_it_was():
    values, _ = sphere_values(n=9, h=0.35)
    b = geom.SceneBuilder()
    with pytest.raises(PecletArgumentError, match="scale"):
        b.add_grid(values, 0.35, scale=-1.0)
    assert b.num_nodes() == 0


@pytest.mark.heavy
def test_a_bed_in_a_vessel_mesh_with_a_plate_is_analysed_over_its_fluid_only(tmp_path):
    # the CLI's report used to fail on any tree container (a vessel from a mesh); the voidage
    # counts only the vessel's fluid region, and the bed stands on the plate, not the vessel's
    # lowest point
    import sys
    sys.path.insert(0, str(__import__("pathlib").Path(__file__).parents[1] / "examples"))
    import support_plate as SP

    from peclet.packing.bed.api import pack
    from peclet.packing.output import report
    stl = SP.write_vessel_stl(tmp_path / "vessel.stl", lattice=91)
    res = pack("sphere", f"{stl}:scale={1 / SP.MM_PER_D}", 40, "rain", seed=2, progress=False)
    y = res.pack.positions[:, 1]
    assert y.min() > SP.PLATE_Y + 0.5 * SP.PLATE_T + 0.45          # on the plate, none below
    rep = report.analyse(res, None, figures=False, exports=False, samples=20_000)
    assert report.bed_floor(res.pack, res.container) == pytest.approx(y.min() - 0.5)
    assert 0.3 < rep["bulk"]["eps"] < 0.9 and rep["bulk"]["eps_se"] < 0.1
