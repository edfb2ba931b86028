"""Bounding balls and the certificate rule of docs/architecture.md §4.

A node's *certificate* asserts two things about its field phi in its parent frame:

1. Equation 1: ``phi(p) >= |p - c| - r`` for every point p, with (c, r) the node's ball;
2. phi is 1-Lipschitz.

Exact leaves carry both. A union (min) of two certified children keeps both for the ball that
encloses the children's balls. An intersection or difference (max) keeps the LEFT child's ball;
``max(a, .) >= a`` preserves Equation 1, and the result stays 1-Lipschitz only if the right
subtree is 1-Lipschitz, so the node is certified iff the left child is certified AND every leaf
of the right subtree is 1-Lipschitz. (The upstream rule checked only the left child.)
Conformal transforms preserve both properties.
"""
from __future__ import annotations

import numpy as np


def enclosing_ball(c1, r1, c2, r2):
    """The smallest ball containing balls (c1, r1) and (c2, r2)."""
    if not np.isfinite(r1) or not np.isfinite(r2):
        return (c1 if not np.isfinite(r1) else c2).copy(), float("inf")
    d = float(np.linalg.norm(c2 - c1))
    if d + r2 <= r1:
        return c1.copy(), float(r1)
    if d + r1 <= r2:
        return c2.copy(), float(r2)
    r = 0.5 * (d + r1 + r2)
    c = c1 + (c2 - c1) * ((r - r1) / d)
    # the arithmetic above can round a hair inside either ball; grow to contain both exactly
    r = max(r, float(np.linalg.norm(c - c1)) + r1, float(np.linalg.norm(c - c2)) + r2)
    return c, r


def combine(op, left, right):
    """(centre, radius, certified, lipschitz) of an operator node, in the node's own frame.

    ``left`` and ``right`` are the children's (centre, radius, certified, lipschitz), each in
    the node's own frame.
    """
    from .leaves import UNION
    cl, rl, certl, lipl = left
    cr, rr, certr, lipr = right
    lip = lipl and lipr
    if op == UNION:
        c, r = enclosing_ball(cl, rl, cr, rr)
        return c, r, certl and certr, lip
    return cl.copy(), rl, certl and lipr, lip
