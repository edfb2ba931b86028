"""Named columns of the flat encoding (docs/architecture.md §2): read and write records through
these.

Node table: ``node_ints`` (n, 3) int32 rows ``(kind, left, right)`` (children -1 for a leaf) and
``node_reals`` (n, 16) float64 rows ``(params[0:8], t[3], q[4] as x, y, z, w, s)``. Instance
table: ``inst_ints`` (m, 2) rows ``(root, 0)`` and ``inst_reals`` (m, 8) rows ``(t, q, s)``.
A record's transform maps its own frame to its parent's: ``p_parent = s R(q) p + t``.
"""
from __future__ import annotations

from .leaves import MAX_PARAMS

__all__ = ["NODE_INT_COLS", "NODE_REAL_COLS", "KIND", "LEFT", "RIGHT", "PARAMS", "TRANSLATION",
           "ROTATION", "SCALE", "INST_INT_COLS", "INST_REAL_COLS", "INST_ROOT",
           "INST_TRANSLATION", "INST_ROTATION", "INST_SCALE", "node_transform",
           "instance_transform"]

# node_ints columns
NODE_INT_COLS = 3
KIND = 0
LEFT = 1
RIGHT = 2

# node_reals columns
NODE_REAL_COLS = 16
PARAMS = slice(0, MAX_PARAMS)
TRANSLATION = slice(8, 11)
ROTATION = slice(11, 15)
SCALE = 15

# instance tables
INST_INT_COLS = 2
INST_ROOT = 0
INST_REAL_COLS = 8
INST_TRANSLATION = slice(0, 3)
INST_ROTATION = slice(3, 7)
INST_SCALE = 7


def node_transform(rec):
    """(t (3,), q (4,), s) of one ``node_reals`` row, as views (t, q) and a float (s)."""
    return rec[TRANSLATION], rec[ROTATION], float(rec[SCALE])


def instance_transform(rec):
    """(t (3,), q (4,), s) of one ``inst_reals`` row, as views (t, q) and a float (s)."""
    return rec[INST_TRANSLATION], rec[INST_ROTATION], float(rec[INST_SCALE])
