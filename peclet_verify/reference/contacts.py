"""Brute-force contact sets: the reference that the engine's contact detection is checked against.

Slow and obviously correct: every probe of every body is tested against every other body.
"""
from __future__ import annotations

import numpy as np

__all__ = ["brute_force_contacts"]


def brute_force_contacts(builder, root, probes, positions, quaternions):
    """Reference contacts of identical bodies (tree ``root`` of ``builder`` in the body frame,
    shell ``probes`` (m, 3) on its surface, poses ``positions`` (n, 3) and ``quaternions``
    (n, 4) as (x, y, z, w), active rotations body -> world): every ordered pair (a, b),
    a != b, with a probe of a strictly inside b (phi_b < 0 by ``eval_root`` in b's frame).
    Returns the sorted list of (a, b, probe index)."""
    from peclet.core.geom import quat_to_matrix
    rots = [quat_to_matrix(q) for q in quaternions]
    out = []
    for ia in range(len(positions)):
        world = probes @ rots[ia].T + positions[ia]
        for ib in range(len(positions)):
            if ia != ib:
                local = (world - positions[ib]) @ rots[ib]
                out.extend((ia, ib, int(k)) for k in
                           np.nonzero(builder.eval_root(root, local) < 0.0)[0])
    return sorted(out)
