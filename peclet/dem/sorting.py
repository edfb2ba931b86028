"""A stable counting sort of small integer keys: the cell list's and the contact colouring's.

Both bucket items by an integer key in [0, nkeys) and keep the items of one bucket in their
original order (so everything built on them stays deterministic).
"""
from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["counting_sort"]


@njit(cache=True)
def counting_sort(keys, nkeys):
    """Items 0..n-1 bucketed by ``keys`` (n,) int64 in [0, ``nkeys``): returns (start
    (nkeys + 1,), order (n,)), bucket k's items at ``order[start[k]:start[k + 1]]``, ascending
    (the sort is stable)."""
    n = keys.shape[0]
    start = np.zeros(nkeys + 1, np.int64)
    for i in range(n):
        start[keys[i] + 1] += 1
    for k in range(nkeys):
        start[k + 1] += start[k]
    fill = start[:-1].copy()
    order = np.empty(n, np.int64)
    for i in range(n):
        order[fill[keys[i]]] = i
        fill[keys[i]] += 1
    return start, order
