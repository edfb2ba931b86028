"""The quadrature's tuning constants, in one place, each with the reason for its value.

Lengths given "of the cell" / "of the probe interval" are fractions of the cell's (or the
interval's) extent along the axis concerned. Changing any of these changes the engine's bits
(``scripts/fingerprint.py``); the measured trade-offs are noted where they were measured.

Integer constants that kernels pass to other kernels (scratch rows, step counts, re-probes)
are numpy int64 scalars: Numba types a global Python int as a literal and compiles a callee
once per literal value it is called with; a global np.int64 is an ordinary int64 (one
compilation). ``I0``/``I1``/``I2`` stand for the small counts written at call sites.
"""

import numpy as np

#: 0, 1 and 2 as int64 arguments of kernel calls (see the module notes).
I0, I1, I2 = np.int64(0), np.int64(1), np.int64(2)

# ------------------------------------------------------------------ scratch and capacities
#: Max roots along one line, knots and breakpoints across one cell (a scratch row each). A
#: line crossing the surface more often, or a cell with more breaks, is an overflow: the cell
#: is integrated again without re-probes, then the whole call fails (a pathological tree).
MAX_BREAKS = 128
#: Rows of the per-thread scratch S: line roots and their features, knot search roots and
#: features, v-knots, v-breaks and their tangency flags, u-knots, u-breaks and flags, extra
#: v-probes, piece midpoints carried from neighbouring u (two ends, the next probe and the
#: u-piece's centre), the ends' previous midpoints, two rows for extrapolated midpoints, and
#: the midpoints at a bracket's start. Named rows, so that no kernel hard-codes an index.
(R_ROOT, R_LEAF, R_KROOT, R_KLEAF, R_VKNOT, R_VBRK, R_VFLAG, R_UKNOT, R_UBRK, R_UFLAG, R_EXTRA,
 R_MLO, R_MHI, R_MY, R_MC, R_MLP, R_MHP, R_XP, R_XT, R_MX) = (np.int64(i) for i in range(20))
SCRATCH_ROWS = 20
#: v-probes remembered per u-piece from the scan (see cell_rule.cell_rules): enough for the
#: midpoints of every v-piece a u-piece's probes saw, in the cells measured (the Pall ring's
#: worst has under 20); more are dropped, costing only a re-probe's chance to follow a wedge.
SEEDS = 32

# ------------------------------------------------------------------ the line search (inner)
#: A line search resolves pairs of roots down to LINE_EPS of the line: below that, the run
#: between them carries no measurable length at any tol the API accepts (>= 1e-16 relative).
LINE_EPS = 1e-10
#: Depth of the line search's stack of halvings: each halving pushes two entries, and
#: LINE_EXTRA halvings of one step can never be nested deeper than log2(line / LINE_EPS) ~ 34.
LINE_STACK = 64
#: ``lip`` (passed down every kernel) is 0 for a tree that is not 1-Lipschitz, else the cap on
#: certifying halvings per line (see line_search.line_roots): LINE_EXTRA when tol <
#: CERTIFY_TOL, else LINE_EXTRA_LOOSE. A capped line may miss a pair of roots narrower than a
#: step; measured on the Pall ring (against its exact volume) that costs 3e-10 relative at the
#: loose cap, and the full cap costs 4x the time.
LINE_EXTRA = 1024
LINE_EXTRA_LOOSE = 64
CERTIFY_TOL = 1e-8
#: A step left unproved is searched for an extremum of the other sign (see line_search.dip):
#: at most DIP_STEPS evaluations each (regula falsi converges on a tangency's parabola in one
#: or two), DIP_BUDGET per line (a bound on the time a grazing line can cost).
DIP_STEPS = 30
DIP_BUDGET = 256

# ------------------------------------------------------------------ the break search (v and u)
#: Levels of refinement below the top cells: 2^-8 of a top cell is below any structure the
#: probes resolve at the tolerances accepted, and it bounds the work of a cell that never
#: converges (reported as ``unconverged_cells``).
MAX_DEPTH = 8

#: Most cells one quadrature may integrate. The page's ring needs 544-1184 cells at tol 1e-6 to
#: 1e-10; a solid far thinner than its box (a slab 1e-5 thick across a unit box) makes every
#: level of refinement 4x larger and would run for minutes: past this budget the quadrature
#: stops with an error saying so instead (refine.integrate_body).
MAX_CELLS = 50_000
#: Signature probes across a cell (intervals). With it the top-level cell count follows from
#: the sampling resolution: ``ceil(n / V_PROBES)`` cells per axis (see api.body_properties).
V_PROBES = 4
#: Breaks closer than FLICKER (of the cell) to the previous one are a signature flickering at a
#: tangency, not structure: they are stepped over.
FLICKER = 1e-10
#: Structure is probed this far (of the cell) inside each knot segment: right at a knot a new
#: piece is thinner than the level below resolves, and probing there would only find it again
#: by bisection. Only where to look moves; pieces still start at the exact knots.
V_NUDGE = 1e-11
U_NUDGE = 1e-9
#: Bisection steps locating a breakpoint of the inner integrand (2^-44 of the cell): it may
#: jump there (a wall parallel to the height axis), so the location must be sharp.
BREAK_STEPS = np.int64(44)
#: ... but past KINK_STEPS a bracket across which the line's inside length changes by less than
#: KINK_SLOPE x its width holds a kink (or a jump of that size), whose misplacement costs only
#: O(width^2): the bisection stops there.
KINK_STEPS = np.int64(20)
KINK_SLOPE = 1e3
#: ... and of the outer integrand (2^-30 of the probe interval): it jumps only at a wall normal to
#: u, whose trace on the cell's edges is a u-knot, found exactly, unless the wall ends inside.
U_BREAK_STEPS = np.int64(30)
#: While locating a u-breakpoint only the v-structure (the sequence of piece signatures)
#: matters, not where its breaks sit: its v-bisections stop at 2^-HASH_STEPS.
HASH_STEPS = np.int64(12)
#: ... but inside a u-bisection the v-pieces seen are the probes of the next step, and a
#: piece thinning to a vertex is followed only while its midpoint is sharper than its width.
TRACK_STEPS = np.int64(24)
#: Re-probes of a bisected u-break's upper end per probe interval (see breaks.locate_u); a
#: cell that overflows with them is integrated again without.
U_REPROBES = np.int64(4)
#: A re-probe attempt of the u-bisection first follows the upper end's pieces down from it in
#: doubling steps, the first this fraction of the bracket (then at most 24 probes reach its
#: lower end). A thin box turned off the axes (half extents 0.10 x 1.0 x 0.10) lost a wedge at
#: a vertex: it first shows at a probe 0.0097 above the vertex, its midpoint moving 14 times
#: faster than it opens, and bisection from the bracket's middle never saw it again.
U_FOLLOW = 2.0 ** -24
#: ... and a u-bisection goes below its bracket (a change the scan passed, unseen at its last
#: probe, as in that box) only when every v-piece seen there is wider than this fraction of
#: the cell: a grazing pair of roots (round-off's flicker at a tangency) is far narrower
#: (without this test the rotated torus of tests/test_quadrature.py ran over 15 minutes) ...
U_WIDE = 1e-6
#: ... and at most this many times per u-scan, which then goes on from below where it was
#: (without a cap the rotated hollow cylinder at tol 1e-9 did not finish in 10 minutes; with
#: 4, 39 s against 34 s for the code that never goes below, cold compile included).
U_BACKTRACKS = 4
#: u-breaks closer than this to the previous one are flicker (4 u-bisection resolutions).
U_FLICKER = 4.0 / (V_PROBES * 2.0 ** U_BREAK_STEPS)
#: More than U_ZONE_BREAKS breaks in a row each closer than U_ZONE (of the cell) to the one
#: before are a flicker zone, not structure (see breaks.scan_breaks). A thin torus gave a
#: steady run of breaks 2^-20 of the cell apart, just over the first threshold tried; a real
#: break the zone steps over leaves a kink inside a u-piece, which its rules' estimate then
#: reports.
U_ZONE = 2.0 ** -16
U_ZONE_BREAKS = 2
#: ... and a zone's step-over doubles up to U_ZONE_MAX (of the cell). Where two break curves
#: of the v-structure touch (the outline of a rim tangent to the outline of its wall), the
#: piece between them is thinner than any resolution over a stretch of u: its flicker zone can
#: be far wider than U_ZONE.
U_ZONE_MAX = 2.0 ** -12

# ------------------------------------------------------------------ missed structure, round-off
#: Newton projection onto the surface (see cell_rule.surface_in_cell): steps (quadratic
#: convergence from a start within a cell of the surface needs a handful), and |phi| (of the
#: cell) at which it has arrived.
PROJECT_STEPS = 12
PROJECT_EPS = 1e-12
#: A cell's rule "saw surface" when its volume is this far (relative) from empty and full:
#: a few thousand ulps, above the round-off of a full cell's moments.
SURFACE_FRAC = 1e-12
#: Round-off carried by a cut cell's moments, in ulps of its moment bound (see
#: refine.integrate_cells): each root is exact to a few ulps of its coordinates, and a moment
#: sums a few dozen of them per line.
ROUND_ULPS = 16.0
#: The float64 machine epsilon (2^-52).
EPS = 2.220446049250313e-16
