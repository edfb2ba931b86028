"""The D3Q19 lattice: velocities, weights, opposites, and the TRT relaxation rates.

Lattice units throughout this package: one cell = 1, one step = 1, reference density rho0 = 1,
speed of sound c_s^2 = 1/3. Velocity ``i`` is ``C[i]`` (integers), weight ``W[i]``, its
opposite ``OPP[i]`` (``C[OPP[i]] = -C[i]``). Index 0 is the rest velocity.
"""
from __future__ import annotations

import numpy as np

from peclet.core.validation import check_float

__all__ = ["Q", "C", "W", "OPP", "CS2", "MAGIC_DEFAULT", "trt_rates"]

Q = 19
CS2 = 1.0 / 3.0

_axes = [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)]
_diag = [(1, 1, 0), (-1, -1, 0), (1, -1, 0), (-1, 1, 0),
         (1, 0, 1), (-1, 0, -1), (1, 0, -1), (-1, 0, 1),
         (0, 1, 1), (0, -1, -1), (0, 1, -1), (0, -1, 1)]
#: (19, 3) int64 lattice velocities; pairs (i, i+1) for i odd are opposites.
C = np.array([(0, 0, 0)] + _axes + _diag, dtype=np.int64)
#: (19,) weights: 1/3 rest, 1/18 axis, 1/36 diagonal.
W = np.array([1.0 / 3.0] + [1.0 / 18.0] * 6 + [1.0 / 36.0] * 12)
#: (19,) index of the opposite velocity.
OPP = np.array([0] + [i + 1 if i % 2 == 1 else i - 1 for i in range(1, Q)], dtype=np.int64)

assert np.all(C[OPP] == -C)
assert abs(W.sum() - 1.0) < 1e-15

#: Ginzburg's "magic" product Lambda = (tau+ - 1/2)(tau- - 1/2). With 3/16, bounce-back puts a
#: straight wall exactly halfway between nodes for Poiseuille flow, and steady results (hence
#: the permeability) do not depend on the viscosity.
MAGIC_DEFAULT = 3.0 / 16.0


def trt_rates(nu, magic=MAGIC_DEFAULT):
    """(omega_plus, omega_minus) of the two-relaxation-time collision for kinematic viscosity
    ``nu`` (lattice units, cells^2/step; nu = (tau+ - 1/2)/3) and magic parameter ``magic``."""
    nu = check_float("nu", nu, 0.0, lo_open=True)
    magic = check_float("magic", magic, 0.0, lo_open=True)
    tau_p = 3.0 * nu + 0.5
    tau_m = 0.5 + magic / (tau_p - 0.5)
    return 1.0 / tau_p, 1.0 / tau_m
