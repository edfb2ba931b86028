"""Mass-property engines under certification: the protocol, peclet's quadrature, a child-process
engine. The certificate against the closed forms of the leaf table is
:func:`peclet_verify.mass.properties.mass_properties_certificate` (this module stays free of
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
engine's precision is reached (default :data:`DEFAULT_FLOOR`; a float32 engine would state
~1e-6). A floor is the error the engine is excused from, so it is bounded:
:data:`MAX_FLOOR`; a backend declaring more fails the certificate, and every verdict reports
the floor it was judged with.

Reaching a backend: ``--peclet-mass-backend module:factory``, else a
``pytest_peclet_make_mass_backend(config)`` hook, else :class:`PecletMassBackend`.
"""
from __future__ import annotations

import math
import os
import sys
from typing import Protocol, Sequence, runtime_checkable

import numpy as np

from ..loading import load_factory
from ..processes import ChildProcess

__all__ = ["MassBackend", "PecletMassBackend", "SubprocessMassBackend", "check_backend",
           "load_backend", "default_backend", "child_command", "wheel_child_command",
           "DEFAULT_FLOOR", "MAX_FLOOR"]

#: Relative error below which an engine's precision is reached unless it declares a ``floor``.
DEFAULT_FLOOR = 1e-12
#: The largest ``floor`` an engine may declare. Why 1e-5: a float32 engine's precision (eps
#: 1.2e-7) after summing 1e4 to 1e6 cell contributions is about 1e-6 relative, and ten times
#: that is the most any engine can need; a larger floor would excuse real error (a volume 0.1 %
#: off passing as "precision reached"). A certificate judging a larger floor fails.
MAX_FLOOR = 1e-5


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
    :func:`peclet_verify.wire.serve` with a ``mass`` engine); its declared
    ``resolutions``, ``order``, ``constant`` and ``floor`` come from the child. Timeouts as
    for :class:`~peclet_verify.processes.ChildProcess`."""

    own_deadline = True  # its child times out: no in-process deadline on top

    def __init__(self, cmd, name=None, env=None, cwd=None, timeout=None):
        self._child = ChildProcess(cmd, env=env, cwd=cwd, timeout=timeout, name=name)
        if "mass_properties" not in self._child.methods:
            self._child.close()
            raise ValueError(f"child {list(cmd)!r} serves no 'mass_properties'; it offers "
                             f"{sorted(self._child.methods)}")
        d = self._child.declared
        self.name = name or d.get("mass_name") or self._child.name
        self.resolutions = tuple(d["resolutions"])
        self.order = float(d["order"])
        self.constant = d.get("constant")
        if d.get("floor") is not None:
            self.floor = float(d["floor"])

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


def check_backend(backend):
    """``backend`` if it has ``mass_properties``, non-empty ``resolutions`` and a finite
    ``order`` (and a ``floor``, if declared, that is a number > 0); else ``ValueError`` saying
    what is missing. A floor above :data:`MAX_FLOOR` is not refused here: the certificate
    fails with it, so that the report shows it."""
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
    floor = getattr(backend, "floor", None)
    if floor is not None and (isinstance(floor, bool) or not isinstance(floor, (int, float))
                              or not math.isfinite(floor) or floor <= 0):
        raise ValueError(f"a mass backend's floor must be a number > 0 (a relative error) or "
                         f"None; {backend!r} declares {floor!r}")
    return backend


def default_backend():
    """The mass-property engine certified when no other is named: :class:`PecletMassBackend`."""
    return PecletMassBackend()


def load_backend(spec, option="--peclet-mass-backend"):
    """The mass backend of ``"module:factory"`` (``"reference"``: :class:`PecletMassBackend`);
    ``ValueError`` naming ``option`` on any failure."""
    return load_factory(spec, option, default_backend, check_backend)


_HERE = os.path.dirname(os.path.abspath(__file__))


def wheel_child_command(python):
    """Command serving the upstream ``peclet-geom`` wheel's mass properties installed for
    ``python`` (through its dialect adapter :mod:`peclet_verify.mass.wheel_child`)."""
    return [python, os.path.join(_HERE, "wheel_child.py")]


def child_command(python=None):
    """Command serving peclet's quadrature from a child of ``python``."""
    return [python or sys.executable, os.path.join(_HERE, "child.py")]
