"""Engines under certification: the backend protocol, our reference engine, loaders, and an
out-of-process backend speaking numpy arrays over a pipe.

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
"""
from __future__ import annotations

import importlib
import math
import os
import select
import subprocess
import sys
import time

import numpy as np

from peclet.core.validation import PecletArgumentError, check_float

from . import wire

__all__ = ["ReferenceBackend", "SubprocessBackend", "ChildProcess", "load_backend",
           "parse_backend_spec", "serve", "check_backend", "backend_name",
           "peclet_geom_child_command", "DEFAULT_TIMEOUT"]

serve = wire.serve

#: Seconds :class:`SubprocessBackend` waits for each answer (start-up included) by default.
DEFAULT_TIMEOUT = 300.0
#: Seconds a closing child gets to exit before it is killed.
CLOSE_GRACE = 10.0


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


def parse_backend_spec(spec):
    """``(module, factory)`` of a ``"module:factory"`` spec, or None for the reference engine
    (``None``, ``""`` or ``"reference"``); :class:`PecletArgumentError` for anything else.
    Cheap: nothing is imported."""
    if spec is None or spec in ("", "reference"):
        return None
    accepted = "'module:factory' (dotted module, Python name) or 'reference'"
    if not isinstance(spec, str) or spec.count(":") != 1:
        raise PecletArgumentError("backend", accepted, spec)
    mod_name, attr = spec.split(":")
    if not all(part.isidentifier() for part in mod_name.split(".")) or not attr.isidentifier():
        raise PecletArgumentError("backend", accepted, spec)
    return mod_name, attr


def load_backend(spec: str):
    """Instantiate a backend from ``"module:factory"`` (``factory()`` returns the backend).

    ``"reference"`` (or an empty spec) gives :class:`ReferenceBackend`. Every failure (a
    malformed spec, a module that does not import, no such factory, a factory that raises or
    returns no engine) is a ``ValueError`` naming the spec.
    """
    parsed = parse_backend_spec(spec)
    if parsed is None:
        return ReferenceBackend()
    return check_backend(_call_factory(spec, parsed, "backend"))


def _call_factory(spec, parsed, label):
    """What the factory of ``spec`` (``parsed``: its ``(module, factory)``) returns. Every
    failure (a module that does not import, no such factory, a factory that raises) is a
    ``ValueError`` starting ``"{label} {spec!r}: "``."""
    mod_name, attr = parsed
    try:
        mod = importlib.import_module(mod_name)
    except ImportError as exc:
        raise ValueError(f"{label} {spec!r}: cannot import module {mod_name!r}: {exc}") \
            from exc
    factory = getattr(mod, attr, None)
    if not callable(factory):
        raise ValueError(f"{label} {spec!r}: {mod_name} has no callable {attr!r}")
    try:
        return factory()
    except Exception as exc:  # a broken factory is a usage error for the one who named it
        raise ValueError(f"{label} {spec!r}: {attr}() raised {type(exc).__name__}: {exc}") \
            from exc


class _TimedPipe:
    """``read(n)`` / ``write(data)`` on a child's pipes that give up (``TimeoutError(what)``)
    once ``deadline`` (time.monotonic()) has passed: a child that neither answers nor reads
    its input cannot hang the certification."""

    def __init__(self, proc, deadline, what):
        self.rfd, self.wfd = proc.stdout.fileno(), proc.stdin.fileno()
        self.deadline, self.what = deadline, what

    def _wait(self, fd, for_write):
        left = self.deadline - time.monotonic()
        ready = select.select([], [fd], [], left)[1] if for_write else \
            select.select([fd], [], [], left)[0]
        if left <= 0 or not ready:
            raise TimeoutError(self.what)

    def read(self, n):
        chunks, got = [], 0
        while got < n:
            self._wait(self.rfd, False)
            data = os.read(self.rfd, n - got)
            if not data:
                break  # EOF: the caller reports the short read
            chunks.append(data)
            got += len(data)
        return b"".join(chunks)

    def write(self, data):
        view = memoryview(data)
        while len(view):
            self._wait(self.wfd, True)
            view = view[os.write(self.wfd, view[:select.PIPE_BUF]):]

    def flush(self):
        pass  # unbuffered (bufsize=0): every write went straight to the pipe


class ChildProcess:
    """A child process (``cmd``) answering framed numpy messages of :mod:`peclet_verify.wire`
    on its pipes: the start-up, each call with its timeout and error messages, kill and close.

    ``cmd`` a non-empty list of program arguments; ``env`` the child's environment (None: this
    process's), ``cwd``, ``timeout`` (seconds per answer, default :data:`DEFAULT_TIMEOUT`).
    A child that does not answer in time is killed and the call raises :class:`TimeoutError`
    naming the backend (``name``, default the command's last argument). Use as a context
    manager or call :meth:`close`.
    """

    #: Named in the message of a call that timed out.
    timeout_label = "timeout"

    def __init__(self, cmd, name=None, env=None, cwd=None, timeout=None):
        if isinstance(cmd, (str, bytes)) or not isinstance(cmd, (list, tuple)) or not cmd \
                or not all(isinstance(c, (str, os.PathLike)) for c in cmd):
            raise PecletArgumentError("cmd", "a non-empty list of program arguments (strings)",
                                      cmd)
        self.timeout = DEFAULT_TIMEOUT if timeout is None else check_float(
            "timeout", timeout, 0.0, math.inf, lo_open=True)
        self._check_name(name)
        self.name = name or os.path.basename(str(cmd[-1]))
        self._proc = None
        try:
            self._proc = subprocess.Popen([os.fspath(c) for c in cmd], stdin=subprocess.PIPE,
                                          stdout=subprocess.PIPE, stderr=None,
                                          env=self._child_env(env), cwd=cwd, bufsize=0)
        except OSError as exc:
            raise PecletArgumentError("cmd", "a command that can be started", cmd,
                                      str(exc)) from None

    def _check_name(self, name):
        """Hook: raise for a ``name`` this kind of child refuses (any is accepted here)."""

    def _child_env(self, env):
        """The environment the child starts with, from the ``env`` argument."""
        return env

    def call(self, method, *args):
        """The child's answer (a list of arrays) to ``method`` with ``args``."""
        if self._proc is None:
            raise RuntimeError(f"backend {self.name!r} is closed")
        what = (f"backend {self.name!r} did not answer {method!r} within {self.timeout:g} s "
                f"({self.timeout_label}); the child was killed")
        pipe = _TimedPipe(self._proc, time.monotonic() + self.timeout, what)
        try:
            wire.write_message(pipe, [np.array(method), *args])
            reply = wire.read_message(pipe)
        except TimeoutError:
            self._kill()
            raise
        except (EOFError, BrokenPipeError) as exc:
            code = self._proc.poll()
            raise RuntimeError(f"backend {self.name!r} child died (exit code {code}): "
                               f"{exc}") from exc
        if str(reply[0]) != "ok":
            raise RuntimeError(f"backend {self.name!r} failed in {method}:\n{reply[1]}")
        return reply[1:]

    def _kill(self):
        proc, self._proc = self._proc, None
        if proc is not None:
            proc.kill()
            proc.wait()
            for f in (proc.stdin, proc.stdout):
                f.close()

    def close(self):
        """Ask the child to exit (it has ``CLOSE_GRACE`` seconds), then kill it."""
        if self._proc is not None:
            pipe = _TimedPipe(self._proc, time.monotonic() + CLOSE_GRACE, "close")
            try:
                wire.write_message(pipe, [np.array("close")])
                wire.read_message(pipe)
            except Exception:  # the child may already be gone or hung; closing must not raise
                pass
            try:
                self._proc.wait(timeout=CLOSE_GRACE)
            except subprocess.TimeoutExpired:
                pass
            self._kill()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        if getattr(self, "_proc", None) is not None:
            self.close()


class SubprocessBackend(ChildProcess):
    """A backend served by a child process (``cmd``), which runs :func:`serve` on its engine.

    The child can live in another interpreter or virtual environment: it needs numpy and
    :mod:`peclet_verify.wire` only. ``evaluate_grad`` / ``bound`` exist on this object iff the
    child's engine offers them. Use as a context manager or call :meth:`close`.

    ``timeout`` (seconds, default :data:`DEFAULT_TIMEOUT`) bounds the wait for each answer,
    the child's start-up included: a child that does not answer in time is killed and the
    call raises :class:`TimeoutError` naming the backend (a certificate then fails with it).
    """

    timeout_label = "SubprocessBackend timeout"

    def __init__(self, cmd, name=None, env=None, cwd=None, timeout=None):
        super().__init__(cmd, name=name, env=env, cwd=cwd, timeout=timeout)
        self._methods = set(str(m) for m in self.call("methods")[0].reshape(-1) if str(m))
        if "evaluate" not in self._methods:
            self.close()
            raise ValueError(f"child {cmd!r} serves no evaluate; it offers {self._methods}")

    def _check_name(self, name):
        if name is not None and not isinstance(name, str):
            raise PecletArgumentError("name", "a string or None", name)

    def __getattr__(self, item):
        # evaluate_grad / bound appear only when the child offers them (hasattr is truthful)
        if item in ("evaluate_grad", "bound") and item in self.__dict__.get("_methods", ()):
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


def reference_child_command(python=None):
    """Command that serves :class:`ReferenceBackend` from a child of ``python``."""
    return [python or sys.executable, "-c",
            "from peclet_verify.backends import ReferenceBackend, serve; serve(ReferenceBackend())"]


def peclet_geom_child_command(python):
    """Command that serves the upstream ``peclet-geom`` wheel installed for ``python``."""
    return [python, os.path.join(os.path.dirname(os.path.abspath(__file__)),
                                 "peclet_geom_child.py")]
