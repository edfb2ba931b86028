"""Mass-property engines under certification: the protocol, peclet's quadrature, a child-process
engine. The certificate against the closed forms of the leaf table is
:func:`peclet_verify.properties.mass.mass_properties_certificate` (also importable from here,
as are ``closed_form_world`` and ``MASS_KINDS``, loaded on first use: this module stays free of
Hypothesis for the child processes that serve an engine).

Protocol (:class:`MassBackend`)
-------------------------------
``mass_properties(node_ints, node_reals, root, lo, hi, resolution_or_tol)`` -> ``(volume,
com (3,), inertia (3, 3))`` or ``(volume, com, inertia, claimed)``: the solid ``phi < 0`` of
the tree at ``root`` (flat encoding, docs/architecture.md §2; world = the root's parent frame)
inside the box [lo, hi], at unit density; ``inertia`` about the centre of mass. ``claimed`` is
the engine's own error claim, absolute: a float (volume) or a dict with ``"volume"`` and/or
``"inertia"`` (any entry of the tensor); None or absent: nothing claimed.

Declared attributes: ``resolutions`` (the values of the engine's accuracy knob to try, coarse to
fine: a tolerance that decreases, or a resolution such as cells per axis that increases),
``order`` p and optionally ``constant`` C: the engine states that its relative error is at most
``C h^p`` with ``h = resolution`` when the knob decreases (a tolerance) and ``h =
1 / resolution`` when it increases. Without ``constant``, C is taken from the coarsest level
(so the claim is about the RATE). Optional ``floor``: a relative error below which the
engine's precision is reached (default 1e-12; a float32 engine would state ~1e-6).

Reaching a backend: ``--peclet-mass-backend module:factory``, else a
``pytest_peclet_make_mass_backend(config)`` hook, else :class:`PecletMassBackend`.
"""
from __future__ import annotations

import math
import os
import sys
from typing import Protocol, Sequence, runtime_checkable

import numpy as np

from .family_child import FamilyChild, load_factory

# names in _MOVED resolve through the module __getattr__ below, which ruff cannot see
__all__ = ["MassBackend", "PecletMassBackend", "SubprocessMassBackend", "check_mass_backend",
           "load_mass_backend", "closed_form_world", "mass_properties_certificate",
           "MASS_KINDS", "mass_child_command", "wheel_mass_child_command"]

#: Names published here that live with the certificate (module -> names), loaded on use.
_MOVED = {"peclet_verify.properties.mass": ("closed_form_leaf", "closed_form_world",
                                            "mass_properties_certificate", "DEFAULT_FLOOR"),
          "peclet_verify.strategies.mass": ("MASS_KINDS",)}


def __getattr__(name):
    import importlib
    for module, names in _MOVED.items():
        if name in names:
            return getattr(importlib.import_module(module), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


@runtime_checkable
class MassBackend(Protocol):
    """See the module docstring."""

    resolutions: Sequence[float]
    order: float

    def mass_properties(self, node_ints, node_reals, root, lo, hi, resolution_or_tol): ...


class PecletMassBackend:
    """peclet's implicit quadrature, ``SceneBuilder.body_properties(root, lo, hi, n=32,
    tol=...)``: the knob is the relative tolerance, stated as relative error <= 1 x tol
    (order 1, constant 1).

    ``claim="tolerance"`` (default) claims what body_properties documents as its contract,
    ``|volume error| <= tol x volume``. ``claim="estimate"`` claims its error ESTIMATES
    ``volume_error`` and ``moment_error`` instead; these are not bounds: on a turned box at
    tol 1e-3 the true volume error is 1.5 x the estimate (a turned box [0.5, 0.9375, 1.0],
    quaternion (0.2474, 0, 0, 0.9689): estimate 4.1e-5, error 6.2e-5), so that mode fails the
    certificate. ``claim=None`` claims nothing."""

    name = "peclet quadrature (body_properties)"
    resolutions = (1e-3, 1e-4, 1e-6)
    order = 1.0
    constant = 1.0

    def __init__(self, claim="tolerance"):
        if claim not in ("tolerance", "estimate", None):
            from peclet.core.validation import PecletArgumentError
            raise PecletArgumentError("claim", "'tolerance', 'estimate' or None", claim)
        self.claim = claim

    def mass_properties(self, node_ints, node_reals, root, lo, hi, resolution_or_tol):
        from peclet.core.geom import SceneBuilder
        b = SceneBuilder.decode(np.asarray(node_ints, np.int32),
                                np.asarray(node_reals, np.float64))
        tol = float(resolution_or_tol)
        p = b.body_properties(int(root), lo, hi, n=32, tol=tol)
        claimed = None
        if self.claim == "tolerance":
            claimed = {"volume": tol * p.volume}
        elif self.claim == "estimate":
            claimed = {"volume": p.volume_error, "inertia": p.moment_error}
        return p.volume, p.com, p.inertia, claimed


class SubprocessMassBackend:
    """A :class:`MassBackend` served by a child process (``cmd`` runs
    :func:`peclet_verify.family_wire.serve` with a ``mass`` engine); its declared
    ``resolutions``, ``order`` and ``constant`` come from the child. Timeouts as for
    :class:`~peclet_verify.backends.SubprocessBackend`."""

    def __init__(self, cmd, name=None, env=None, cwd=None, timeout=None):
        self._child = FamilyChild(cmd, env=env, cwd=cwd, timeout=timeout, name=name)
        if "mass_properties" not in self._child.methods:
            self._child.close()
            raise ValueError(f"child {list(cmd)!r} serves no 'mass_properties'; it offers "
                             f"{sorted(self._child.methods)}")
        d = self._child.declared
        self.name = name or d.get("mass_name") or self._child.name
        self.resolutions = tuple(d["resolutions"])
        self.order = float(d["order"])
        self.constant = d.get("constant")

    def mass_properties(self, node_ints, node_reals, root, lo, hi, resolution_or_tol):
        v, com, inertia, claimed = self._child.call(
            "mass_properties", np.asarray(node_ints, np.int32),
            np.asarray(node_reals, np.float64), np.array(int(root)),
            np.asarray(lo, np.float64), np.asarray(hi, np.float64),
            np.array(float(resolution_or_tol)))
        c = {k: float(x) for k, x in zip(("volume", "inertia"), claimed) if np.isfinite(x)}
        return float(v), com, inertia, (c or None)

    def close(self):
        self._child.close()


def check_mass_backend(backend):
    """``backend`` if it has ``mass_properties``, non-empty ``resolutions`` and a finite
    ``order``; else ``ValueError`` saying what is missing."""
    if not callable(getattr(backend, "mass_properties", None)):
        raise ValueError(f"a mass backend must have mass_properties(node_ints, node_reals, "
                         f"root, lo, hi, resolution_or_tol); {backend!r} has none")
    res = getattr(backend, "resolutions", None)
    if not res or len(res) < 2:
        raise ValueError(f"a mass backend must declare resolutions (at least 2 values of its "
                         f"accuracy knob, coarse to fine); {backend!r} declares {res!r}")
    order = getattr(backend, "order", None)
    if not isinstance(order, (int, float)) or not math.isfinite(order) or order <= 0:
        raise ValueError(f"a mass backend must declare its convergence order (a number > 0); "
                         f"{backend!r} declares {order!r}")
    return backend


def load_mass_backend(spec, option="--peclet-mass-backend"):
    """The mass backend of ``"module:factory"`` (``"reference"``: :class:`PecletMassBackend`);
    ``ValueError`` naming ``option`` on any failure."""
    return load_factory(spec, option, PecletMassBackend, check_mass_backend)


def wheel_mass_child_command(python):
    """Command serving the upstream ``peclet-geom`` wheel's mass properties installed for
    ``python`` (through its dialect adapter :mod:`peclet_verify.peclet_geom_mass_child`)."""
    return [python, os.path.join(os.path.dirname(os.path.abspath(__file__)),
                                 "peclet_geom_mass_child.py")]


def mass_child_command(python=None):
    """Command serving peclet's quadrature (and DEM) from a child of ``python``."""
    return [python or sys.executable,
            os.path.join(os.path.dirname(os.path.abspath(__file__)), "peclet_dem_child.py")]
