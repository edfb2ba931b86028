"""Engines under certification: the backend protocol, our reference engine, loaders, and an
out-of-process backend speaking numpy arrays over a pipe.

Protocol (duck-typed; DESIGN.md §2 flat encoding, phi < 0 inside, world = root's parent frame):

``evaluate(node_ints, node_reals, root, points) -> phi``
    node_ints (n, 3) int32 (kind, left, right), node_reals (n, 16) float64
    (params[0:8], t[3], q[4] as (x, y, z, w), s), root an int, points (N, 3) float64;
    returns phi (N,) float64 of the tree at ``root``.
``evaluate_grad(...) -> (phi (N,), grad (N, 3))``  (optional) outward gradient.
``bound(node_ints, node_reals, root) -> (centre (3,), radius, certified)``  (optional) the
    root's ball in its parent frame and whether Equation 1 is claimed for it.
A ``name`` attribute is used in reports.
"""
from __future__ import annotations

import importlib
import os
import subprocess
import sys

import numpy as np

from peclet.core.geom import SceneBuilder

from . import wire

__all__ = ["ReferenceBackend", "SubprocessBackend", "load_backend", "serve", "check_backend",
           "backend_name", "peclet_geom_child_command"]

serve = wire.serve


def backend_name(backend) -> str:
    return getattr(backend, "name", type(backend).__name__)


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


def load_backend(spec: str):
    """Instantiate a backend from ``"module:factory"`` (``factory()`` returns the backend).

    ``"reference"`` (or an empty spec) gives :class:`ReferenceBackend`.
    """
    if not spec or spec == "reference":
        return ReferenceBackend()
    if not isinstance(spec, str) or spec.count(":") != 1:
        raise ValueError(f"backend must be 'module:factory' (or 'reference'), got {spec!r}")
    mod_name, attr = spec.split(":")
    try:
        mod = importlib.import_module(mod_name)
    except ImportError as exc:
        raise ValueError(f"backend {spec!r}: cannot import module {mod_name!r}: {exc}") from exc
    factory = getattr(mod, attr, None)
    if not callable(factory):
        raise ValueError(f"backend {spec!r}: {mod_name} has no callable {attr!r}")
    return check_backend(factory())


class SubprocessBackend:
    """A backend served by a child process (``cmd``), which runs :func:`serve` on its engine.

    The child can live in another interpreter or virtual environment: it needs numpy and
    :mod:`peclet_verify.wire` only. ``evaluate_grad`` / ``bound`` exist on this object iff the
    child's engine offers them. Use as a context manager or call :meth:`close`.
    """

    def __init__(self, cmd, name=None, env=None, cwd=None):
        if isinstance(cmd, str) or not cmd:
            raise ValueError(f"cmd must be a non-empty list of program arguments, got {cmd!r}")
        self.name = name or os.path.basename(str(cmd[-1]))
        self._proc = subprocess.Popen(list(cmd), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                      stderr=None, env=env, cwd=cwd)
        self._methods = set(str(m) for m in self._call("methods")[0].reshape(-1) if str(m))
        if "evaluate" not in self._methods:
            self.close()
            raise ValueError(f"child {cmd!r} serves no evaluate; it offers {self._methods}")

    def _call(self, method, *args):
        if self._proc is None:
            raise RuntimeError(f"backend {self.name!r} is closed")
        try:
            wire.write_message(self._proc.stdin, [np.array(method), *args])
            reply = wire.read_message(self._proc.stdout)
        except (EOFError, BrokenPipeError) as exc:
            code = self._proc.poll()
            raise RuntimeError(f"backend {self.name!r} child died (exit code {code}): "
                               f"{exc}") from exc
        if str(reply[0]) != "ok":
            raise RuntimeError(f"backend {self.name!r} failed in {method}:\n{reply[1]}")
        return reply[1:]

    def __getattr__(self, item):
        # evaluate_grad / bound appear only when the child offers them (hasattr is truthful)
        if item in ("evaluate_grad", "bound") and item in self.__dict__.get("_methods", ()):
            return lambda *a: self._dispatch(item, *a)
        raise AttributeError(item)

    def _dispatch(self, method, ni, nr, root, points=None):
        args = [np.asarray(ni, np.int32), np.asarray(nr, np.float64), np.array(int(root))]
        if points is not None:
            args.append(np.ascontiguousarray(points, dtype=np.float64))
        out = self._call(method, *args)
        if method == "evaluate":
            return out[0]
        if method == "bound":
            return np.asarray(out[0], float), float(out[1]), bool(out[2])
        return tuple(out)

    def evaluate(self, node_ints, node_reals, root, points):
        return self._dispatch("evaluate", node_ints, node_reals, root, points)

    def close(self):
        if self._proc is not None:
            try:
                wire.write_message(self._proc.stdin, [np.array("close")])
                wire.read_message(self._proc.stdout)
            except Exception:  # the child may already be gone; closing must not raise
                pass
            for f in (self._proc.stdin, self._proc.stdout):
                f.close()
            self._proc.wait(timeout=30)
            self._proc = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        if getattr(self, "_proc", None) is not None:
            self.close()


def reference_child_command(python=None):
    """Command that serves :class:`ReferenceBackend` from a child of ``python``."""
    return [python or sys.executable, "-c",
            "from peclet_verify.backends import ReferenceBackend, serve; serve(ReferenceBackend())"]


def peclet_geom_child_command(python):
    """Command that serves the upstream ``peclet-geom`` wheel installed for ``python``."""
    return [python, os.path.join(os.path.dirname(os.path.abspath(__file__)),
                                 "peclet_geom_child.py")]
