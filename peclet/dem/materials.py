"""Contact materials: the body-body material and the per-contact coefficients of a step."""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from peclet.core.validation import PecletArgumentError, check_float, check_int


@dataclass(frozen=True)
class Material:
    """A contact material, the one type of the whole package (dimensionless).

    ``e_n``: normal restitution in [0, 1]; ``e_t``: tangential (Walton) restitution in [-1, 1];
    ``mu``: Coulomb friction >= 0 (finite). The defaults are the Pall-ring page's
    (0.15, 0.0, 0.5); a :class:`~peclet.dem.Simulation` whose material was never set uses
    :data:`SIMULATION_DEFAULT` instead. Construction checks every field
    (:class:`~peclet.core.validation.PecletArgumentError` naming it).
    """

    e_n: float = 0.15
    e_t: float = 0.0
    mu: float = 0.5

    def __post_init__(self):
        object.__setattr__(self, "e_n", check_float("e_n", self.e_n, 0.0, 1.0))
        object.__setattr__(self, "e_t", check_float("e_t", self.e_t, -1.0, 1.0))
        object.__setattr__(self, "mu", check_float("mu", self.mu, 0.0))

    def as_tuple(self):
        """(e_n, e_t, mu), the order of ``Simulation.set_material_params``."""
        return (self.e_n, self.e_t, self.mu)

    def to_dict(self):
        return asdict(self)


#: The body-body material of a Simulation before ``set_material_params``.
SIMULATION_DEFAULT = Material(0.5, 0.0, 0.5)


def material(e_n, e_t, mu):
    """A validated :class:`Material`."""
    return Material(e_n, e_t, mu)


#: Largest material id (ids are small integers indexing the pair table).
MAX_MATERIAL_ID = 1023


class MaterialTable:
    """Materials per pair of material ids (``set_material_ids``, ``set_pair_material``,
    ``set_wall_material_id``).

    Every body has a material id (default 0); a wall has none (its own restitution and friction
    from ``add_analytic_wall``) unless one is set. A body-body contact of ids (i, j) takes the
    pair (i, j) = (j, i); the pair (0, 0) is the simulation's ``set_material_params`` unless
    declared. A body-wall contact with a wall of id k takes the pair (i, k). A pair that a
    contact could need and that was never declared is an error before the step, naming it.
    """

    def __init__(self):
        self.body_ids = None                 # (N,) int64, None: every body 0
        self.wall_ids = np.zeros(0, np.int64)   # (W,) -1: the wall's own material
        self.pairs = {}                      # (i, j) with i <= j -> Material

    def active(self):
        """Whether any id other than the defaults is in use (else the old, cheaper path)."""
        return (self.pairs != {} or np.any(self.wall_ids >= 0)
                or (self.body_ids is not None and np.any(self.body_ids != 0)))

    def set_pair(self, a, b, e_n, e_t, mu):
        a = check_int("a", a, 0, MAX_MATERIAL_ID)
        b = check_int("b", b, 0, MAX_MATERIAL_ID)
        self.pairs[(min(a, b), max(a, b))] = material(e_n, e_t, mu)

    def lookup(self, i, j, default):
        """The material of the pair (i, j); ``default`` for an undeclared (0, 0)."""
        key = (min(i, j), max(i, j))
        if key in self.pairs:
            return self.pairs[key]
        if key == (0, 0):
            return default
        raise PecletArgumentError("material ids", "pairs declared with set_pair_material(a, b, "
                                  "e_n, e_t, mu) for every pair of ids in contact",
                                  f"({key[0]}, {key[1]})", "never declared")

    def check_declared(self, n_bodies, default):
        """Raise for any pair of ids (bodies x bodies, bodies x walls with an id) a contact
        could need and that was never declared."""
        ids = np.unique(self.body_ids) if self.body_ids is not None and n_bodies \
            else np.zeros(1 if n_bodies else 0, np.int64)
        for x in ids.tolist():
            for y in ids.tolist():
                self.lookup(x, y, default)
            for k in self.wall_ids[self.wall_ids >= 0].tolist():
                self.lookup(x, k, default)

    def per_contact(self, body_a, body_b, default, geo):
        """(e, e_t, mu) per contact from the table (see the class notes)."""
        nc = len(body_a)
        e = np.empty(nc)
        et = np.empty(nc)
        mu = np.empty(nc)
        ida = self.body_ids[body_a] if self.body_ids is not None else np.zeros(nc, np.int64)
        isw = body_b < 0
        widx = np.where(isw, -1 - body_b, 0)
        bids = np.where(isw, -1, 0)
        if self.body_ids is not None:
            bids = np.where(isw, -1, self.body_ids[np.where(isw, 0, body_b)])
        if len(self.wall_ids):
            bids = np.where(isw, self.wall_ids[widx], bids)
        own_wall = isw & (bids < 0)
        # the walls with their own material: as the default path does
        if np.any(own_wall):
            e[own_wall] = geo.wall_e[widx[own_wall]]
            mu[own_wall] = geo.wall_mu[widx[own_wall]]
            et[own_wall] = default.e_t
        rest = ~own_wall
        if np.any(rest):
            key = np.stack([ida[rest], bids[rest]], axis=1)
            uk, inv = np.unique(key, axis=0, return_inverse=True)
            tab = np.array([self.lookup(int(x), int(y), default).as_tuple()
                            for x, y in uk.tolist()], np.float64).reshape(-1, 3)
            inv = inv.reshape(-1)
            e[rest], et[rest], mu[rest] = tab[inv, 0], tab[inv, 1], tab[inv, 2]
        return e, et, mu

    def arrays(self, n_bodies):
        """(body ids (N,), wall ids (W,), pairs (K, 5) rows a, b, e_n, e_t, mu) for a save."""
        ids = self.body_ids if self.body_ids is not None else np.zeros(n_bodies, np.int64)
        rows = [[a, b, m.e_n, m.e_t, m.mu] for (a, b), m in sorted(self.pairs.items())]
        return ids, self.wall_ids.copy(), np.array(rows, np.float64).reshape(-1, 5)


def per_contact(body_b, mat, geo):
    """(e, e_t, mu) per contact (each (nc,)): a wall contact (``body_b`` < 0, wall -1 - b) takes
    the wall's restitution and friction, a body-body contact the body material ``mat``."""
    nc = len(body_b)
    isw = body_b < 0
    widx = np.where(isw, -1 - body_b, 0)
    if len(geo.wall_e):
        e_c = np.where(isw, geo.wall_e[widx], mat.e_n)
        mu_c = np.where(isw, geo.wall_mu[widx], mat.mu)
    else:
        e_c = np.full(nc, mat.e_n)
        mu_c = np.full(nc, mat.mu)
    return e_c, np.full(nc, mat.e_t), mu_c
