"""Parent side of the DEM and mass-property families out of process, and the loader of
``module:factory`` specs for their options.

:class:`FamilyChild` is :class:`peclet_verify.backends.SubprocessBackend`'s pattern for the
families of :mod:`peclet_verify.family_wire`: a child process (any interpreter or virtual
environment with numpy; it loads ``family_wire.py`` and ``wire.py`` by file path) answers
framed numpy messages on its pipes; every answer is awaited at most ``timeout`` seconds (the
start-up included), after which the child is killed and the call raises ``TimeoutError``
naming the backend.
"""
from __future__ import annotations

import importlib
import json
import math
import os
import subprocess
import time

import numpy as np

from peclet.core.validation import PecletArgumentError, check_float

from . import wire
from .backends import CLOSE_GRACE, DEFAULT_TIMEOUT, _TimedPipe, parse_backend_spec

__all__ = ["FamilyChild", "load_factory", "check_factory_spec"]


class FamilyChild:
    """One child process serving :func:`peclet_verify.family_wire.serve`.

    ``cmd`` a non-empty list of program arguments; ``env`` (added to this process's
    environment), ``cwd``, ``timeout`` (seconds per answer, default :data:`DEFAULT_TIMEOUT`).
    ``methods`` and ``declared`` hold what the child serves and declares.
    """

    def __init__(self, cmd, name=None, env=None, cwd=None, timeout=None):
        if isinstance(cmd, (str, bytes)) or not isinstance(cmd, (list, tuple)) or not cmd \
                or not all(isinstance(c, (str, os.PathLike)) for c in cmd):
            raise PecletArgumentError("cmd", "a non-empty list of program arguments (strings)",
                                      cmd)
        self.timeout = DEFAULT_TIMEOUT if timeout is None else check_float(
            "timeout", timeout, 0.0, math.inf, lo_open=True)
        self.name = name or os.path.basename(str(cmd[-1]))
        self._proc = None
        full_env = dict(os.environ, **(env or {}))
        try:
            self._proc = subprocess.Popen([os.fspath(c) for c in cmd], stdin=subprocess.PIPE,
                                          stdout=subprocess.PIPE, stderr=None, env=full_env,
                                          cwd=cwd, bufsize=0)
        except OSError as exc:
            raise PecletArgumentError("cmd", "a command that can be started", cmd,
                                      str(exc)) from None
        out = self.call("methods")
        self.methods = set(str(m) for m in out[0].reshape(-1) if str(m))
        self.declared = json.loads(str(out[1]))

    def call(self, method, *args):
        if self._proc is None:
            raise RuntimeError(f"backend {self.name!r} is closed")
        what = (f"backend {self.name!r} did not answer {method!r} within {self.timeout:g} s "
                f"(timeout); the child was killed")
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

    def __del__(self):
        if getattr(self, "_proc", None) is not None:
            self.close()


def check_factory_spec(spec, option):
    """``(module, factory)`` of a ``module:factory`` spec given to ``option``, or None for
    ``"reference"`` / empty; :class:`PecletArgumentError` naming ``option`` otherwise.
    Cheap: nothing is imported."""
    try:
        return parse_backend_spec(spec)
    except PecletArgumentError:
        raise PecletArgumentError(option, "'module:factory' (dotted module, Python name) or "
                                  "'reference'", spec) from None


def load_factory(spec, option, default, check):
    """The backend ``factory()`` of ``spec`` returns, checked with ``check(backend)`` (which
    raises ``ValueError`` for an object that is no such backend); ``default()`` for
    ``"reference"``. Every failure is a ``ValueError`` naming ``option`` and the spec."""
    parsed = check_factory_spec(spec, option)
    if parsed is None:
        return default()
    mod_name, attr = parsed
    try:
        mod = importlib.import_module(mod_name)
    except ImportError as exc:
        raise ValueError(f"{option} {spec!r}: cannot import module {mod_name!r}: {exc}") \
            from exc
    factory = getattr(mod, attr, None)
    if not callable(factory):
        raise ValueError(f"{option} {spec!r}: {mod_name} has no callable {attr!r}")
    try:
        backend = factory()
    except Exception as exc:  # a broken factory is a usage error for the one who named it
        raise ValueError(f"{option} {spec!r}: {attr}() raised {type(exc).__name__}: {exc}") \
            from exc
    try:
        return check(backend)
    except ValueError as exc:
        raise ValueError(f"{option} {spec!r}: {exc}") from None
