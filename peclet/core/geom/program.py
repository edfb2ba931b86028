"""Lower a root of the flat encoding to an evaluation program (flat arrays, no code).

The program is the post-order walk of the root's subtree, with every leaf's transform composed
down to the root's parent frame (see :mod:`peclet.core.geom.kernels` for the layout). It is
built once per root, in O(nodes), and cached by the builder; trees are never compiled to code.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import kernels as K
from .encoding import PARAMS, node_transform
from .leaves import DATA, GRID
from .sampled import grid_values, program_rows
from .transforms import quat_to_matrix


@dataclass(frozen=True)
class Program:
    """Flat evaluation arrays for one root (or several concatenated; see :func:`concatenate`)."""

    ops: np.ndarray         # (n_ops, 2) int32: (code, leaf row)
    leaf_kind: np.ndarray   # (n_rows,) int32; DATA for the rows of a grid's samples
    leaf_reals: np.ndarray  # (n_rows, LEAF_COLS) float64: leaf rows, then data rows
    op_begin: int
    op_end: int


def compile_root(node_ints: np.ndarray, node_reals: np.ndarray, root: int) -> Program:
    """Compile ``root`` of the flat arrays ``node_ints`` (n, 3) / ``node_reals`` (n, 16).

    A grid leaf's samples (data rows of the node table, :mod:`.sampled`) are appended after the
    leaf rows, ``LEAF_COLS`` to a row with kind DATA, once per data block however many leaves
    share it; the leaf's first parameter becomes the row offset from the leaf to them."""
    ops: list[tuple[int, int]] = []
    leaf_kind: list[int] = []
    leaf_rows: list[np.ndarray] = []
    grids: list[tuple[int, int]] = []       # (leaf row, node of the leaf)
    # explicit DFS: (node, S, R, T, visited)
    stack = [(int(root), 1.0, np.eye(3), np.zeros(3), False)]
    while stack:
        node, S, R, T, visited = stack.pop()
        kind, left, right = (int(v) for v in node_ints[node])
        if visited:
            ops.append((kind, -1))
            continue
        rec = node_reals[node]
        t, q, s = node_transform(rec)
        Rn = quat_to_matrix(q)
        # world-from-node: p_world = S R (s Rn p + t) + T
        # with an identity rotation or a zero translation these products are exact
        T2 = T + S * (R @ t)
        R2 = R @ Rn
        S2 = S * s
        if left < 0:
            row = np.zeros(K.LEAF_COLS)
            row[PARAMS] = rec[PARAMS]
            row[K.LEAF_T:K.LEAF_T + 3] = T2
            row[K.LEAF_R:K.LEAF_R + 9] = R2.reshape(-1)
            row[K.LEAF_S] = S2
            ops.append((K.OP_LEAF, len(leaf_rows)))
            if kind == GRID:
                grids.append((len(leaf_rows), node))
            leaf_kind.append(kind)
            leaf_rows.append(row)
        else:
            stack.append((node, S, R, T, True))
            stack.append((right, S2, R2, T2, False))
            stack.append((left, S2, R2, T2, False))
    _append_grid_data(node_ints, node_reals, grids, leaf_kind, leaf_rows)
    ops_arr = np.ascontiguousarray(np.array(ops, dtype=np.int32).reshape(-1, 2))
    return Program(ops_arr, np.array(leaf_kind, dtype=np.int32),
                   np.ascontiguousarray(np.array(leaf_rows, dtype=np.float64)
                                        .reshape(-1, K.LEAF_COLS)),
                   0, len(ops_arr))


def _append_grid_data(node_ints, node_reals, grids, leaf_kind, leaf_rows):
    """Append each grid's samples after the leaf rows and point its leaf row at them."""
    start: dict[int, int] = {}             # first data row in the node table -> program row
    for row, node in grids:
        params = node_reals[node, PARAMS]
        first = int(params[0])
        if first not in start:
            values = grid_values(node_ints[:, 0], node_reals, params, node)
            start[first] = len(leaf_rows)
            for r in program_rows(values, K.LEAF_COLS):
                leaf_kind.append(DATA)
                leaf_rows.append(r)
        leaf_rows[row][0] = float(start[first] - row)


def concatenate(programs):
    """Pack several programs into one set of arrays.

    Returns (ops, leaf_kind, leaf_reals, ranges) with ``ranges[i] = (op_begin, op_end)``.
    """
    ops, kinds, reals, ranges = [], [], [], []
    n_ops = n_leaves = 0
    for p in programs:
        o = p.ops.copy()
        o[o[:, 0] == K.OP_LEAF, 1] += n_leaves
        ops.append(o)
        kinds.append(p.leaf_kind)
        reals.append(p.leaf_reals)
        ranges.append((n_ops, n_ops + len(o)))
        n_ops += len(o)
        n_leaves += len(p.leaf_kind)
    return (np.ascontiguousarray(np.concatenate(ops).astype(np.int32)),
            np.ascontiguousarray(np.concatenate(kinds).astype(np.int32)),
            np.ascontiguousarray(np.concatenate(reals)),
            np.asarray(ranges, dtype=np.int64).reshape(-1, 2))
