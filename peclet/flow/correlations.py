"""Reference pressure drops and permeabilities of packed beds, each with its formula and source.

Any consistent units: U the superficial velocity, eps the bed voidage, d_p a particle diameter
(which one each correlation wants is said below), mu the dynamic viscosity, rho the density,
dP/L the pressure drop per unit bed length (positive along the flow).

- :func:`ergun`: Ergun (1952), "Fluid flow through packed columns", Chem. Eng. Prog. 48, 89-94::

      dP/L = A (1 - eps)^2 / eps^3 * mu U / d_p^2 + B (1 - eps) / eps^3 * rho U^2 / d_p

  with A = 150, B = 1.75; d_p the sphere diameter, for other shapes the Sauter diameter
  6 V_p / A_p (6 / a_v). Fitted to granular beds of voidage ~0.35-0.55.
- :func:`eisfeld_schnitzlein`: Eisfeld & Schnitzlein (2001), "The influence of confining walls
  on the pressure drop in packed beds", Chem. Eng. Sci. 56, 4321-4329, their Reichelt-type
  equation with the wall terms::

      dP/L = K1 A_w^2 (1 - eps)^2 / eps^3 * mu U / d_p^2 + A_w / B_w (1 - eps) / eps^3 * rho U^2 / d_p
      A_w = 1 + 2 / (3 (D_t / d_p) (1 - eps)),   B_w = (k1 (d_p / D_t)^2 + k2)^2

  spheres: K1 = 154, k1 = 1.15, k2 = 0.87 (:data:`ES_SPHERES`); d_p the volume-equivalent
  sphere diameter, D_t the column's diameter. D_t = inf (no wall) gives A_w = 1, B_w = k2^2.
- :func:`carman_kozeny`: k = eps^3 d_p^2 / (36 K (1 - eps)^2) with the Kozeny constant K = 5
  (Carman 1937, Trans. Inst. Chem. Eng. 15, 150-166; K = 5 is k = eps^3 d^2 / (180 (1 - eps)^2));
  d_p = 6 / a_v (Sauter).
- :func:`happel_kozeny`: the Kozeny constant of Happel's (1958) sphere-in-cell model, "Viscous
  flow in multiparticle systems: slow motion of fluids relative to beds of spherical
  particles", AIChE J. 4, 197-201; with gamma = (1 - eps)^(1/3)::

      dP/L = 18 mu U (1 - eps) / d^2 * (3 + 2 gamma^5) / (3 - 9/2 gamma + 9/2 gamma^5 - 3 gamma^6)

  so K = eps^3 d^2 / (36 (1 - eps)^2 k): 4.5 at eps 0.4, 5.1 at 0.6, 7.2 at 0.8, 11.3 at 0.9.
  The trend is the published one for high-voidage media (Carman 1937 and Davies 1952 for
  fibre beds likewise report K rising well above 5 as eps -> 1): the Ergun/Carman constant is
  a property of granular beds, not of every medium with the same a_v.

**Why the ratio to Ergun is not 1 for rings at eps ~0.8** (:data:`RING_NOTE`).
"""
from __future__ import annotations

import math

import numpy as np

from peclet.core.validation import check_float

__all__ = ["ERGUN", "ES_SPHERES", "RING_NOTE", "ergun", "eisfeld_schnitzlein", "carman_kozeny",
           "happel_kozeny", "ergun_kozeny", "friction_factor"]

#: Ergun's (1952) constants (A, B) of the viscous and inertial terms.
ERGUN = (150.0, 1.75)
#: Eisfeld & Schnitzlein (2001), spheres: (K1, k1, k2) of their wall-corrected Ergun equation.
ES_SPHERES = (154.0, 1.15, 0.87)

#: What the printed ratio to Ergun means for thin-walled elements at high voidage.
RING_NOTE = ("dP/L / Ergun is not expected to be 1 for rings at eps ~0.8: Ergun's 150 is a "
             "Kozeny constant of 150/36 = 4.17 fitted on granular beds of eps 0.35-0.55; at "
             "high voidage the Kozeny constant rises (Happel's cell model: 7.2 at eps 0.8, "
             "1.7 x Ergun's), and the Sauter diameter counts a ring's bore wall as fully "
             "wetted surface although the bore carries less than its share of the flow")


def _eps(eps):
    return check_float("eps", eps, 0.0, 1.0, lo_open=True, hi_open=True)


def ergun(U, eps, d_p, mu, rho=1.0, constants=ERGUN):
    """dP/L of Ergun's equation (module docstring) at superficial velocity U (scalar or array),
    voidage eps in (0, 1), particle diameter d_p (Sauter for non-spheres) > 0, viscosity mu
    and density rho. Returns (dP/L, its viscous part)."""
    eps = _eps(eps)
    d_p = check_float("d_p", d_p, 0.0, lo_open=True)
    A, B = constants
    U = np.asarray(U, np.float64)
    visc = A * (1.0 - eps) ** 2 / eps ** 3 * mu * U / d_p ** 2
    return visc + B * (1.0 - eps) / eps ** 3 * rho * U * U / d_p, visc


def eisfeld_schnitzlein(U, eps, d_p, D_t, mu, rho=1.0, constants=ES_SPHERES):
    """dP/L of Eisfeld & Schnitzlein's (2001) wall-corrected equation (module docstring) at
    superficial velocity U, voidage eps, volume-equivalent particle diameter d_p, column
    diameter D_t (> d_p; inf for no wall), viscosity mu, density rho. Returns (dP/L, A_w,
    B_w)."""
    eps = _eps(eps)
    K1, k1, k2 = constants
    A_w = 1.0 + 2.0 / (3.0 * (D_t / d_p) * (1.0 - eps))
    B_w = (k1 * (d_p / D_t) ** 2 + k2) ** 2
    visc = K1 * A_w ** 2 * (1.0 - eps) ** 2 / eps ** 3 * mu * U / d_p ** 2
    inert = A_w / B_w * (1.0 - eps) / eps ** 3 * rho * U * U / d_p
    return visc + inert, A_w, B_w


def carman_kozeny(eps, d_p, kozeny=5.0):
    """Permeability eps^3 d_p^2 / (36 K (1 - eps)^2) (units of d_p^2), K = ``kozeny``."""
    eps = _eps(eps)
    return eps ** 3 * d_p ** 2 / (36.0 * kozeny * (1.0 - eps) ** 2)


def happel_kozeny(eps):
    """The Kozeny constant of Happel's (1958) sphere-in-cell model at voidage eps (module
    docstring): the published rise of K with voidage beyond granular beds."""
    eps = _eps(eps)
    g = (1.0 - eps) ** (1.0 / 3.0)
    k = (3.0 - 4.5 * g + 4.5 * g ** 5 - 3.0 * g ** 6) / ((3.0 + 2.0 * g ** 5) * 18.0 * (1.0 - eps))
    return eps ** 3 / (36.0 * k * (1.0 - eps) ** 2)


def ergun_kozeny():
    """The Kozeny constant Ergun's viscous term implies: 150 / 36."""
    return ERGUN[0] / 36.0


def friction_factor(dpdl, U, d, mu):
    """The dimensionless resistance (dP/L) d^2 / (mu U) (Darcy: d^2 / k) of a measured point."""
    return dpdl * d * d / (mu * U) if U else math.nan
