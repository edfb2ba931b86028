"""Polydisperse bodies: a per-body isotropic scale of its registered shape.

A body of shape k and scale s is shape k enlarged by s about its centre of mass: a sphere of
radius s r; a composed particle whose tree is scaled by s (the root's conformal transform,
docs/architecture.md §2: ``p -> s p``, so phi scales by s and stays exact / 1-Lipschitz where
it was), its probes and bounding radius by s. The contact kernels see such a body as an
ordinary shape: every distinct (shape, scale) pair in use becomes one internal shape, built
once and kept (so a few size classes of a composed particle cost a few shape builds, a
continuous distribution of a composed particle one build per body: prefer classes there).
Without scales (or with every scale 1) the internal table is the registered shapes themselves,
and every step does exactly the arithmetic it did before scales existed.
"""
from __future__ import annotations

import numpy as np

from peclet.core.geom import encoding
from peclet.core.validation import PecletArgumentError, check_array, check_float
from peclet.dem.limits import MIN_SCALE
from peclet.dem.shapes import SceneShape, SphereShape, scene_shape, sphere_shape

__all__ = ["Scales", "scaled_shape", "MAX_SCALE"]

#: Scales lie in [MIN_SCALE, MAX_SCALE] (:data:`peclet.dem.limits.MIN_SCALE` = 1e-6, below
#: which a body's mass and inertia factors s^3, s^5 and its size against its own shape lose
#: meaning); beyond MAX_SCALE a shape's bounding sphere outgrows any domain.
MAX_SCALE = 1e3
_RANGE = f"in (0, {MAX_SCALE:g}], at least {MIN_SCALE:g}"


def scaled_shape(shape, s):
    """``shape`` (a SphereShape or SceneShape) enlarged by ``s`` about its home origin."""
    if isinstance(shape, SphereShape):
        return sphere_shape(shape.radius * s)
    assert isinstance(shape, SceneShape)
    nr = shape.node_reals.copy()
    root = shape.root
    nr[root, encoding.TRANSLATION] *= s            # p -> s (s0 R p + t) = (s s0) R p + s t
    nr[root, encoding.SCALE] *= s
    return scene_shape(shape.node_ints, nr, root, shape.shell * s, shape.radius * s)


class Scales:
    """Per-body scales (``values`` (N,) float64, or None: all 1) and the internal shapes."""

    def __init__(self):
        self.values = None
        self._built = {}          # (shape id, scale) -> scaled shape

    def resize(self, n):
        """Follow a change of N: the first min(N_old, n) keep their scale, new bodies get 1."""
        v = self.values
        if v is not None and len(v) != n:
            out = np.ones(n)
            k = min(n, len(v))
            out[:k] = v[:k]
            self.values = out

    def checked(self, scales, n):
        """``scales`` as a validated (n,) float64 array in [MIN_SCALE, MAX_SCALE]."""
        a = check_array("scales", scales, (n,))
        if np.any(a < MIN_SCALE) or np.any(a > MAX_SCALE):
            raise PecletArgumentError("scales", f"numbers {_RANGE}", scales,
                                      f"values in [{a.min():.4g}, {a.max():.4g}]")
        return a.copy()

    @staticmethod
    def checked_uniform(scale):
        s = check_float("scale", scale, 0.0, MAX_SCALE, lo_open=True)
        if s < MIN_SCALE:
            raise PecletArgumentError("scale", f"a finite number {_RANGE}", scale)
        return s

    def active(self):
        return self.values is not None and bool(np.any(self.values != 1.0))

    def table(self, shapes, ids):
        """(internal shapes, internal shape id per body) for the registered ``shapes`` and the
        bodies' shape ``ids``: the inputs themselves without scales; otherwise the registered
        shapes followed by one scaled shape per distinct (id, scale != 1) in use, ordered by
        (id, scale) so that the table depends only on the state, never on call history."""
        if not self.active():
            return shapes, ids
        v = self.values
        out_ids = ids.copy()
        scaled = v != 1.0
        pairs = sorted(set(zip(ids[scaled].tolist(), v[scaled].tolist())))
        table = list(shapes)
        index = {}
        for k, s in pairs:
            if (k, s) not in self._built:
                self._built[(k, s)] = scaled_shape(shapes[k], s)
            index[(k, s)] = len(table)
            table.append(self._built[(k, s)])
        sel = np.flatnonzero(scaled)
        out_ids[sel] = [index[(k, s)] for k, s in zip(ids[sel].tolist(), v[sel].tolist())]
        return table, out_ids
