"""Steady D3Q19 lattice-Boltzmann flow on the fluid nodes of a :class:`LatticeGeometry`.

Lattice units (cell 1, step 1, rho0 = 1). One step, per fluid node, in one kernel (pull):

1. **stream**: ``f_i(x) = f*_i(x - c_i)`` along uncut links; on a cut link (wall at fraction
   q of the way from x towards x - c_i) Bouzidi, Firdaouss & Lallemand's (2001) linear
   interpolated bounce-back, with ``ib`` the opposite of ``i`` and ``x_f = x + c_i``:
   ``q < 1/2: f_i = 2q f*_ib(x) + (1 - 2q) f*_ib(x_f)``;
   ``q >= 1/2: f_i = f*_ib(x) / (2q) + (1 - 1/(2q)) f*_i(x)``.
   Where x_f is not a fluid node reachable by an uncut link (a gap of one cell), q < 1/2
   falls back to halfway bounce-back ``f_i = f*_ib(x)`` (counted in ``fallback_links``);
2. **mass correction**: interpolated bounce-back does not conserve mass. With ``mass="local"``
   (default) the mass the wall rule returns to a node beyond what the node sent into the wall,
   ``dm = sum over its cut links of (f_i - f*_ib(x))``, is taken back from that node at once,
   ``f_j -= w_j dm`` (no momentum): the wall then neither makes nor destroys mass anywhere,
   as halfway bounce-back. ``mass="global"`` only puts the domain's total loss of the
   previous step back evenly on every node; that leaves the local sources and sinks in
   place, and across a pressure difference they carry mass *through* a wall (sink on the
   high-pressure face, source on the low-pressure one): a channel closed by a plate 0.2
   cells thick (walls at q = 0.4) still carries a mass flux of 0.14 F in lattice units (F the
   body force; tests/test_flow.py). The even correction is kept in both modes, for round-off;
3. **moments**: rho = sum f, j = sum f c + F/2 (F the body force density, rho0 g), u = j/rho0
   (the incompressible equilibrium of He & Luo, so a steady Stokes field is independent of
   the density variations);
4. **TRT collision** (Ginzburg): symmetric and antisymmetric parts relax with omega+ and
   omega-; ``Lambda = (1/omega+ - 1/2)(1/omega- - 1/2) = 3/16`` by default; Guo's forcing
   split into its symmetric and antisymmetric parts, each with its own (1 - omega/2).

The node loop runs over blocks of nodes in parallel; each node writes only its own slots and
each block its own partial sums of rho and j, summed serially in block order afterwards, so
the result is the same bits at any Numba thread count.

**Superficial velocity** (the Darcy U of the result): the mass streamed along uncut links in
one step, ``sum over nodes and uncut links of f*_i c_i``, over the number of cells. It is the
mass flux through the lattice planes averaged over the planes (a cut link carries none, so a
closed channel gives 0); with the local mass correction every plane carries the same flux at
steady state. The mean of the node velocities u (``U_nodes``) differs from it at O(h^2) near
walls, and is not zero in a closed channel (a node beside a wall under a pressure gradient
has u != 0 although no mass crosses the wall).

**Convergence** (stated): every ``check_every`` steps (>= 2, a window of iterations) two
figures are measured, each as the mean over two consecutive steps: the mean node velocity
along the force U (sum of u over fluid nodes / all cells) and the force balance
``B = (momentum given to the walls per step along F) / (|F| n_fluid)`` (momentum exchange on
every cut link; apart from the walls the scheme conserves momentum exactly, so the two-step
mean of B - 1 is the rate at which the fluid's mean momentum still changes, relative to the
drive). With ``r = |U_k - U_(k-1)| / |U_k|`` and the ratio ``rho_k = r_k / r_(k-1)`` of
successive changes, the remaining change of a geometric approach is ``r_k rho_k / (1 -
rho_k)``. The run stops when ``r_k`` and that estimate are below ``tol`` (default 1e-6
relative) AND ``|B - 1|`` is below ``balance_tol`` (default 1e-4).

Why two-step means: packs (not the simple validation geometries) carry a period-2 mode that
barely decays: the fluid's total momentum alternates by a fraction of a percent of the drive
from one step to the next (measured: 0.34-0.36% of n|F| on rained sphere column sections at
D/8, its amplitude falling by only ~5e-7 relative per step; not seen in the empty pipe or the
sphere arrays). A check every ``check_every`` steps sees it at one phase only: U looks
converged to 1e-7 while the wall force of that phase is 0.36% off (the "0.9995" of earlier
runs). The two-step means cancel it (B then closes to ~1e-8 there), and the returned fields
are the means over the last two steps (the run takes one step more to have them);
``parity_swing`` reports the mode's amplitude (in units of B).

Its source (located on a rained column section, column:4, 90 spheres, at D/6, from the
difference of two consecutive steps): fluid nodes whose uncut links all lie in one plane, so
that their momentum along that plane's normal e meets only wall links; they are slivers of
fluid less than two cells thick, in the wedges where elements touch each other, the wall or the
floor. Mostly e is the force's direction: the 18 nodes there with every link that has a
component along the force cut carry 95% of the mode (of |u(t+1) - u(t)|^2); two nodes with a
diagonal e carry most of the rest, and e across the force gets only ~1% of the peak. Such a
momentum goes to a wall and comes back each step: the collision conserves it and bounce-back
reverses it, so it flips sign every step: ``j(t+1) = -(j(t) + F.e)`` for halfway bounce-back
(the rule such a node gets where q < 1/2 and no fluid node lies behind it), an eigenvalue of
exactly -1 about the fixed point u.e = 0; the interpolated rule for q >= 1/2 multiplies it by
``1 - 1/(2 q_i) - 1/(2 q_o)`` (damping it unless q is near 1/2), and the parabolic correction
shifts it slightly, whence the slow decay. The start from rest sets its amplitude (about F/2
per node). The alternation does not leave the node: its uncut links are normal to e, and their
equilibria see u.e only through (u.e)^2, nearly the same at both phases (exactly so about u.e =
0); the two-step difference of u at those nodes is along e, and on their neighbours below 1e-4
of its peak. Such a node carries no flux along e, so U and k do not see the mode; only the wall
force and the total momentum do, and the two-step means cancel it. Neither the magic parameter
(the collision conserves the node's momentum at any rates) nor the mass correction (it adds no
momentum) enters; plain Bouzidi without the parabolic correction keeps the mode, and starting
from populations at u = 0 halves it (both measured). (The bulk scheme has an exact period-2
invariant of its own, the momentum along an axis staggered along that axis, eigenvalue -1 at
wavevector pi there for any viscosity and magic parameter; the measured mode is not it: it
shows no staggering between neighbours.) tests/test_flow.py builds one such fluid layer.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from peclet.core.validation import (PecletArgumentError, check_array, check_choice, check_float,
                                    check_int)

from .geometry import LatticeGeometry
from .lattice import C, MAGIC_DEFAULT, OPP, Q, W, trt_rates
from .wall_rule import fallback_counts, link_table

__all__ = ["FlowResult", "solve", "BLOCK", "BALANCE_TOL"]

#: Default tolerance of the force balance |wall force / body force - 1| (convergence).
BALANCE_TOL = 1e-4

#: Nodes per block of the fixed-order reduction (independent of the thread count).
BLOCK = 2048

_CX = np.ascontiguousarray(C[:, 0].astype(np.float64))
_CY = np.ascontiguousarray(C[:, 1].astype(np.float64))
_CZ = np.ascontiguousarray(C[:, 2].astype(np.float64))


class Lattice(NamedTuple):
    """What the step reads of the fluid nodes, lattice units, built once per :func:`solve`:
    the pull table ``nb`` (19, N) int64 (the node population i is pulled from, or -1 - k on cut
    link k); per cut link k the wall rule of :func:`~peclet.flow.wall_rule.link_table` (``lc``
    (K, 3) coefficients, ``ld`` (K, 3) int64 populations, ``ln`` (K, 3) int64 nodes, ``la``
    (K,), ``lb`` (K,)), ``nm`` (K,) n-_i of the link's node at the previous step (each step
    writes it), the link's node ``lnode`` (K,) and pulled population ``ldir`` (K,); the velocity
    set: ``opp`` (19,) int64 opposite populations, ``cx``, ``cy``, ``cz`` (19,) float64
    components of c_i and the weights ``w`` (19,)."""
    nb: np.ndarray
    lc: np.ndarray
    ld: np.ndarray
    ln: np.ndarray
    la: np.ndarray
    lb: np.ndarray
    nm: np.ndarray
    lnode: np.ndarray
    ldir: np.ndarray
    opp: np.ndarray
    cx: np.ndarray
    cy: np.ndarray
    cz: np.ndarray
    w: np.ndarray


class Drive(NamedTuple):
    """The collision's TRT rates ``om_p``, ``om_m`` (omega+ and omega-, per step), the body
    force density ``fx``, ``fy``, ``fz`` (lattice units, rho0 g) and ``local`` (1.0: the local
    mass correction of the wall rule, 0.0: the global one only; module docstring)."""
    om_p: float
    om_m: float
    fx: float
    fy: float
    fz: float
    local: float


@njit(cache=True, inline="always")
def _gather(n, fa, lat, f):
    """Pre-collision populations of node n into f (19,), from post-collision fa (19, N):
    streamed along uncut links, and on cut link k the combination
    sum_m lc[k, m] * fa[ld[k, m], ln[k, m]] + la[k] * nm[k] + lb[k] of the wall rule (see
    :func:`~peclet.flow.wall_rule.link_table`; nm[k] is n-_i of the node at the previous
    step)."""
    nb, lc, ld, ln, la, lb, nm = lat.nb, lat.lc, lat.ld, lat.ln, lat.la, lat.lb, lat.nm
    for i in range(19):
        s = nb[i, n]
        if s >= 0:
            f[i] = fa[i, s]
        else:
            k = -1 - s
            f[i] = (lc[k, 0] * fa[ld[k, 0], ln[k, 0]] + lc[k, 1] * fa[ld[k, 1], ln[k, 1]]
                    + lc[k, 2] * fa[ld[k, 2], ln[k, 2]] + la[k] * nm[k] + lb[k])


@njit(cache=True, inline="always")
def _wall_mass(n, fa, nb, opp, f):
    """Mass the wall rule returned to node n in excess of what the node sent into the wall:
    sum over its cut links of f_i (gathered) - f*_opp(i)(n)."""
    dm = 0.0
    for i in range(1, 19):
        if nb[i, n] < 0:
            dm += f[i] - fa[opp[i], n]
    return dm


@njit(cache=True, inline="always")
def _corrected_moments(f, dm, lat):
    """Add the mass correction w_i dm to every population of f (19,), then return its moments
    (rho, jx, jy, jz) = (sum f, sum f c) (j without the force's half)."""
    w, cx, cy, cz = lat.w, lat.cx, lat.cy, lat.cz
    rho = 0.0
    jx = 0.0
    jy = 0.0
    jz = 0.0
    for i in range(19):
        f[i] += w[i] * dm
        rho += f[i]
        jx += f[i] * cx[i]
        jy += f[i] * cy[i]
        jz += f[i] * cz[i]
    return rho, jx, jy, jz


@njit(cache=True, parallel=True)
def _step(fa, fb, lat, drive, delta, sums):
    """One stream + correct + collide step from fa into fb (:class:`Lattice`, :class:`Drive`;
    ``delta`` the even mass correction per node); sums[b] = (rho, jx, jy, jz) of block b after
    streaming (j including F/2)."""
    nb, nm, opp, cx, cy, cz, w = lat.nb, lat.nm, lat.opp, lat.cx, lat.cy, lat.cz, lat.w
    om_p, om_m, fx, fy, fz, local = drive
    n = fa.shape[1]
    nblk = sums.shape[0]
    for b in prange(nblk):
        f = np.empty(19)
        srho = 0.0
        sjx = 0.0
        sjy = 0.0
        sjz = 0.0
        for node in range(b * BLOCK, min(n, (b + 1) * BLOCK)):
            _gather(node, fa, lat, f)
            dm = delta - local * _wall_mass(node, fa, nb, opp, f)
            rho, jx, jy, jz = _corrected_moments(f, dm, lat)
            ux = jx + 0.5 * fx
            uy = jy + 0.5 * fy
            uz = jz + 0.5 * fz
            srho += rho
            sjx += ux
            sjy += uy
            sjz += uz
            uu = ux * ux + uy * uy + uz * uz
            uf = ux * fx + uy * fy + uz * fz
            # the node's own cut links keep n-_i for next step's parabolic correction
            for i in range(1, 19):
                s = nb[i, node]
                if s < 0:
                    cu = cx[i] * ux + cy[i] * uy + cz[i] * uz
                    nm[-1 - s] = 0.5 * (f[i] - f[opp[i]]) - 3.0 * w[i] * cu
            # rest population: symmetric only
            e0 = w[0] * (rho - 1.5 * uu)
            s0 = w[0] * (-3.0 * uf)
            fb[0, node] = f[0] - om_p * (f[0] - e0) + (1.0 - 0.5 * om_p) * s0
            for i in range(1, 19, 2):
                j = i + 1
                cu = cx[i] * ux + cy[i] * uy + cz[i] * uz
                cf = cx[i] * fx + cy[i] * fy + cz[i] * fz
                ep = w[i] * (rho + 4.5 * cu * cu - 1.5 * uu)
                em = w[i] * 3.0 * cu
                sp = w[i] * (9.0 * cu * cf - 3.0 * uf)
                sm = w[i] * 3.0 * cf
                fp = 0.5 * (f[i] + f[j])
                fm = 0.5 * (f[i] - f[j])
                cp = -om_p * (fp - ep) + (1.0 - 0.5 * om_p) * sp
                cm = -om_m * (fm - em) + (1.0 - 0.5 * om_m) * sm
                fb[i, node] = f[i] + cp + cm
                fb[j, node] = f[j] + cp - cm
        sums[b, 0] = srho
        sums[b, 1] = sjx
        sums[b, 2] = sjy
        sums[b, 3] = sjz


@njit(cache=True, parallel=True)
def _macro(fa, lat, drive, rho_out, u_out):
    """rho and u = sum f c + F/2 (rho0 = 1) of every node after streaming from fa."""
    nb, opp = lat.nb, lat.opp
    fx, fy, fz, local = drive.fx, drive.fy, drive.fz, drive.local
    n = fa.shape[1]
    nblk = (n + BLOCK - 1) // BLOCK
    for b in prange(nblk):
        f = np.empty(19)
        for node in range(b * BLOCK, min(n, (b + 1) * BLOCK)):
            _gather(node, fa, lat, f)
            dm = -local * _wall_mass(node, fa, nb, opp, f)
            rho, jx, jy, jz = _corrected_moments(f, dm, lat)
            rho_out[node] = rho
            u_out[node, 0] = jx + 0.5 * fx
            u_out[node, 1] = jy + 0.5 * fy
            u_out[node, 2] = jz + 0.5 * fz


@njit(cache=True, parallel=True)
def _uncut_flux(fa, nb, cx, cy, cz, out):
    """Mass flux streamed along uncut links in one step: out[b] = sum over the nodes of
    block b of sum_i f*_i(x - c_i) c_i over the populations pulled along uncut links (the mass
    that crosses the lattice planes; a cut link carries none)."""
    n = fa.shape[1]
    for b in prange(out.shape[0]):
        sx = 0.0
        sy = 0.0
        sz = 0.0
        for node in range(b * BLOCK, min(n, (b + 1) * BLOCK)):
            for i in range(1, 19):
                s = nb[i, node]
                if s >= 0:
                    v = fa[i, s]
                    sx += v * cx[i]
                    sy += v * cy[i]
                    sz += v * cz[i]
        out[b, 0] = sx
        out[b, 1] = sy
        out[b, 2] = sz


@njit(cache=True, parallel=True)
def _link_momentum(fa, lat, out):
    """Momentum given to the wall per step on each cut link (momentum exchange): the
    population leaving towards the wall, f*_ib(x), minus the one coming back, f_i(x), both
    along c_ib = -c_i. out (K, 3)."""
    lnode, ldir, opp, cx, cy, cz = lat.lnode, lat.ldir, lat.opp, lat.cx, lat.cy, lat.cz
    k_all = lnode.shape[0]
    for k in prange(k_all):
        f = np.empty(19)
        node = lnode[k]
        i = ldir[k]
        _gather(node, fa, lat, f)
        tot = fa[opp[i], node] + f[i]
        out[k, 0] = -cx[i] * tot
        out[k, 1] = -cy[i] * tot
        out[k, 2] = -cz[i] * tot


@dataclass
class FlowResult:
    """A converged (or stopped) steady flow, lattice units (cell 1, step 1, rho0 = 1).

    Fields from the end state are means over the last two steps (module docstring).
    u (N, 3) node velocities (including F/2), rho (N,) densities, U (3,) superficial velocity
    (the mass flux along uncut links per cell, see the module docstring), U_nodes (3,) the
    mean node velocity (sum of u / cells), force (3,) body force density, nu viscosity,
    magic, steps taken, converged, residual (last relative change of the mean node velocity
    between checks), tail (its geometric remaining-change estimate), balance (wall force /
    body force along F, mean of the last two steps; tol and balance_tol the criteria),
    parity_swing (half the difference of the balance between the last two steps: the
    period-2 mode's amplitude), history (check step, two-step mean node velocity along the
    force, two-step mean balance) triples, seconds (stepping wall time), mlups (fluid
    node updates per second / 1e6), link_force (K, 3) momentum given to the wall per step by
    each cut link, fallback_links, mass ("local" or "global" correction), memory_bytes (the
    stepping arrays: two population buffers, the pull table, the wall-rule table and the
    geometry's per-node and per-link arrays), stopped (the reason a ``stop`` callable gave to
    end the run early, else "").
    """

    geometry: LatticeGeometry
    u: np.ndarray
    rho: np.ndarray
    U: np.ndarray
    force: np.ndarray
    nu: float
    magic: float
    steps: int
    converged: bool
    residual: float
    tail: float
    seconds: float
    mlups: float
    link_force: np.ndarray
    fallback_links: int
    history: list = field(default_factory=list)
    U_nodes: np.ndarray = None
    mass: str = "local"
    memory_bytes: int = 0
    balance: float = math.nan
    balance_tol: float = math.nan
    tol: float = math.nan
    parity_swing: float = math.nan
    stopped: str = ""

    @property
    def mass_drift(self) -> float:
        """Relative deviation of the total mass from its start (after the correction)."""
        return float(self.rho.sum() / self.geometry.n_fluid - 1.0)


MASS_MODES = ("local", "global")


def solve(geo: LatticeGeometry, force, nu=1.0 / 6.0, magic=MAGIC_DEFAULT, scheme="linear",
          tol=1e-6, max_steps=200_000, check_every=None, progress=None, min_steps=None,
          mass="local", balance_tol=None, init=None, stop=None):
    """Drive the fluid of ``geo`` by a uniform body force to a steady state.

    force: (3,) body force per unit volume in lattice units (= rho0 g, rho0 = 1; a pressure
    gradient dP/dx = -F). nu: kinematic viscosity (lattice). magic: TRT product Lambda
    (3/16 by default). tol: relative convergence tolerance of the superficial velocity (see the
    module docstring). max_steps: a stop (``converged`` False). check_every: steps between
    convergence checks (default: a tenth of the viscous time of the largest box side, between
    20 and 500). progress: an object with ``update(n)`` (e.g. peclet.packing.bed.progress.Progress)
    or None. mass: "local" (default) or "global" mass correction of the wall rule (see the
    module docstring). balance_tol: the force balance's tolerance |B - 1| (default 1e-4;
    see the module docstring; 1 switches it off). init: None (start at rest, rho = 1) or
    (rho (N,), u (N, 3)) of the fluid nodes (e.g. an earlier run's ``rho``, ``u``): the run
    starts from the incompressible equilibrium of that state. stop: None or a callable given
    the history (list of (step, U, balance)) at every check, returning "" to go on or a
    reason to end the run (``converged`` False, ``stopped`` the reason). Returns a
    :class:`FlowResult`.
    """
    if not isinstance(geo, LatticeGeometry):
        raise PecletArgumentError("geo", "a peclet.flow.geometry.LatticeGeometry", geo)
    F = check_array("force", force, (3,))
    if not np.any(F != 0):
        raise PecletArgumentError("force", "a non-zero body force (3,)", F.tolist())
    nu = check_float("nu", nu, 1e-4, 10.0)
    om_p, om_m = trt_rates(nu, magic)
    tol = check_float("tol", tol, 0.0, 1.0, lo_open=True)
    max_steps = check_int("max_steps", max_steps, 1)
    if check_every is None:
        side = max(geo.grid.dims)
        check_every = int(min(500, max(20, 0.1 * side * side * 0.05 / nu)))
    check_every = check_int("check_every", check_every, 2)
    min_steps = 3 * check_every if min_steps is None else check_int("min_steps", min_steps, 0)
    mass = check_choice("mass", mass, MASS_MODES)
    balance_tol = BALANCE_TOL if balance_tol is None else \
        check_float("balance_tol", balance_tol, 0.0, 1.0, lo_open=True)
    local = 1.0 if mass == "local" else 0.0
    n = geo.n_fluid
    nb = np.ascontiguousarray(geo.nb)
    lc, ld, ln, la, lb = link_table(geo, scheme, (om_p, om_m), F)
    nm = np.zeros(len(lc))
    fa = np.empty((Q, n))
    fa[:] = W[:, None]
    if init is not None:
        fa[:] = _equilibrium(check_array("init[0]", init[0], (n,)),
                             check_array("init[1]", init[1], (n, 3)))
    stopped = ""
    fb = np.empty_like(fa)
    nblk = (n + BLOCK - 1) // BLOCK
    sums = np.zeros((nblk, 4))
    lnode = np.ascontiguousarray(geo.link_node)
    ldir = np.ascontiguousarray(geo.link_dir)
    # the kernels' bundles, once per run (nm, in lat, is the step's state: written each step)
    lat = Lattice(nb, lc, ld, ln, la, lb, nm, lnode, ldir, OPP, _CX, _CY, _CZ, W.copy())
    drive = Drive(om_p, om_m, *(float(v) for v in F), local)
    mass0 = float(n)
    delta = 0.0
    cells = geo.grid.n_cells
    fdir = F / np.linalg.norm(F)
    hist = []
    prev_U = None
    prev_r = None
    r = tail = bal = math.inf
    lf = np.empty((len(lc), 3))
    nF = float(np.linalg.norm(F)) * n
    converged = False
    steps = 0
    half = None
    t0 = time.perf_counter()

    def balance():
        _link_momentum(fa, lat, lf)
        return float(_ordered_sum(lf) @ fdir) / nF

    def advance():
        nonlocal fa, fb, delta, steps
        _step(fa, fb, lat, drive, delta, sums)
        fa, fb = fb, fa
        steps += 1
        tot = sums.sum(axis=0) if nblk < 2 else _ordered_sum(sums)
        delta = (mass0 - tot[0]) / n
        if progress is not None:
            progress.update(1)
        return tot

    while steps < max_steps:
        tot = advance()
        if (steps + 1) % check_every == 0:
            # first half of a two-step measurement (a period-2 mode: module docstring)
            half = (float(tot[1:] @ fdir) / cells, balance())
        if steps % check_every == 0:
            U = tot[1:] / cells
            if not np.all(np.isfinite(U)):
                raise FloatingPointError(f"the flow diverged at step {steps} (U = {U}); "
                                         "lower the force or raise nu")
            b1 = balance()
            Uf = 0.5 * (float(U @ fdir) + half[0])
            bal = 0.5 * (b1 + half[1])
            swing = 0.5 * abs(b1 - half[1])
            hist.append((steps, Uf, bal))
            if prev_U is not None and Uf != 0.0:
                r = abs(Uf - prev_U) / abs(Uf)
                ratio = r / prev_r if prev_r else 1.0
                tail = r * ratio / (1.0 - ratio) if ratio < 1.0 else math.inf
                if r < tol and tail < tol and abs(bal - 1.0) < balance_tol \
                        and steps >= min_steps:
                    converged = True
                    break
                prev_r = r
            prev_U = Uf
            stopped = stop(hist) if stop is not None else ""
            if stopped:
                break
    # the outputs: means over the last two steps (a period-2 mode cancels; module docstring)
    outs = []
    for last in (False, True):
        if last:
            advance()
        rho = np.empty(n)
        u = np.empty((n, 3))
        _macro(fa, lat, drive, rho, u)
        flux = np.zeros((nblk, 3))
        _uncut_flux(fa, nb, _CX, _CY, _CZ, flux)
        bb = balance()
        outs.append((rho, u, _ordered_sum(flux) / cells, lf.copy(), bb))
    seconds = time.perf_counter() - t0
    (rho0, u0, U0, lf0, b0), (rho1, u1, U1, lf1, b1) = outs
    rho = 0.5 * (rho0 + rho1)
    u = 0.5 * (u0 + u1)
    U = 0.5 * (U0 + U1)
    lf = 0.5 * (lf0 + lf1)
    bal = 0.5 * (b0 + b1)
    swing = 0.5 * abs(b1 - b0)
    U_nodes = _ordered_sum(u) / cells
    fallback = fallback_counts(geo, scheme)
    mem = sum(int(a.nbytes) for a in (fa, fb, nb, lc, ld, ln, la, lb, nm, geo.ijk, geo.phi,
                                       geo.cell, geo.link_node, geo.link_dir, geo.link_q,
                                       geo.link_ff, geo.link_fff))
    return FlowResult(geometry=geo, u=u, rho=rho, U=U, force=F.copy(), nu=nu, magic=magic,
                      steps=steps, converged=converged, residual=r, tail=tail,
                      seconds=seconds, mlups=n * steps / max(seconds, 1e-12) / 1e6,
                      link_force=lf, fallback_links=fallback, history=hist, U_nodes=U_nodes,
                      mass=mass, memory_bytes=mem, balance=bal, balance_tol=balance_tol,
                      tol=tol, parity_swing=swing, stopped=stopped)


def _equilibrium(rho, u):
    """(19, N) incompressible equilibria w_i (rho + 3 c.u + 9/2 (c.u)^2 - 3/2 u.u)."""
    cu = u @ C.T.astype(np.float64)                       # (N, 19)
    uu = (u * u).sum(axis=1)
    return (W[None, :] * (rho[:, None] + 3.0 * cu + 4.5 * cu * cu - 1.5 * uu[:, None])).T


def _ordered_sum(a):
    """Column sums of a 2-D array in row order (numpy's pairwise summation is also fixed, but
    spelling the order out keeps the reduction independent of numpy's blocking)."""
    return _serial_sum(np.ascontiguousarray(a, dtype=np.float64))


@njit(cache=True)
def _serial_sum(a):
    out = np.zeros(a.shape[1])
    for r in range(a.shape[0]):
        for c in range(a.shape[1]):
            out[c] += a[r, c]
    return out
