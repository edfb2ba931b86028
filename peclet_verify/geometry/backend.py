"""Geometry engines under certification: the backend protocol, peclet's reference engine, the
loader, and an out-of-process backend speaking numpy arrays over a pipe.

Protocol (duck-typed; the flat encoding of docs/architecture.md §2, phi < 0 inside, world =
root's parent frame):

``evaluate(node_ints, node_reals, root, points) -> phi``
    node_ints (n, 3) int32 (kind, left, right), node_reals (n, 16) float64
    (params[0:8], t[3], q[4] as (x, y, z, w), s), root an int, points (N, 3) float64;
    returns phi (N,) float64 of the tree at ``root``.
``evaluate_grad(...) -> (phi (N,), grad (N, 3))``  (optional) outward gradient.
``bound(node_ints, node_reals, root) -> (centre (3,), radius, certified)``  (optional) the
    root's ball in its parent frame and whether Equation 1 is claimed for it.
A ``name`` attribute is used in reports.

Reaching a backend: ``--peclet-backend module:factory``, else a
``pytest_peclet_make_backend(config)`` hook, else :class:`ReferenceBackend`. An engine in
another virtual environment: :class:`SubprocessBackend` with a child that calls
:func:`peclet_verify.wire.serve` (see :mod:`peclet_verify.geometry.child` and
:mod:`peclet_verify.geometry.wheel_child`).
"""
from __future__ import annotations

import os
import sys

import numpy as np

from ..loading import load_factory
from ..processes import ChildProcess

__all__ = ["ReferenceBackend", "SubprocessBackend", "load_backend", "check_backend",
           "default_backend", "child_command", "wheel_child_command"]

def check_backend(backend):
    """Raise ``ValueError`` unless ``backend`` has a callable ``evaluate``; return it."""
    if not callable(getattr(backend, "evaluate", None)):
        raise ValueError(f"backend must have evaluate(node_ints, node_reals, root, points); "
                         f"{backend!r} has none")
    return backend


class ReferenceBackend:
    """The peclet reference engine, via ``SceneBuilder.decode`` of the flat encoding."""

    name = "peclet-reference"

    def __init__(self):
        self._cache_key = None
        self._cache = None

    def _decode(self, ni, nr):
        ni = np.ascontiguousarray(ni, dtype=np.int32)
        nr = np.ascontiguousarray(nr, dtype=np.float64)
        key = (ni.tobytes(), nr.tobytes())
        if key != self._cache_key:
            from peclet.core.geom import SceneBuilder  # here: importing this module stays light
            self._cache = SceneBuilder.decode(ni, nr)
            self._cache_key = key
        return self._cache

    def evaluate(self, node_ints, node_reals, root, points):
        return self._decode(node_ints, node_reals).eval_root(int(root), points)

    def evaluate_grad(self, node_ints, node_reals, root, points):
        return self._decode(node_ints, node_reals).eval_root_grad(int(root), points)

    def bound(self, node_ints, node_reals, root):
        c, r, cert = self._decode(node_ints, node_reals).node_bound(int(root))
        return c, r, cert


def default_backend():
    """The engine certified when no other is named: :class:`ReferenceBackend`."""
    return ReferenceBackend()


def load_backend(spec, option="--peclet-backend"):
    """The geometry backend of ``"module:factory"`` (``factory()`` returns it; ``"reference"``
    or an empty spec: :class:`ReferenceBackend`). Every failure (a malformed spec, a module
    that does not import, no such factory, a factory that raises or returns no engine) is a
    ``ValueError`` naming ``option`` and the spec."""
    return load_factory(spec, option, default_backend, check_backend)


class SubprocessBackend(ChildProcess):
    """A backend served by a child process (``cmd``), which runs :func:`peclet_verify.wire.serve` on its engine.

    The child can live in another interpreter or virtual environment: it needs numpy and
    :mod:`peclet_verify.wire` only. ``evaluate_grad`` / ``bound`` exist on this object iff the
    child's engine offers them. Use as a context manager or call :meth:`close`.

    ``timeout`` (seconds, default :data:`DEFAULT_TIMEOUT`) bounds the wait for each answer,
    the child's start-up included: a child that does not answer in time is killed and the
    call raises :class:`TimeoutError` naming the backend (a certificate then fails with it).
    """

    timeout_label = "SubprocessBackend timeout"
    own_deadline = True  # its child times out: no in-process deadline on top

    def __init__(self, cmd, name=None, env=None, cwd=None, timeout=None):
        super().__init__(cmd, name=name, env=env, cwd=cwd, timeout=timeout)
        if "evaluate" not in self.methods:
            self.close()
            raise ValueError(f"child {cmd!r} serves no evaluate; it offers {self.methods}")

    def __getattr__(self, item):
        # evaluate_grad / bound appear only when the child offers them (hasattr is truthful)
        if item in ("evaluate_grad", "bound") and item in self.__dict__.get("methods", ()):
            return lambda *a: self._dispatch(item, *a)
        raise AttributeError(item)

    def _dispatch(self, method, ni, nr, root, points=None):
        args = [np.asarray(ni, np.int32), np.asarray(nr, np.float64), np.array(int(root))]
        if points is not None:
            args.append(np.ascontiguousarray(points, dtype=np.float64))
        out = self.call(method, *args)
        if method == "evaluate":
            return out[0]
        if method == "bound":
            return np.asarray(out[0], float), float(out[1]), bool(out[2])
        return tuple(out)

    def evaluate(self, node_ints, node_reals, root, points):
        return self._dispatch("evaluate", node_ints, node_reals, root, points)


_HERE = os.path.dirname(os.path.abspath(__file__))


def child_command(python=None):
    """Command that serves :class:`ReferenceBackend` from a child of ``python``."""
    return [python or sys.executable, os.path.join(_HERE, "child.py")]


def wheel_child_command(python):
    """Command that serves the upstream ``peclet-geom`` wheel installed for ``python``
    (through its dialect adapter :mod:`peclet_verify.geometry.wheel_child`)."""
    return [python, os.path.join(_HERE, "wheel_child.py")]
