"""The wall rule of every cut link of a :class:`~peclet.flow.geometry.LatticeGeometry`, as the
table :func:`link_table` the lattice-Boltzmann step (:mod:`peclet.flow.solver`) pulls through:
Bouzidi, Firdaouss & Lallemand's interpolated bounce-back (linear or quadratic) with a parabolic
correction (:func:`_correction`), plain halfway bounce-back (``"bounce_back"``: every cut link
reflects at the node, the wall put halfway along the link whatever its fraction q; the
staircase reference), and :func:`fallback_counts` of the links whose stencil was incomplete.
Lattice units (cell 1, step 1)."""
from __future__ import annotations

import numpy as np

from peclet.core.validation import check_choice

from .lattice import C, OPP, W

__all__ = ["link_table", "fallback_counts", "SCHEMES"]

SCHEMES = ("linear", "quadratic", "bouzidi", "bounce_back")


def _correction(q, tp, tm, rule):
    """(alpha, beta) of the parabolic correction ``alpha n-_i(x) + beta S-_i`` for ``rule``
    (one of "lin_lo", "lin_hi", "quad_lo", "quad_hi", "bb"); tp, tm the TRT relaxation times.

    Derived here (not copied): the steady TRT solution on one link pair for a velocity
    U0 + U1 s + U2 s^2 along the link at constant density, with any body force, is solved
    exactly; the rule's value minus the exact incoming population, required to vanish for
    every U1, U2, F with u = 0 at the wall, is alpha n- + beta S-.
    """
    d = tm * (2.0 * tp - 1.0)
    if rule == "lin_lo":
        return (-2.0 * (q * q + 2.0 * q * tp - q - 2.0 * tm * tp + tm) / d,
                q * (2.0 * tm - 1.0) * (q + 2.0 * tp - 1.0) / d)
    if rule == "lin_hi":
        return (-(q * q - 2.0 * q * tp + q - 2.0 * tm * tp + tm + 2.0 * tp - 1.0) / (q * d),
                (2.0 * tm - 1.0) * (q * q - 2.0 * q * tp + q + 2.0 * tp - 1.0) / (2.0 * q * d))
    if rule == "quad_lo":
        return (2.0 * (q * q - 2.0 * q * tp + 2.0 * tm * tp - tm) / d,
                -q * (q - 2.0 * tp) * (2.0 * tm - 1.0) / d)
    if rule == "quad_hi":
        e = q * (2.0 * q + 1.0) * d
        return (2.0 * (q * q + 2.0 * q * tp - 2.0 * q + 2.0 * tm * tp - tm - 2.0 * tp + 1.0) / e,
                -(q - 1.0) * (2.0 * tm - 1.0) * (q + 2.0 * tp - 1.0) / e)
    return (-(2.0 * q * q - 4.0 * tm * tp + 2.0 * tm + 2.0 * tp - 1.0) / d,
            (2.0 * tm - 1.0) * (2.0 * q * q + 2.0 * tp - 1.0) / (2.0 * d))


def link_table(geo, scheme="linear", omegas=(1.0, 1.0), force=(0.0, 0.0, 0.0)):
    """The wall rule of every cut link: (lc (K, 3) float64, ld (K, 3) int64 populations,
    ln (K, 3) int64 nodes, la (K,), lb (K,)), so that the population pulled on link k is
    ``sum_m lc[k, m] * f*[ld[k, m], ln[k, m]] + la[k] * n-_i(x) + lb[k]`` with f* the
    post-collision values and n-_i(x) the antisymmetric non-equilibrium part of the pulled
    population at its node in the previous step.

    With i the pulled population, o its opposite (heading to the wall), q the wall fraction,
    x the node, x_f = x + c_i and x_ff = x + 2 c_i, the interpolation (Bouzidi, Firdaouss &
    Lallemand 2001, Lagrange interpolation along the link of the population that reflects):

    - linear, q < 1/2: 2q f*_o(x) + (1-2q) f*_o(x_f);
      q >= 1/2: f*_o(x)/(2q) + (1-1/(2q)) f*_i(x);
    - quadratic, q < 1/2: q(1+2q) f*_o(x) + (1-4q^2) f*_o(x_f) - q(1-2q) f*_o(x_ff);
      q >= 1/2: f*_o(x)/(q(2q+1)) + (2q-1)/q f*_i(x) + (1-2q)/(1+2q) f*_i(x_f).

    "linear" and "quadratic" add a parabolic correction ``alpha(q) n-_i(x) + beta(q) S-_i``
    (S-_i = 3 w_i c_i.F, the antisymmetric force term) that makes the rule exact for a
    velocity parabolic along the link at uniform density under TRT, for any q, viscosity and
    magic parameter (see :func:`_correction`); "bouzidi" is the plain linear rule (second
    order, its error grows with the magic parameter and q); "bounce_back" is halfway
    bounce-back on every cut link, ``f*_o(x)`` (no interpolation, no correction: the wall sits
    halfway along every link, exact for a straight wall at q = 1/2 with magic 3/16, first
    order in h for any other q). Where a node the stencil needs
    is missing (solid, or behind another cut link) the quadratic rule falls back to the
    linear one, and the linear one for q < 1/2 without x_f to bounce-back from the node
    itself, f*_o(x), with its own correction (counted by :func:`fallback_counts`).
    """
    scheme = check_choice("scheme", scheme, SCHEMES)
    tp, tm = 1.0 / omegas[0], 1.0 / omegas[1]
    q = np.asarray(geo.link_q, np.float64)
    i = np.asarray(geo.link_dir, np.int64)
    o = OPP[i]
    x = np.asarray(geo.link_node, np.int64)
    xf = np.asarray(geo.link_ff, np.int64)
    xff = np.asarray(geo.link_fff, np.int64)
    k = len(q)
    lc = np.zeros((k, 3))
    ld = np.zeros((k, 3), np.int64)
    ln = np.zeros((k, 3), np.int64)
    la = np.zeros(k)
    beta = np.zeros(k)
    ld[:] = o[:, None]
    ln[:] = x[:, None]
    if scheme == "bounce_back":
        lc[:, 0] = 1.0
        return lc, ld, ln, la, np.zeros(k)
    lo = q < 0.5
    quad = scheme == "quadratic"

    def rule(m, name, coef, dirs, nodes):
        for c in range(len(coef)):
            lc[m, c] = coef[c]
            ld[m, c] = dirs[c][m] if isinstance(dirs[c], np.ndarray) else dirs[c]
            ln[m, c] = nodes[c][m]
        if scheme != "bouzidi":
            la[m], beta[m] = _correction(q[m], tp, tm, name)

    m = ~lo
    qq = q[m]
    rule(m, "lin_hi", (1.0 / (2.0 * qq), 1.0 - 1.0 / (2.0 * qq)), (o, i), (x, x))
    m = lo & (xf >= 0)
    qq = q[m]
    rule(m, "lin_lo", (2.0 * qq, 1.0 - 2.0 * qq), (o, o), (x, xf))
    m = lo & (xf < 0)
    rule(m, "bb", (np.ones(int(m.sum())),), (o,), (x,))
    if quad:
        m = lo & (xff >= 0)
        qq = q[m]
        rule(m, "quad_lo", (qq * (1.0 + 2.0 * qq), 1.0 - 4.0 * qq * qq, -qq * (1.0 - 2.0 * qq)),
             (o, o, o), (x, xf, xff))
        m = ~lo & (xf >= 0)
        qq = q[m]
        rule(m, "quad_hi", (1.0 / (qq * (2.0 * qq + 1.0)), (2.0 * qq - 1.0) / qq,
                            (1.0 - 2.0 * qq) / (1.0 + 2.0 * qq)), (o, i, i), (x, x, xf))
    F = np.asarray(force, np.float64)
    lb = beta * 3.0 * W[i] * (C[i] @ F)
    return lc, ld, ln, la, lb


def fallback_counts(geo, scheme="linear"):
    """{"linear": links where the quadratic stencil was incomplete, "bounce_back": links on
    bounce-back from the node itself} for ``scheme`` (every link with "bounce_back")."""
    q, xf, xff = geo.link_q, geo.link_ff, geo.link_fff
    if scheme == "bounce_back":
        return {"linear": 0, "bounce_back": int(len(q))}
    half = int(np.count_nonzero((q < 0.5) & (xf < 0)))
    if scheme != "quadratic":
        return {"linear": 0, "bounce_back": half}
    lin = int(np.count_nonzero(((q < 0.5) & (xf >= 0) & (xff < 0)) | ((q >= 0.5) & (xf < 0))))
    return {"linear": lin, "bounce_back": half}
