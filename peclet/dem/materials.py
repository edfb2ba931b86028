"""Contact materials: the body-body material and the per-contact coefficients of a step."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from peclet.core.validation import check_float


class Material(NamedTuple):
    """Normal restitution ``e_n`` in [0, 1], tangential (Walton) restitution ``e_t`` in
    [-1, 1], Coulomb friction ``mu`` >= 0 (finite)."""
    e_n: float = 0.5
    e_t: float = 0.0
    mu: float = 0.5


def material(e_n, e_t, mu):
    """A validated :class:`Material`."""
    return Material(check_float("e_n", e_n, 0.0, 1.0), check_float("e_t", e_t, -1.0, 1.0),
                    check_float("mu", mu, 0.0))


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


def clamp_to_cone(lam, mu_c):
    """Scale each row's tangential impulse (``lam[:, 1:3]``) into the Coulomb cone
    ``|lam_t| <= mu lam_n``, in place (warm-start impulses must satisfy it too)."""
    tm = np.sqrt(lam[:, 1] ** 2 + lam[:, 2] ** 2)
    lim = mu_c * lam[:, 0]
    over = tm > lim
    if np.any(over):
        sc = np.where(tm[over] > 0, lim[over] / np.where(tm[over] > 0, tm[over], 1.0), 0.0)
        lam[over, 1] *= sc
        lam[over, 2] *= sc
