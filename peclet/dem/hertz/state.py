"""The Hertz engine's state in a Simulation: moduli per material id, rolling friction per pair of
material ids and the contact histories (docstring of :mod:`peclet.dem.hertz`, "Moduli")."""
from __future__ import annotations

import numpy as np

from peclet.core.validation import PecletArgumentError, check_float, check_int
from peclet.dem.materials import MAX_MATERIAL_ID

from .rolling import MU_R_MAX


class HertzState:
    """The Hertz engine's state in a Simulation: moduli per material id, rolling friction per
    pair of material ids, and the contact histories (``keys`` (K,) sorted int64, ``xi`` (K, 3)
    the tangential displacement and ``mr`` (K, 3) the rolling spring torque, world frame, for
    ``n_bodies`` bodies)."""

    def __init__(self):
        self.moduli = {}                       # material id -> (E, nu)
        self.rolling = {}                      # (i, j), i <= j, or None (every pair) -> mu_r
        self.keys = np.zeros(0, np.int64)
        self.xi = np.zeros((0, 3))
        self.mr = np.zeros((0, 3))
        self.n_bodies = -1
        self.last = None                       # the last substep's contacts and forces
        self.cand = None                       # the candidate list (see substep)
        self.spacing = None                    # (geometry, probe spacing per shape)
        self.dist_last = None                  # the last distributed contacts' details

    def set_material(self, material_id, youngs, poisson):
        """Young's modulus ``youngs`` (> 0, finite; pressure units) and Poisson ratio
        ``poisson`` in (-1, 0.5) of material id ``material_id`` in [0, 1023]."""
        mid = check_int("material_id", material_id, 0, MAX_MATERIAL_ID)
        e = check_float("youngs", youngs, 0.0, lo_open=True)
        nu = check_float("poisson", poisson, -1.0, 0.5, lo_open=True, hi_open=True)
        self.moduli[mid] = (e, nu)

    def set_rolling(self, mu_r, material_a=None, material_b=None):
        """Rolling friction ``mu_r`` in [0, MU_R_MAX] for the pair of material ids
        (``material_a``, ``material_b``), or for every pair not declared when both are None."""
        mu_r = check_float("mu_r", mu_r, 0.0, MU_R_MAX)
        if (material_a is None) != (material_b is None):
            raise PecletArgumentError("material_b" if material_b is None else "material_a",
                                      "given together with the other material id (a pair), "
                                      "or both None (every pair)", None)
        if material_a is None:
            self.rolling[None] = mu_r
            return
        ia = check_int("material_a", material_a, 0, MAX_MATERIAL_ID)
        ib = check_int("material_b", material_b, 0, MAX_MATERIAL_ID)
        self.rolling[(min(ia, ib), max(ia, ib))] = mu_r

    def rolling_active(self):
        return any(v > 0.0 for v in self.rolling.values())

    def snapshot(self):
        """What a refused substep puts back (:meth:`restore`): histories and candidates."""
        return (self.keys, self.xi, self.mr, self.cand)

    def restore(self, kept):
        self.keys, self.xi, self.mr, self.cand = kept

    def clear_history(self):
        self.keys = np.zeros(0, np.int64)
        self.xi = np.zeros((0, 3))
        self.mr = np.zeros((0, 3))

    def _modulus(self, mid, what):
        if mid not in self.moduli:
            raise PecletArgumentError("material ids", "declared with set_hertz_material("
                                      "material_id, youngs, poisson) before step_hertz",
                                      mid, f"{what} material id {mid} has no moduli")
        return self.moduli[mid]

    def body_moduli(self, body_ids):
        """(E, nu) per body from its material id (every id must be declared)."""
        uk, inv = np.unique(body_ids, return_inverse=True)
        tab = np.array([self._modulus(int(k), "body") for k in uk], np.float64).reshape(-1, 2)
        inv = inv.reshape(-1)
        return tab[inv, 0], tab[inv, 1]

    def wall_moduli(self, wall_ids):
        """(normal compliance (1 - nu^2)/E, shear compliance (2 - nu)/G) per wall: both zero
        for a wall without a material id (rigid)."""
        ce = np.zeros(len(wall_ids))
        cg = np.zeros(len(wall_ids))
        for w, k in enumerate(wall_ids.tolist()):
            if k >= 0:
                e, nu = self._modulus(int(k), "wall")
                ce[w] = (1.0 - nu * nu) / e
                cg[w] = (2.0 - nu) * 2.0 * (1.0 + nu) / e
        return ce, cg

    def _lookup(self, keys, table):
        out = np.zeros((len(keys), 3))
        if len(keys) and len(self.keys):
            j = np.minimum(np.searchsorted(self.keys, keys), len(self.keys) - 1)
            hit = self.keys[j] == keys
            out[hit] = table[j[hit]]
        return out

    def lookup(self, keys):
        """The stored history (nc, 3) of each key, zero for a new contact."""
        return self._lookup(keys, self.xi)

    def lookup_rolling(self, keys):
        """The stored rolling spring torque (nc, 3) of each key, zero for a new contact."""
        return self._lookup(keys, self.mr)

    def store(self, keys, xi, touching, n_bodies, mr=None):
        o = np.argsort(keys[touching], kind="stable")
        self.keys = keys[touching][o]
        self.xi = xi[touching][o]
        self.mr = mr[touching][o] if mr is not None else np.zeros((len(self.keys), 3))
        self.n_bodies = n_bodies

    def arrays(self):
        """(moduli (M, 3) rows id, E, nu; keys; xi; n_bodies) for a save."""
        rows = [[k, e, nu] for k, (e, nu) in sorted(self.moduli.items())]
        return (np.array(rows, np.float64).reshape(-1, 3), self.keys.copy(), self.xi.copy(),
                np.int64(self.n_bodies))

    def rolling_arrays(self):
        """(settings (P, 3) rows material_a, material_b, mu_r with -1, -1 for every pair;
        mr (K, 3) aligned with ``keys``) for a save."""
        rows = [[-1, -1, v] if k is None else [k[0], k[1], v]
                for k, v in sorted(self.rolling.items(), key=lambda kv: (-1, -1)
                                   if kv[0] is None else kv[0])]
        return np.array(rows, np.float64).reshape(-1, 3), np.ascontiguousarray(self.mr)
