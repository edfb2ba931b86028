"""Per-block pruned CSG programs: the same bits as the full program for a fraction of the work.

Near any one point only a few leaves of a tree can be the value a CSG operator selects. For each
block of a regular lattice we bake, once per shape, a *pruned* program: the full program with
every operator whose outcome is decided throughout the block replaced by the operand it always
selects. For every point inside the block the pruned program returns bit for bit the same
(phi, gradient, active feature ``st[0, 4]``) as the full program, because it performs the very
same leaf evaluations and comparisons on the surviving operands.

Blocks are the cubes ``origin + (i, j, k) * block .. + block`` (world / program frame, the
program's length unit), ``i < dims[0]`` etc., numbered ``(k * dims[1] + j) * dims[0] + i``
(x fastest). A point outside the lattice (or with a NaN coordinate) is given the full program,
which the pruned ops array holds at ``[full_begin, full_end)``.

Deciding an operator (see :func:`_decide`): every leaf is evaluated alone at the block centre c
(``eval_point`` on the one-row program of its push, so the leaf's scale is included). A
1-Lipschitz leaf's value anywhere in the block then lies in ``[v - r, v + r]`` with r the
block's half-diagonal, inflated against round-off; any other leaf (ellipsoid, superquadric,
unknown kind) or a non-finite value gets ``(-inf, inf)``, which blocks every decision it takes
part in. Ranges are combined up the postfix walk like the operators combine values.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from peclet.core.validation import PecletArgumentError, check_array, check_float, check_int

from . import kernels as K
from .leaves import LEAVES_BY_KIND

#: Relative inflation of a block's half-diagonal: covers the rounding of the block centre and
#: of the rotation matrices (a leaf in the world frame is Lipschitz to 1 + O(1e-16)).
RHO_REL = 1e-9
#: Absolute tolerance per unit of magnitude (coordinates, leaf placement and size, value):
#: covers the rounding of a leaf's evaluation at c and at q, and of the block index of q.
ABS_TOL = 1e-12
#: An operator is decided only when the ranges are separated by more than
#: SEPARATION * (1 + |endpoints|): round-off in the range arithmetic can then never flip it.
SEPARATION = 1e-12
#: Refuse lattices with more blocks than this (memory of the index alone: 16 bytes a block).
MAX_BLOCKS = 1 << 24

_KEEP_BOTH, _KEEP_A, _KEEP_B = 0, 1, 2


class PrunedPrograms(NamedTuple):
    """The pruned programs of one program over a block lattice (see the module docstring).

    ops : (n, 2) int32, rows in the program format of :mod:`kernels`, referencing the SAME leaf
        rows as the input program (evaluate with its ``leaf_kind`` / ``leaf_reals``); the full
        program is copied to ``ops[full_begin:full_end]``.
    block_range : (n_blocks, 2) int64, the ``[begin, end)`` rows of each block's program in
        ``ops`` (blocks with identical programs share rows).
    ob : (5,) float64, (origin x, y, z, block edge, 1 / block edge), program-frame units.
    dims : (3,) int64, blocks per axis.
    full_begin, full_end : the full program's rows in ``ops``.
    """

    ops: np.ndarray
    block_range: np.ndarray
    ob: np.ndarray
    dims: np.ndarray
    full_begin: int
    full_end: int

    @property
    def nbytes(self) -> int:
        """Bytes of the arrays the lookup and the evaluation read (ops + block index)."""
        return int(self.ops.nbytes + self.block_range.nbytes + self.ob.nbytes
                   + self.dims.nbytes)

    def block_rows(self) -> np.ndarray:
        """(n_blocks,) rows of each block's pruned program."""
        return self.block_range[:, 1] - self.block_range[:, 0]


@njit(cache=True, inline="always")
def _separated(x, y):
    # x > y by a margin that no rounding of the endpoints can bridge
    return x - y > SEPARATION * (1.0 + abs(x) + abs(y))


@njit(cache=True, inline="always")
def _decide(code, alo, ahi, blo, bhi):
    """Which operands of operator ``code`` can be selected for values a in [alo, ahi] (left,
    below on the stack) and b in [blo, bhi] (right, top).

    eval_point's comparisons are STRICT and ties keep the left operand:
      union        takes b iff b < a   -> A only if b >= a always, i.e. blo >= ahi;
                                          B only if b < a always,  i.e. bhi <  alo;
      intersection takes b iff b > a   -> A only if bhi <= alo;  B only if blo > ahi;
      difference   takes -b iff -b > a -> A only if -b <= a always, i.e. -blo <= alo. There is
                                          no "B only": the result would be -b, and the format
                                          has no negation.
    A tie could go either way under round-off, so every test demands a strict separation by
    a margin (:func:`_separated`), which implies each of the conditions above, ties included.
    An infinite endpoint (a non-Lipschitz or non-finite operand, possibly NaN at some point,
    where every comparison is false) never decides anything.
    """
    if not (math.isfinite(alo) and math.isfinite(ahi) and math.isfinite(blo)
            and math.isfinite(bhi)):
        return _KEEP_BOTH
    if code == K.OP_UNION:
        if _separated(blo, ahi):
            return _KEEP_A
        if _separated(alo, bhi):
            return _KEEP_B
    elif code == K.OP_INTERSECTION:
        if _separated(alo, bhi):
            return _KEEP_A
        if _separated(blo, ahi):
            return _KEEP_B
    else:
        if _separated(alo, -blo):
            return _KEEP_A
    return _KEEP_BOTH


@njit(cache=True, inline="always")
def _combine(code, alo, ahi, blo, bhi):
    """Range of the operator's value when both operands stay; (-inf, inf) if either is
    unbounded (the value may then be NaN, which no finite range describes)."""
    if not (math.isfinite(alo) and math.isfinite(ahi) and math.isfinite(blo)
            and math.isfinite(bhi)):
        return -np.inf, np.inf
    if code == K.OP_UNION:
        return min(alo, blo), min(ahi, bhi)
    if code == K.OP_INTERSECTION:
        return max(alo, blo), max(ahi, bhi)
    return max(alo, -bhi), max(ahi, -blo)


@njit(cache=True)
def _hash_rows(rows, n):
    h = np.int64(1469598103934665603)
    for i in range(n):
        # integer arithmetic wraps (no overflow check): a plain 64-bit mixing hash
        h = (h ^ np.int64(rows[i, 0])) * np.int64(1099511628211)
        h = (h ^ np.int64(rows[i, 1])) * np.int64(1099511628211)
    return h ^ np.int64(n)


@njit(cache=True)
def _seen_slot(keys, vals, h):
    """The slot of hash ``h`` in the open-addressing table (keys, vals; vals -2: empty): where
    it is, or the empty slot where it goes (linear probing; the table is never full)."""
    mask = keys.shape[0] - 1
    i = (h ^ (h >> 31)) & mask
    while vals[i] != -2 and keys[i] != h:
        i = (i + 1) & mask
    return i


@njit(cache=True)
def _same_rows(out, begin, end, rows, n):
    if end - begin != n:
        return False
    for i in range(n):
        if out[begin + i, 0] != rows[i, 0] or out[begin + i, 1] != rows[i, 1]:
            return False
    return True


class _Tree(NamedTuple):
    """The program a bake prunes: ``ops`` (n, 2) int32 and the leaf tables ``leaf_kind`` (L,)
    int32 and ``leaf_reals`` (L, LEAF_COLS) float64 in the format of :mod:`kernels`, ``lip``
    (L,) bool (the leaf is 1-Lipschitz in the world frame), the program's rows
    ``[op_begin, op_end)``."""
    ops: np.ndarray
    leaf_kind: np.ndarray
    leaf_reals: np.ndarray
    lip: np.ndarray
    op_begin: int
    op_end: int


class _Scratch(NamedTuple):
    """One block's working arrays, for a program of ``nfull`` rows: the pruned ``rows``
    (nfull, 2) int32, the stack of pending operands (their value ranges ``lo``, ``hi``
    (nfull,) float64, in the program's length unit, and the first of their rows ``start``
    (nfull,) int64) and the evaluator's stack ``st`` (MAX_STACK, STACK_COLS)."""
    rows: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    start: np.ndarray
    st: np.ndarray


@njit(cache=True)
def _prune_block(tree, scratch, cx, cy, cz, rho, tol0):
    """Write the pruned program of ``tree`` (a :class:`_Tree`) for the block centred at c
    into ``scratch.rows``; return its length.

    ``rho`` is the inflated half-diagonal, ``tol0`` the magnitude of the lattice coordinates.
    The stack holds, per pending operand, its value range [lo, hi] and the first of its rows;
    its rows run to the next operand's first row (or the end): postfix keeps them contiguous.
    """
    ops, leaf_kind, leaf_reals, lip, op_begin, op_end = tree
    rows, lo, hi, start, st = scratch
    L = leaf_reals
    sp = 0
    n = 0
    ctol = tol0 + abs(cx) + abs(cy) + abs(cz)
    for k in range(op_begin, op_end):
        code = ops[k, 0]
        if code == K.OP_LEAF:
            j = ops[k, 1]
            v = K.eval_point(ops, leaf_kind, leaf_reals, k, k + 1, cx, cy, cz, st)[0]
            if lip[j] and math.isfinite(v):
                size = 0.0
                for c in range(K.LEAF_T):
                    size += abs(L[j, c])
                mag = (ctol + abs(L[j, K.LEAF_T]) + abs(L[j, K.LEAF_T + 1])
                       + abs(L[j, K.LEAF_T + 2]) + abs(L[j, K.LEAF_S]) * size + abs(v))
                r = rho + ABS_TOL * mag
                lo[sp] = v - r
                hi[sp] = v + r
            else:
                lo[sp] = -np.inf
                hi[sp] = np.inf
            start[sp] = n
            rows[n, 0] = code
            rows[n, 1] = j
            n += 1
            sp += 1
        else:
            sp -= 1
            alo = lo[sp - 1]
            ahi = hi[sp - 1]
            blo = lo[sp]
            bhi = hi[sp]
            keep = _decide(code, alo, ahi, blo, bhi)
            if keep == _KEEP_A:
                n = start[sp]
            elif keep == _KEEP_B:
                a0 = start[sp - 1]
                b0 = start[sp]
                for i in range(n - b0):
                    rows[a0 + i, 0] = rows[b0 + i, 0]
                    rows[a0 + i, 1] = rows[b0 + i, 1]
                n = a0 + (n - b0)
                lo[sp - 1] = blo
                hi[sp - 1] = bhi
            else:
                rows[n, 0] = code
                rows[n, 1] = ops[k, 1]
                n += 1
                lo[sp - 1], hi[sp - 1] = _combine(code, alo, ahi, blo, bhi)
    return n


@njit(cache=True)
def _bake(tree, origin, block, dims):
    """(ops, block_range) of ``tree`` (a :class:`_Tree`): see :func:`bake_pruned`.
    Sequential, so deterministic."""
    ops = tree.ops
    op_begin = tree.op_begin
    op_end = tree.op_end
    nfull = op_end - op_begin
    nx = dims[0]
    ny = dims[1]
    nz = dims[2]
    block_range = np.empty((nx * ny * nz, 2), np.int64)
    cap = 4 * nfull + 64
    out = np.empty((cap, 2), np.int32)
    for i in range(nfull):
        out[i, 0] = ops[op_begin + i, 0]
        out[i, 1] = ops[op_begin + i, 1]
    n_out = nfull
    # identical programs share rows: hash -> first block with it (-1: the full program), an
    # open-addressing table in two arrays (a typed Dict costs seconds of compilation)
    size = 1
    while size < 2 * (nx * ny * nz + 1):
        size *= 2
    seen_key = np.zeros(size, np.int64)
    seen_val = np.full(size, np.int64(-2))
    k = _seen_slot(seen_key, seen_val, _hash_rows(out, nfull))
    seen_key[k] = _hash_rows(out, nfull)
    seen_val[k] = -1
    rows = np.empty((nfull, 2), np.int32)
    scratch = _Scratch(rows, np.empty(nfull), np.empty(nfull), np.empty(nfull, np.int64),
                       np.empty((K.MAX_STACK, K.STACK_COLS)))
    rho = block * (math.sqrt(3.0) / 2.0) * (1.0 + RHO_REL)
    tol0 = 1.0 + abs(origin[0]) + abs(origin[1]) + abs(origin[2])
    b = 0
    for kz in range(nz):
        cz = origin[2] + (kz + 0.5) * block
        for jy in range(ny):
            cy = origin[1] + (jy + 0.5) * block
            for ix in range(nx):
                cx = origin[0] + (ix + 0.5) * block
                n = _prune_block(tree, scratch, cx, cy, cz, rho, tol0)
                h = _hash_rows(rows, n)
                slot = _seen_slot(seen_key, seen_val, h)
                first = seen_val[slot]                  # -2: not seen
                if first == -1 and _same_rows(out, np.int64(0), nfull, rows, n):
                    block_range[b, 0] = 0
                    block_range[b, 1] = nfull
                elif first >= 0 and _same_rows(out, block_range[first, 0],
                                               block_range[first, 1], rows, n):
                    block_range[b, 0] = block_range[first, 0]
                    block_range[b, 1] = block_range[first, 1]
                else:
                    if n_out + n > cap:
                        cap = 2 * (n_out + n)
                        grown = np.empty((cap, 2), np.int32)
                        for i in range(n_out):
                            grown[i, 0] = out[i, 0]
                            grown[i, 1] = out[i, 1]
                        out = grown
                    for i in range(n):
                        out[n_out + i, 0] = rows[i, 0]
                        out[n_out + i, 1] = rows[i, 1]
                    block_range[b, 0] = n_out
                    block_range[b, 1] = n_out + n
                    n_out += n
                    if first == -2:
                        seen_key[slot] = h
                        seen_val[slot] = b
                b += 1
    return out[:n_out].copy(), block_range


def bake_pruned(program, origin, block, dims) -> PrunedPrograms:
    """Bake the pruned programs of ``program`` over a block lattice.

    Parameters
    ----------
    program : a compiled program (``peclet.core.geom.compile_root`` / ``SceneBuilder.program``):
        uses its ``ops``, ``leaf_kind``, ``leaf_reals``, ``op_begin``, ``op_end``.
    origin : (3,) finite, the lattice's lower corner in the program's (world) frame.
    block : finite > 0, the block edge (program length units).
    dims : (3,) integers >= 1, blocks per axis (at most ``MAX_BLOCKS`` in all).

    Returns a :class:`PrunedPrograms`. For any point q in block b (cube ``origin + idx * block``
    to ``+ block``, faces included), evaluating ``ops[block_range[b, 0]:block_range[b, 1]]``
    with the program's leaf tables gives bit for bit the full program's phi, gradient and
    feature. Use :func:`pruned_range` to find the rows for a point. Deterministic.
    """
    origin = check_array("origin", origin, (3,))
    block = check_float("block", block, 0.0, lo_open=True)
    try:
        items = list(dims) if not isinstance(dims, (str, bytes)) else None
    except TypeError:
        items = None
    if items is None or len(items) != 3:
        raise PecletArgumentError("dims", "3 integers >= 1", dims)
    # element by element, so that a bool or a non-integral float is refused, not cast
    dims = np.array([check_int("dims", v, 1, MAX_BLOCKS) for v in items], np.int64)
    if int(np.prod(dims)) > MAX_BLOCKS:
        raise PecletArgumentError("dims", f"3 integers >= 1 with a product <= {MAX_BLOCKS}",
                                  dims.tolist())
    ops = np.ascontiguousarray(program.ops, dtype=np.int32)
    leaf_kind = np.ascontiguousarray(program.leaf_kind, dtype=np.int32)
    leaf_reals = np.ascontiguousarray(program.leaf_reals, dtype=np.float64)
    op_begin, op_end = int(program.op_begin), int(program.op_end)
    if not 0 <= op_begin < op_end <= len(ops):
        raise PecletArgumentError("program", "a program with 0 <= op_begin < op_end <= len(ops)",
                                  (op_begin, op_end))
    lip = np.array([LEAVES_BY_KIND[int(k)].lipschitz if int(k) in LEAVES_BY_KIND else False
                    for k in leaf_kind], dtype=np.bool_)
    out, block_range = _bake(_Tree(ops, leaf_kind, leaf_reals, lip, op_begin, op_end), origin,
                             block, dims)
    ob = np.array([origin[0], origin[1], origin[2], block, 1.0 / block])
    return PrunedPrograms(out, block_range, ob, dims, 0, op_end - op_begin)


@njit(cache=True, inline="always")
def pruned_range(block_range, boff, ob, dims, full_begin, full_end, qx, qy, qz):
    """(begin, end) rows of the pruned program for program-frame point q: those of q's block
    (``block_range[boff + block]``), or ``(full_begin, full_end)`` when q is outside the
    lattice, has a NaN coordinate, or there is no lattice (``dims`` zero).
    A point on a face between two blocks may get either block's program: both are exact there.
    """
    # a product, not a quotient (several times cheaper): the index may then be off by an
    # ulp at a face, which the bake's tolerance (ABS_TOL, relative to the coordinates) covers
    inv = ob[4]
    tx = (qx - ob[0]) * inv
    ty = (qy - ob[1]) * inv
    tz = (qz - ob[2]) * inv
    # written so that NaN fails every test
    if not (tx >= 0.0 and tx < dims[0] and ty >= 0.0 and ty < dims[1]
            and tz >= 0.0 and tz < dims[2]):
        return full_begin, full_end
    b = boff + (int(tz) * dims[1] + int(ty)) * dims[0] + int(tx)
    return block_range[b, 0], block_range[b, 1]


@njit(cache=True)
def _lookup_ranges(block_range, boff, ob, dims, full_begin, full_end, points):
    n = points.shape[0]
    out = np.empty((n, 2), np.int64)
    for i in range(n):
        out[i, 0], out[i, 1] = pruned_range(block_range, boff, ob, dims, full_begin, full_end,
                                            points[i, 0], points[i, 1], points[i, 2])
    return out


def lookup_ranges(table: PrunedPrograms, points) -> np.ndarray:
    """(N, 2) int64: :func:`pruned_range` of every row of ``points`` (N, 3) in ``table``."""
    points = check_array("points", points, (None, 3), finite=False)
    return _lookup_ranges(table.block_range, 0, table.ob, table.dims, table.full_begin,
                          table.full_end, points)


class PrunedSet(NamedTuple):
    """Several shapes' pruned programs packed like :func:`program.concatenate` packs programs.

    ops : (n, 2) int32, every table's rows, leaf rows shifted to the concatenated leaf table.
    block_range : (total blocks, 2) int64, rows in ``ops``; shape i's blocks start at
        ``block_off[i]``.
    block_off : (n_programs,) int64.
    ob : (n_programs, 5) float64 and dims : (n_programs, 3) int64, each shape's lattice
        (dims zero for a program without a table: its points always get the full program).
    full : (n_programs, 2) int64, each full program's rows in ``ops``.
    For shape i: ``pruned_range(block_range, block_off[i], ob[i], dims[i], full[i, 0],
    full[i, 1], q...)``, then ``eval_point(ops, leaf_kind, leaf_reals, ...)`` with the leaf
    tables of ``program.concatenate(programs)``.
    """

    ops: np.ndarray
    block_range: np.ndarray
    block_off: np.ndarray
    ob: np.ndarray
    dims: np.ndarray
    full: np.ndarray


def concatenate_pruned(programs, tables) -> PrunedSet:
    """Pack ``tables[i]`` (a :class:`PrunedPrograms` of ``programs[i]``, or None) for the leaf
    tables of ``program.concatenate(programs)`` (same order: leaf rows are shifted by the
    leaves of the programs before, exactly as there). A None entry stores its full program."""
    if len(programs) != len(tables):
        raise PecletArgumentError("tables", f"a list of {len(programs)} tables or None",
                                  len(tables))
    ops, ranges, boff, obs, dims, full = [], [], [], [], [], []
    n_ops = n_leaves = n_blocks = 0
    for p, t in zip(programs, tables):
        if t is None:
            o = np.asarray(p.ops[p.op_begin:p.op_end], np.int32).copy()
            t = PrunedPrograms(o, np.zeros((0, 2), np.int64), np.ones(5),
                               np.zeros(3, np.int64), 0, len(o))
        o = t.ops.copy()
        o[o[:, 0] == K.OP_LEAF, 1] += n_leaves
        ops.append(o)
        ranges.append(t.block_range + n_ops)
        boff.append(n_blocks)
        obs.append(t.ob)
        dims.append(t.dims)
        full.append((t.full_begin + n_ops, t.full_end + n_ops))
        n_ops += len(o)
        n_leaves += len(p.leaf_kind)
        n_blocks += len(t.block_range)
    return PrunedSet(np.ascontiguousarray(np.concatenate(ops).astype(np.int32)),
                     np.ascontiguousarray(np.concatenate(ranges).astype(np.int64)
                                          .reshape(-1, 2)),
                     np.asarray(boff, np.int64), np.asarray(obs, np.float64).reshape(-1, 5),
                     np.asarray(dims, np.int64).reshape(-1, 3),
                     np.asarray(full, np.int64).reshape(-1, 2))


@njit(cache=True)
def eval_ranges(ops, leaf_kind, leaf_reals, ranges, points):
    """phi (N,), gradient (N, 3) and active feature (N,) int64 of ``ops[ranges[i, 0]:
    ranges[i, 1]]`` at each row of ``points`` (N, 3): the reference loop of the tests and the
    benchmark, for the full program (one range repeated) and the pruned ones alike."""
    n = points.shape[0]
    phi = np.empty(n)
    grad = np.empty((n, 3))
    feat = np.empty(n, np.int64)
    st = np.empty((K.MAX_STACK, K.STACK_COLS))
    for i in range(n):
        v, gx, gy, gz = K.eval_point(ops, leaf_kind, leaf_reals, ranges[i, 0], ranges[i, 1],
                                     points[i, 0], points[i, 1], points[i, 2], st)
        phi[i] = v
        grad[i, 0] = gx
        grad[i, 1] = gy
        grad[i, 2] = gz
        feat[i] = int(st[0, 4])
    return phi, grad, feat


def evaluate_pruned(table: PrunedPrograms, program, points):
    """(phi, grad, feature) of ``program`` at ``points`` (N, 3) through the pruned ``table``."""
    points = check_array("points", points, (None, 3), finite=False)
    rng = lookup_ranges(table, points)
    return eval_ranges(table.ops, program.leaf_kind, program.leaf_reals, rng, points)


def evaluate_full(program, points):
    """(phi, grad, feature) of the full ``program`` at ``points`` (N, 3), for comparisons."""
    points = check_array("points", points, (None, 3), finite=False)
    rng = np.empty((len(points), 2), np.int64)
    rng[:, 0] = program.op_begin
    rng[:, 1] = program.op_end
    return eval_ranges(program.ops, program.leaf_kind, program.leaf_reals, rng, points)
