"""Child processes that serve an engine under certification, and deadlines for every call of
an engine in this process.

:class:`ChildProcess` starts a child (any interpreter or virtual environment with numpy; it
runs :func:`peclet_verify.wire.serve`), sends framed numpy messages on its pipes and awaits
each answer at most ``timeout`` seconds (the start-up included), after which the child is
killed and the call raises ``TimeoutError`` naming the backend. Each family's subprocess
backend is built on it.

:class:`DeadlineBackend` gives an engine running in this process the same protection: each
call runs in a worker thread and is awaited at most ``deadline`` seconds; a call that does not
return in time raises ``TimeoutError`` naming the engine, the call and the deadline (the
certificate fails with it), and the engine is not called again (it may still be busy). The
pytest plugin wraps every in-process engine in one (``--peclet-deadline``, default
:data:`DEFAULT_DEADLINE` seconds).
"""
from __future__ import annotations

import json
import math
import os
import queue
import select
import subprocess
import threading
import time

import numpy as np

from peclet.core.validation import PecletArgumentError, check_float

from . import wire
from .loading import backend_name

__all__ = ["ChildProcess", "TimedPipe", "DeadlineBackend", "with_deadline", "DEFAULT_TIMEOUT",
           "DEFAULT_DEADLINE", "CLOSE_GRACE"]

#: Seconds a :class:`ChildProcess` waits for each answer (start-up included) by default.
DEFAULT_TIMEOUT = 300.0
#: Seconds a call of an in-process engine may take by default (:class:`DeadlineBackend`): the
#: same as a child's answer; the slowest call peclet's own engines make in a certificate (a
#: DEM pour, a quadrature at tol 1e-6, first compilation included) takes well under a minute.
DEFAULT_DEADLINE = DEFAULT_TIMEOUT
#: Seconds a closing child gets to exit before it is killed.
CLOSE_GRACE = 10.0


class TimedPipe:
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
    process's; see :meth:`child_env`), ``cwd``, ``timeout`` (seconds per answer, default
    :data:`DEFAULT_TIMEOUT`). A child that does not answer in time is killed and the call
    raises :class:`TimeoutError` naming the backend (``name``, default the command's last
    argument). At start-up the child is asked what it serves: ``methods`` (a set of names) and
    ``declared`` (a dict of the engine's declared attributes). Use as a context manager or call
    :meth:`close`.
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
        if name is not None and not isinstance(name, str):
            raise PecletArgumentError("name", "a string or None", name)
        self.name = name or os.path.basename(str(cmd[-1]))
        self._proc = None
        try:
            self._proc = subprocess.Popen([os.fspath(c) for c in cmd], stdin=subprocess.PIPE,
                                          stdout=subprocess.PIPE, stderr=None,
                                          env=self.child_env(env), cwd=cwd, bufsize=0)
        except OSError as exc:
            raise PecletArgumentError("cmd", "a command that can be started", cmd,
                                      str(exc)) from None
        out = self.call("methods")
        self.methods = set(str(m) for m in out[0].reshape(-1) if str(m))
        self.declared = json.loads(str(out[1])) if len(out) > 1 else {}

    def child_env(self, env):
        """The environment the child starts with: ``env`` added to this process's (None:
        this process's)."""
        return dict(os.environ, **(env or {}))

    def call(self, method, *args):
        """The child's answer (a list of arrays) to ``method`` with ``args``."""
        if self._proc is None:
            raise RuntimeError(f"backend {self.name!r} is closed")
        what = (f"backend {self.name!r} did not answer {method!r} within {self.timeout:g} s "
                f"({self.timeout_label}); the child was killed")
        pipe = TimedPipe(self._proc, time.monotonic() + self.timeout, what)
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
            pipe = TimedPipe(self._proc, time.monotonic() + CLOSE_GRACE, "close")
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


# ---------------------------------------------------------------------------- in-process deadline
class DeadlineBackend:
    """An engine running in this process whose every call has a deadline.

    Attributes of ``backend`` read through unchanged (``hasattr`` stays truthful); a callable
    attribute is returned as a function that runs the call in a daemon worker thread and waits
    at most ``deadline`` seconds for it. A call that does not return in time raises
    ``TimeoutError`` naming the engine, the call and the deadline; from then on every call
    raises at once with the same message (the engine may still be busy in the abandoned
    thread, and a certificate must not wait on it again). A daemon thread never keeps the
    interpreter alive at exit. ``close`` is called directly (no deadline: cleanup).

    ``option`` names where the deadline was set (shown in the message). ``factory`` (a
    ``"module:factory"`` spec that makes the same engine, e.g. in a fresh process; default the
    engine's own ``factory`` attribute, if any) is kept for the certificates that need one.
    """

    def __init__(self, backend, deadline=DEFAULT_DEADLINE, option="--peclet-deadline",
                 factory=None):
        self.deadline = check_float("deadline", deadline, 0.0, math.inf, lo_open=True)
        self.backend = backend
        self.option = option
        self.factory = factory or getattr(backend, "factory", None)
        self.timed_out = None  # the message of the first call that missed its deadline
        self.worker = None     # the queue of the worker thread, started on the first call

    def __getattr__(self, item):
        if item in ("backend", "deadline", "option", "timed_out", "worker", "factory"):
            raise AttributeError(item)  # not set yet (during __init__ or unpickling)
        value = getattr(self.backend, item)
        if item == "close" or not callable(value) or isinstance(value, type):
            return value
        return lambda *args, **kwargs: self.call(item, value, args, kwargs)

    @property
    def name(self) -> str:
        return backend_name(self.backend)

    def call(self, method, function, args=(), kwargs=None):
        """``function(*args, **kwargs)`` (the engine's ``method``) within the deadline, on the
        one worker thread of this engine (an engine sees one calling thread, as it would
        without a deadline: Numba's thread count, for one, is set per thread)."""
        if self.timed_out is not None:
            raise TimeoutError(f"{self.timed_out} (an earlier call; the engine is not called "
                               "again)")
        if self.worker is None:
            self.worker = queue.SimpleQueue()
            threading.Thread(target=_serve_calls, args=(self.worker,), daemon=True,
                             name=f"peclet deadline: {self.name}").start()
        box, done = {}, threading.Event()
        self.worker.put((function, args, kwargs or {}, box, done))
        if not done.wait(self.deadline):
            self.timed_out = (f"backend {self.name!r} did not return from {method}() within "
                              f"its deadline of {self.deadline:g} s (set with {self.option})")
            raise TimeoutError(self.timed_out)
        if "error" in box:
            raise box["error"]
        return box["value"]

    def __repr__(self):
        return f"DeadlineBackend({self.backend!r}, deadline={self.deadline:g})"


def _serve_calls(calls):
    """The worker thread of a :class:`DeadlineBackend`: run each queued call, hand over its
    value or exception."""
    while True:
        function, args, kwargs, box, done = calls.get()
        try:
            box["value"] = function(*args, **kwargs)
        except BaseException as exc:  # handed to the caller's thread
            box["error"] = exc
        finally:
            done.set()


def with_deadline(backend, deadline=DEFAULT_DEADLINE, option="--peclet-deadline",
                  factory=None):
    """``backend`` behind a :class:`DeadlineBackend` of ``deadline`` seconds (and ``factory``),
    unless it keeps its own (a subprocess backend: ``own_deadline = True``, its children time
    out)."""
    if getattr(backend, "own_deadline", False) or isinstance(backend, DeadlineBackend):
        return backend
    return DeadlineBackend(backend, deadline, option, factory)
