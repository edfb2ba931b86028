"""Per-block pruned CSG programs (peclet.core.geom.pruning): bit-for-bit the full program.

The reference is always the full program evaluated by kernels.eval_point; "bitwise" compares
phi and the gradient as int64 bit patterns (so -0.0 != 0.0 and NaN == NaN of the same payload)
and the active feature st[0, 4] as integers.
"""
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from peclet.core import geom
from peclet.core.geom import kernels as K
from peclet.core.geom.program import compile_root
from peclet.core.geom.program import concatenate
from peclet.core.geom.pruning import (_combine, _decide, _lookup_ranges, bake_pruned,
                                      concatenate_pruned, eval_ranges, evaluate_full,
                                      evaluate_pruned, lookup_ranges)
from peclet.core.validation import PecletArgumentError
from peclet.dem import distgrid
from peclet_verify.geometry import strategies as GS

import page_steps


def assert_bitwise(prog, table, pts):
    full = evaluate_full(prog, pts)
    pruned = evaluate_pruned(table, prog, pts)
    for name, a, b in zip(("phi", "grad", "feature"), full, pruned):
        if a.dtype == np.float64:
            a, b = a.view(np.int64), b.view(np.int64)
        bad = np.flatnonzero((a != b).reshape(len(pts), -1).any(axis=1))
        assert bad.size == 0, (f"{name} differs at {bad.size} of {len(pts)} points, e.g. "
                               f"{pts[bad[0]].tolist()}")


def lattice_points(table, g, n):
    """Points on block corners, edges and faces (every block plane), and one ulp either side."""
    o, blk, dims = table.ob[:3], table.ob[3], table.dims
    idx = g.integers(0, dims + 1, (n, 3))
    on = o + idx * blk                                   # corners
    free = g.uniform(o, o + dims * blk, (n, 3))
    mask = g.random((n, 3)) < 0.5                        # faces / edges / corners mixed
    pts = np.where(mask, on, free)
    return np.concatenate([on, pts, np.nextafter(pts, np.inf), np.nextafter(pts, -np.inf)])


def near_surface_points(prog, g, lo, hi, n, band):
    """Points with |phi| < band and their Newton projections onto the surface (+-1 ulp)."""
    p = g.uniform(lo, hi, (20 * n, 3))
    phi, grad, _ = evaluate_full(prog, p)
    keep = np.abs(phi) < band
    p, phi, grad = p[keep][:n], phi[keep][:n], grad[keep][:n]
    s = p - phi[:, None] * grad
    return np.concatenate([p, s, np.nextafter(s, np.inf), np.nextafter(s, -np.inf)])


# ---------------------------------------------------------------------------- the Pall ring
def ring_programs():
    """The page's ring in its authoring frame, and in the DEM's home (principal) frame."""
    from test_dem_composed import pall_ring_particle
    sp = pall_ring_particle()
    return [(page_steps.b.program(page_steps.ring), 0.7071067811865476),
            (compile_root(sp.node_ints, sp.node_reals, sp.home_root), sp.bounding_radius)]


def distgrid_lattice(radius, cells):
    """distgrid.bake's lattice (h = R/32, origin -(32 + 2) h) cut into blocks of ``cells``."""
    h = radius / distgrid.CELLS_PER_RADIUS
    n = 2 * (distgrid.CELLS_PER_RADIUS + distgrid.PAD_CELLS)
    return np.full(3, -(distgrid.CELLS_PER_RADIUS + distgrid.PAD_CELLS) * h), cells * h, \
        [n // cells] * 3


@pytest.mark.parametrize("cells", [1, 2, 4])
def test_ring_bitwise_everywhere(cells):
    g = np.random.default_rng(17 + cells)
    for prog, radius in ring_programs():
        origin, block, dims = distgrid_lattice(radius, cells)
        table = bake_pruned(prog, origin, block, dims)
        hi = -origin * 1.05                                 # a few points outside the lattice
        pts = np.concatenate([
            g.uniform(-hi, hi, (40_000, 3)),
            lattice_points(table, g, 10_000),
            near_surface_points(prog, g, -hi, hi, 10_000, 2 * block)])
        assert_bitwise(prog, table, pts)


def test_ring_programs_are_short_and_outside_gets_full():
    prog, radius = ring_programs()[1]
    full = prog.op_end - prog.op_begin
    origin, block, dims = distgrid_lattice(radius, 2)
    table = bake_pruned(prog, origin, block, dims)
    rows = table.block_rows()
    assert rows.max() < full and rows.mean() < full / 4
    # near the surface, where the narrow phase evaluates
    g = np.random.default_rng(3)
    near = near_surface_points(prog, g, origin, -origin, 5000, 0.05)
    rng = lookup_ranges(table, near)
    assert (rng[:, 1] - rng[:, 0]).mean() < full / 3
    # the full program is stored verbatim and is what points off the lattice get
    assert np.array_equal(table.ops[table.full_begin:table.full_end],
                          prog.ops[prog.op_begin:prog.op_end])
    top = -origin[0]
    off = np.array([[top + 1e-9, 0.0, 0.0], [0.0, -top - 0.1, 0.0], [0.0, 0.0, 5.0],
                    [np.nan, 0.0, 0.0], [0.0, np.inf, 0.0], [top, 0.0, 0.0]])
    rng = lookup_ranges(table, off)
    assert np.all(rng[:, 0] == table.full_begin) and np.all(rng[:, 1] == table.full_end)
    assert_bitwise(prog, table, off[[0, 1, 2, 4, 5]])
    # deterministic
    again = bake_pruned(prog, origin, block, dims)
    assert np.array_equal(again.ops, table.ops)
    assert np.array_equal(again.block_range, table.block_range)


def test_far_apart_spheres_prune_to_the_near_one():
    # union(A, B), centres 10 apart, radius 1: in a block of diagonal < 1 next to A, phi_B -
    # phi_A > 8 - diagonal, so B can never be selected and the program is A's push alone; in
    # a block next to B, B is always strictly smaller: B's push alone.
    b = geom.SceneBuilder()
    u = b.add_union(b.add_leaf("sphere", [1.0]),
                    b.add_leaf("sphere", [1.0], translation=[10.0, 0.0, 0.0]))
    prog = b.program(u)
    table = bake_pruned(prog, [-2.0, -2.0, -2.0], 0.5, [28, 8, 8])
    rng = lookup_ranges(table, np.array([[0.1, 0.2, 0.3], [10.1, 0.2, 0.3]]))
    a_push = prog.ops[prog.ops[:, 0] == K.OP_LEAF][0]
    b_push = prog.ops[prog.ops[:, 0] == K.OP_LEAF][1]
    assert np.array_equal(table.ops[rng[0, 0]:rng[0, 1]], a_push[None])
    assert np.array_equal(table.ops[rng[1, 0]:rng[1, 1]], b_push[None])
    # the midplane block keeps both (phi_A = phi_B there)
    mid = lookup_ranges(table, np.array([[5.0, 0.1, 0.1]]))
    assert mid[0, 1] - mid[0, 0] == 3


@pytest.mark.parametrize("case", ["tie_union", "tie_intersection", "tie_difference",
                                  "half_space", "shared_face", "far_from_origin"])
def test_ties_and_unbounded_leaves(case):
    # operands that are equal on whole regions (ties keep the left operand, so the feature
    # tells which one was kept), an unbounded half-space, and coordinates ~1e4 (round-off
    # ~1e-12 absolute, far above the ulps of the values near the surface)
    shift = np.array([1e4, -2e4, 3e4]) if case == "far_from_origin" else np.zeros(3)
    b = geom.SceneBuilder()
    s1 = b.add_leaf("sphere", [0.6])
    s2 = b.add_leaf("sphere", [0.6])
    if case == "tie_union":
        root = b.add_union(s1, s2)
    elif case == "tie_intersection":
        root = b.add_intersection(s1, s2)
    elif case == "tie_difference":
        root = b.add_difference(s1, b.add_leaf("sphere", [0.6], scale=1.0))
    elif case == "half_space":
        root = b.add_difference(s1, b.add_leaf("half_space", [0.0, 1.0, 0.0, 0.1]))
    elif case == "shared_face":
        root = b.add_union(b.add_leaf("box", [0.5, 0.5, 0.5], translation=[-0.5, 0, 0]),
                           b.add_leaf("box", [0.5, 0.5, 0.5], translation=[0.5, 0, 0]))
    else:
        u = b.add_union(b.add_leaf("box", [0.3, 0.4, 0.5], rotation=[0.0, 0.6, 0.0, 0.8]),
                        b.add_leaf("torus", [0.5, 0.1], translation=[0.2, 0.1, 0.0]))
        root = b.add_reframed(b.add_difference(u, s1), translation=shift.tolist())
    prog = b.program(root)
    table = bake_pruned(prog, shift - 1.25, 0.125, [20, 20, 20])
    g = np.random.default_rng(5)
    lo, hi = shift - 1.3, shift + 1.3
    pts = np.concatenate([g.uniform(lo, hi, (20_000, 3)), lattice_points(table, g, 5000),
                          near_surface_points(prog, g, lo, hi, 3000, 0.2)])
    assert_bitwise(prog, table, pts)


@pytest.mark.parametrize("kind,params", [("ellipsoid", [0.9, 0.08, 0.3]),
                                         ("superquadric", [0.7, 0.1, 0.4, 0.2])])
def test_non_lipschitz_leaf_never_pruned(kind, params):
    # A thin ellipsoid/superquadric: its value at a block centre says little about the block
    # (not 1-Lipschitz), so it must survive in every block's program.
    b = geom.SceneBuilder()
    nl = b.add_leaf(kind, params, rotation=[0.3, 0.1, 0.0, float(np.sqrt(0.9))])
    box = b.add_leaf("box", [0.2, 0.2, 0.2], translation=[0.6, 0.0, 0.0])
    sph = b.add_leaf("sphere", [0.3], translation=[-0.5, 0.3, 0.0])
    root = b.add_union(b.add_difference(nl, box), b.add_intersection(sph, nl))
    prog = b.program(root)
    rows_nl = {int(j) for c, j in prog.ops if c == K.OP_LEAF and prog.leaf_kind[j] ==
               geom.leaf_spec(kind).kind}
    table = bake_pruned(prog, [-1.0, -1.0, -1.0], 0.1, [20, 20, 20])
    for b0, b1 in table.block_range:
        rows = table.ops[b0:b1]
        assert rows_nl <= {int(j) for c, j in rows if c == K.OP_LEAF}
    g = np.random.default_rng(9)
    pts = np.concatenate([g.uniform(-1.1, 1.1, (20_000, 3)), lattice_points(table, g, 5000),
                          near_surface_points(prog, g, -1.1, 1.1, 3000, 0.1)])
    assert_bitwise(prog, table, pts)


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(recipe=GS.trees(max_leaves=7), n_blocks=st.integers(1, 9), seed=st.integers(0, 99))
def test_random_trees_bitwise(recipe, n_blocks, seed):
    b, root = recipe.build()
    prog = b.program(root)
    c, r, _ = b.node_bound(root)
    g = np.random.default_rng(seed)
    origin = c - 1.1 * r
    table = bake_pruned(prog, origin, 2.2 * r / n_blocks, [n_blocks] * 3)
    lo, hi = c - 1.3 * r, c + 1.3 * r
    pts = np.concatenate([g.uniform(lo, hi, (2000, 3)), lattice_points(table, g, 500),
                          near_surface_points(prog, g, lo, hi, 500, 0.05 * r)])
    assert_bitwise(prog, table, pts)


def test_concatenated_tables_match_each_full_program():
    # shapes packed as the DEM packs them (program.concatenate): a ring with a table, a
    # sphere without one (always the full program), two spheres with a table
    prog_ring, radius = ring_programs()[1]
    b = geom.SceneBuilder()
    prog_s = b.program(b.add_leaf("sphere", [0.3], translation=[0.1, 0.0, 0.0]))
    prog_u = b.program(b.add_union(b.add_leaf("box", [0.2, 0.3, 0.1]),
                                   b.add_leaf("sphere", [0.2], translation=[0.5, 0.0, 0.0])))
    progs = [prog_ring, prog_s, prog_u]
    tables = [bake_pruned(prog_ring, *distgrid_lattice(radius, 2)), None,
              bake_pruned(prog_u, [-0.5, -0.5, -0.5], 0.1, [12, 10, 10])]
    _, lk, lr, _ = concatenate(progs)
    ps = concatenate_pruned(progs, tables)
    g = np.random.default_rng(11)
    pts = g.uniform(-0.8, 0.8, (20_000, 3))
    for i, p in enumerate(progs):
        rng = _lookup_ranges(ps.block_range, ps.block_off[i], ps.ob[i], ps.dims[i],
                             ps.full[i, 0], ps.full[i, 1], pts)
        if tables[i] is None:
            assert np.all(rng == ps.full[i])
        got = eval_ranges(ps.ops, lk, lr, rng, pts)
        ref = evaluate_full(p, pts)
        # the feature numbers leaf rows of the concatenated table: shift the reference's
        shift = sum(len(q.leaf_kind) for q in progs[:i]) * K.FEATURES
        for a, c in zip(ref[:2] + (ref[2] + shift,), got):
            assert np.array_equal(a.view(np.int64) if a.dtype == np.float64 else a,
                                  c.view(np.int64) if c.dtype == np.float64 else c)
    with pytest.raises(PecletArgumentError) as e:
        concatenate_pruned(progs, tables[:2])
    assert e.value.argument == "tables"


def _select(code, a, b):
    # eval_point's operator comparisons, written out independently: (value, took_b)
    if code == K.OP_UNION:
        return (b, True) if b < a else (a, False)
    if code == K.OP_INTERSECTION:
        return (b, True) if b > a else (a, False)
    return (-b, True) if -b > a else (a, False)


@pytest.mark.parametrize("code", [K.OP_UNION, K.OP_INTERSECTION, K.OP_DIFFERENCE])
def test_decisions_agree_with_the_operators_at_ties(code):
    # Ranges with endpoints on a coarse grid, so that touching and nested ranges are common,
    # nudged by 0 or +-1e-13 (below the decision margin). Whenever an operand is dropped, the
    # operator must agree at every combination of endpoints and midpoints; the kept range must
    # contain the value; clearly separated ranges must be decided.
    g = np.random.default_rng(code)
    decided = 0
    for _ in range(3000):
        e = np.sort(g.integers(-3, 4, 2)).astype(float), np.sort(g.integers(-3, 4, 2)) * 1.0
        (alo, ahi), (blo, bhi) = [x + g.choice([0.0, 1e-13, -1e-13], 2) for x in e]
        alo, ahi, blo, bhi = min(alo, ahi), max(alo, ahi), min(blo, bhi), max(blo, bhi)
        keep = _decide(code, alo, ahi, blo, bhi)
        lo, hi = _combine(code, alo, ahi, blo, bhi)
        for a in (alo, ahi, 0.5 * (alo + ahi)):
            for b in (blo, bhi, 0.5 * (blo + bhi)):
                v, took_b = _select(code, a, b)
                assert lo <= v <= hi
                if keep == 1:
                    assert not took_b, (alo, ahi, blo, bhi)
                elif keep == 2:
                    assert took_b and code != K.OP_DIFFERENCE, (alo, ahi, blo, bhi)
        if keep:
            decided += 1
        if code == K.OP_DIFFERENCE:
            assert (keep == 1) == (alo > -blo + 0.5) or abs(alo + blo) < 0.5
        elif blo > ahi + 0.5 or bhi < alo - 0.5:
            assert keep != 0
    assert decided > 300
    # an unbounded operand decides nothing
    assert _decide(code, -np.inf, np.inf, 5.0, 6.0) == 0
    assert _decide(code, 5.0, 6.0, -np.inf, np.inf) == 0


# ---------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("kw,name", [
    (dict(block=0.0), "block"), (dict(block=-1.0), "block"), (dict(block=np.nan), "block"),
    (dict(block="1"), "block"), (dict(dims=[0, 4, 4]), "dims"), (dict(dims=[4, 4]), "dims"),
    (dict(dims=[4, 4, 1.5]), "dims"), (dict(dims=[4, True, 4]), "dims"),
    (dict(dims=[1 << 10] * 3), "dims"), (dict(origin=[np.nan, 0.0, 0.0]), "origin"),
    (dict(origin=[0.0, 0.0]), "origin"), (dict(origin="abc"), "origin")])
def test_bad_input_names_the_argument(kw, name):
    b = geom.SceneBuilder()
    prog = b.program(b.add_leaf("sphere", [1.0]))
    args = dict(origin=[-1.0, -1.0, -1.0], block=0.5, dims=[4, 4, 4])
    args.update(kw)
    with pytest.raises(PecletArgumentError) as e:
        bake_pruned(prog, **args)
    assert e.value.argument == name
