"""The narrow phase's culling (distance grid, super-clusters, clusters, per-probe bounds) and its
pruned programs never change a contact: the same contacts, bit for bit, as evaluating the whole
tree at every probe within reach."""
import numpy as np

from peclet.dem import Simulation
from peclet.dem.distgrid import lower_bound

from test_dem_composed import _BUILDERS, floor_wall, pall_ring_particle


def _dense_bed(seed=3, n=24, L=3.5):
    sp = pall_ring_particle()
    rng = np.random.default_rng(seed)
    sim = Simulation(n + 2)
    sim.set_domain((0.0, -1.0, 0.0), (L, 10.0, L))
    sim.enable_periodicity(True, False, True)
    ring = sp.register(sim)
    ball = sim.add_sphere_shape(0.3)
    floor_wall(sim, centre=(L / 2, L / 2))
    pos = np.column_stack([rng.uniform(0, L, n + 2), rng.uniform(0.2, 1.4, n + 2),
                           rng.uniform(0, L, n + 2)])
    q = rng.normal(size=(n + 2, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    sim.set_positions(pos)
    sim.set_quaternions(q)
    sim.set_shape_ids(np.array([ring] * n + [ball, ball]))
    sim.set_inv_mass(np.ones(n + 2))
    sim.set_inv_inertia(np.ones((n + 2, 3)))
    # speed sets the speculative margin: a wide one makes many near-miss probes
    sim.set_velocities(rng.normal(scale=2.0, size=(n + 2, 3)))
    sim.set_dt(2e-3)
    return sp, sim


def test_culled_contacts_equal_every_probe_evaluated():
    sp, sim = _dense_bed()
    fast = sim.detect_contacts()
    geo = sim.world.geometry()
    # no Lipschitz culling, no grid: every probe within the bounding spheres is evaluated
    # and no pruned programs (no lattice: every evaluation runs the whole program)
    sim.world._geo = geo._replace(shape_lip=np.zeros_like(geo.shape_lip),
                            wall_lip=np.zeros_like(geo.wall_lip),
                            shape_grid_dims=np.zeros_like(geo.shape_grid_dims),
                            shape_pdims=np.zeros_like(geo.shape_pdims))
    brute = sim.detect_contacts()
    sim.world._geo = geo
    assert len(fast["depth"]) > 50
    assert {int(b) for b in fast["body_b"]} >= {-1}           # the floor is in it
    assert set(fast) == set(brute)
    for k in fast:
        assert np.array_equal(fast[k], brute[k]), k


def test_grid_bound_never_exceeds_phi_and_is_tight_near_the_surface():
    sp = pall_ring_particle()
    sim = Simulation(1)
    sp.register(sim)
    s = sim.world.shapes[0]
    b = _BUILDERS[id(sp)]
    rng = np.random.default_rng(7)
    h = s.grid_oh[3]
    near = sp.shell + rng.normal(scale=0.05, size=sp.shell.shape)
    far = rng.uniform(-1.5 * s.radius, 1.5 * s.radius, size=(4000, 3))   # beyond the lattice too
    pts = np.ascontiguousarray(np.concatenate([near, far]))
    phi = b.eval_root(sp.home_root, pts)
    lb = np.array([lower_bound(s.grid, 0, s.grid_dims, s.grid_oh, *p) for p in pts])
    assert np.all(lb <= phi)
    assert np.isfinite(lb).sum() > 1000
    # 1-Lipschitz both ways: phi <= phi(node) + d, so phi - lb <= 2 d <= sqrt(3) h where the
    # nearest node lies in the lattice and its value is an exact, positive evaluation
    inside = (np.all(np.abs(pts) <= s.radius, axis=1) & (phi > 0.0) & (phi < 2.0 * h)
              & np.isfinite(lb))
    assert inside.sum() > 100
    assert np.all(phi[inside] - lb[inside] <= np.sqrt(3.0) * h * (1 + 1e-9))
