"""Run many realizations as Dask tasks: :func:`run`.

Each :class:`~peclet.ensemble.spec.PackSpec` is one ``distributed`` task (``Client.submit``,
collected with ``as_completed``; the scheduling is Dask's). Default cluster: an embedded
``LocalCluster`` of worker processes sized to the machine (workers x Numba threads = cores),
started and closed by the call. An existing cluster: ``scheduler="tcp://HOST:8786"``, the
environment's ``DASK_SCHEDULER_ADDRESS``, a ``distributed.Client`` or a cluster object
(``dask_jobqueue.SLURMCluster``, ``dask_kubernetes`` ...).

Results travel back to this process, which writes each one to ``OUT/<spec-id>/`` the moment it
arrives (ledger.Ledger), so workers need no shared filesystem and a lost worker, a crash or
Ctrl-C loses only the realizations in flight. A worker lost mid-task: the scheduler reruns its
task elsewhere (up to ``distributed.scheduler.allowed-failures`` times, default 3); a task that
raises is retried ``retries`` times.
"""
from __future__ import annotations

import contextlib
import importlib.util
import logging
import os
import sys

from peclet.core.validation import PecletArgumentError, check_bool, check_int, check_float

from .ledger import Ledger
from .realize import FIGURES, realize
from .spec import PackSpec, element_params, ensemble_manifest

__all__ = ["run", "connect", "open_ledger", "machine_cores", "EnsembleError"]


class EnsembleError(RuntimeError):
    """Some realizations failed (after their retries); the others are in OUT.
    ``failures`` maps spec id -> the error text."""

    def __init__(self, failures):
        self.failures = dict(failures)
        first = next(iter(self.failures.items()))
        super().__init__(f"{len(self.failures)} realization(s) failed, e.g. {first[0]}: "
                         f"{first[1]}")


def machine_cores():
    """Cores this process may use (the affinity mask where the OS has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # macOS, Windows
        return os.cpu_count() or 1


def open_ledger(specs, out, swept=None, name="out"):
    """The :class:`Ledger` of ``specs`` in ``out`` (checks ``out``; PecletArgumentError naming
    ``name`` if it is not a writable directory empty or holding this same ensemble)."""
    return Ledger(out, ensemble_manifest(_check_specs(specs), swept), name=name)


def _check_specs(specs):
    if isinstance(specs, PackSpec):
        specs = [specs]
    specs = list(specs) if isinstance(specs, (list, tuple)) else specs
    if not isinstance(specs, list) or not specs \
            or not all(isinstance(s, PackSpec) for s in specs):
        raise PecletArgumentError("specs", "a non-empty list of PackSpec", specs)
    ids = [s.id for s in specs]
    if len(set(ids)) != len(ids):
        raise PecletArgumentError("specs", "distinct specs", len(ids),
                                  f"{len(ids) - len(set(ids))} given twice")
    return specs


@contextlib.contextmanager
def connect(scheduler=None, n_workers=None, threads_per_worker=None, name="scheduler",
            connect_timeout=3.0):
    """Context manager yielding ``(client, numba_threads_per_task)``.

    scheduler None (and no DASK_SCHEDULER_ADDRESS): a LocalCluster of ``n_workers`` processes
    (default cores // threads_per_worker), each running one task at a time with
    ``threads_per_worker`` Numba threads (default 1), closed on exit. A string: the address of
    a running scheduler, reached within ``connect_timeout`` seconds or PecletArgumentError
    naming ``name`` (or DASK_SCHEDULER_ADDRESS when the address came from it). The bound holds
    end to end: a Dask handshake (``distributed.comm.connect``) is tried first under that
    deadline, so an address that accepts and says nothing, or says something that is not
    Dask, fails within ``connect_timeout`` (plus a second) instead of blocking; then the
    Client is made under the same deadline. A ``distributed.Client``: used as is (not
    closed). A cluster object (has ``scheduler_address``): a client on it. On an existing
    cluster each task uses ``threads_per_worker`` Numba threads (default 1: size the workers
    one per core).
    """
    from distributed import Client

    cores = machine_cores()
    if threads_per_worker is not None:
        threads_per_worker = check_int("threads_per_worker", threads_per_worker, 1, cores
                                       if scheduler is None else 4096)
    if n_workers is not None:
        n_workers = check_int("n_workers", n_workers, 1, 4096)
    connect_timeout = check_float("connect_timeout", connect_timeout, 0.0, 600.0, lo_open=True)
    if scheduler is None and os.environ.get("DASK_SCHEDULER_ADDRESS"):
        scheduler = os.environ["DASK_SCHEDULER_ADDRESS"]
        name = "DASK_SCHEDULER_ADDRESS (environment variable)"
    threads = threads_per_worker or 1
    if scheduler is None:
        from distributed import LocalCluster

        workers = n_workers or max(1, cores // threads)
        # one Dask thread per worker: a worker runs one realization at a time, and that
        # realization uses `threads` Numba threads
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=":0",
                               silence_logs=logging.CRITICAL)
        try:
            client = Client(cluster, set_as_default=False)
            try:
                yield client, threads
            finally:
                client.close()
        finally:
            cluster.close()
        return
    if isinstance(scheduler, Client):
        yield scheduler, threads
        return
    if hasattr(scheduler, "scheduler_address"):
        scheduler = scheduler.scheduler_address
    what = "the address of a running Dask scheduler, e.g. tcp://HOST:8786"
    if not isinstance(scheduler, str) or "://" not in scheduler:
        raise PecletArgumentError(name, what, scheduler)
    client = _bounded_client(scheduler, connect_timeout, name, what)
    try:
        yield client, threads
    finally:
        client.close()


def _within(fn, seconds):
    """``fn()`` in a daemon thread: (True, result) or (False, the exception), or None if it
    has not returned after ``seconds`` (the thread is then left to finish on its own)."""
    import threading

    box = []

    def target():
        try:
            box.append((True, fn()))
        except BaseException as exc:  # noqa: BLE001 - reported to the caller
            box.append((False, exc))

    t = threading.Thread(target=target, name="peclet-dask-connect", daemon=True)
    t.start()
    t.join(seconds)
    return box[0] if box else None


def _handshake(address, timeout):
    """A Dask comm handshake with ``address`` under a hard deadline (its own event loop)."""
    import asyncio

    from distributed.comm import connect as comm_connect

    async def go():
        comm = await comm_connect(address, timeout=timeout)
        await comm.close()

    asyncio.run(asyncio.wait_for(go(), timeout))


def _bounded_client(address, timeout, name, what):
    """A ``distributed.Client`` on ``address``, or PecletArgumentError naming ``name`` within
    ``timeout`` seconds (+ 1 s) per stage: the handshake, then the client."""
    from distributed import Client

    def fail(detail):
        return PecletArgumentError(name, what, address,
                                   f"no Dask scheduler answered within {timeout:g} s: {detail}")

    got = _within(lambda: _handshake(address, timeout), timeout + 1.0)
    if got is None:
        raise fail("the connection stayed silent")
    if not got[0]:
        exc = got[1]
        if isinstance(exc, KeyboardInterrupt):
            raise exc
        text = str(exc).splitlines()[0] if str(exc) else ""
        if isinstance(exc, _timeout_types()):
            text = "the connection stayed silent"
        elif not isinstance(exc, (OSError, ValueError)):
            text = f"not a Dask scheduler ({type(exc).__name__}: {text[:120]})"
        raise fail(text or type(exc).__name__)
    abandoned = []

    def make():
        c = Client(address, timeout=timeout, set_as_default=False)
        if abandoned:          # the caller gave up: do not leave a client open
            c.close()
        return c

    got = _within(make, timeout + 1.0)
    if got is None:
        abandoned.append(True)
        raise fail("the scheduler did not complete the client's registration")
    if not got[0]:
        exc = got[1]
        if isinstance(exc, KeyboardInterrupt):
            raise exc
        raise fail(str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
    return got[1]


def _timeout_types():
    import asyncio

    return (asyncio.TimeoutError, TimeoutError)


def dashboard_link(client):
    """The dashboard URL if the scheduler serves one, else None."""
    try:
        if "dashboard" not in client.scheduler_info().get("services", {}):
            return None
        return client.dashboard_link
    except Exception:  # a link is a convenience; never fail a run for it
        return None


def _row(res, reused):
    """A flat table row: the spec's fields, the id, the figures of merit and their errors."""
    row = dict(res["spec"])
    # the element's given parameters (a swept thickness) as columns of their own
    for k, v in element_params(row["element"]).items():
        row.setdefault(k, v)
    row.update(id=res["id"], state_hash=res["state_hash"], reused=bool(reused))
    for f in FIGURES:
        row[f] = res[f]
    row.update(eps_se=res["eps_se"], f_env_se=res["f_env_se"], rattlers=res["rattlers"])
    return row


def run(specs, out, scheduler=None, threads_per_worker=None, progress=True, n_workers=None,
        retries=1, swept=None, log=None, arg_names=None):
    """Run every spec not already finished in ``out``; return one row (dict) per spec, in order.

    specs: PackSpec list (distinct); out: a directory path or a :class:`Ledger`; scheduler /
    n_workers / threads_per_worker: see :func:`connect` (``scheduler`` may also be a Client
    or cluster); progress: a tqdm bar on stderr; retries: reruns of a task that raised;
    swept: names of the swept parameters (for the manifest; default: those that vary);
    log: where the dashboard link goes (default stderr when ``progress``); arg_names: how the
    caller spells ``out`` / ``scheduler`` in error messages (the CLI: ``--out``...).

    Every argument is checked before a cluster starts. Rows carry the spec's fields, ``id``,
    ``state_hash``, ``eps``, ``eps_se``, ``f_env``, ``f_env_se``, ``z_mean``, ``rattlers`` and
    ``reused`` (True if read from ``out``). Raises :class:`EnsembleError` after the run if
    realizations failed (every other one is written).
    """
    specs = _check_specs(specs)
    progress = check_bool("progress", progress)
    retries = check_int("retries", retries, 0, 100)
    names = {"out": "out", "scheduler": "scheduler", **(arg_names or {})}
    ledger = out if isinstance(out, Ledger) else open_ledger(specs, out, swept, names["out"])
    if log is None:
        log = (lambda s: print(s, file=sys.stderr)) if progress else (lambda s: None)
    done = {s.id: ledger.load(s) for s in specs}
    rows = {i: _row(r, True) for i, r in done.items() if r is not None}
    todo = [s for s in specs if done[s.id] is None]
    failures = {}
    if todo:
        with connect(scheduler, n_workers, threads_per_worker, names["scheduler"]) \
                as (client, threads):
            ledger.prepare()
            link = dashboard_link(client)
            if link and scheduler is None and importlib.util.find_spec("bokeh") is None:
                link += " (its pages need bokeh >= 3.1: pip install bokeh)"
            log(f"dask: {len(todo)} realization(s) to run ({len(rows)} already in "
                f"{ledger.out}); dashboard: {link or 'not served'}")
            rows.update(_run_on(client, todo, threads, retries, ledger, progress, failures))
    if failures:
        raise EnsembleError(failures)
    return [rows[s.id] for s in specs]


def _run_on(client, todo, threads, retries, ledger, progress, failures):
    """Submit ``todo``, write each result as it completes; yield (id, row) pairs."""
    from distributed import as_completed
    from tqdm import tqdm

    by_key = {}
    futures = []
    for s in todo:
        f = client.submit(realize, s, threads, key=f"peclet-realize-{s.id}", pure=False,
                          retries=retries)
        by_key[f.key] = s
        futures.append(f)
    bar = tqdm(total=len(todo), desc="ensemble", unit="pack", disable=not progress,
               file=sys.stderr)
    try:
        for fut in as_completed(futures, loop=client.loop):
            spec = by_key[fut.key]
            try:
                res, pack = fut.result()
            except Exception as exc:  # a failed realization must not lose the others
                failures[spec.id] = f"{type(exc).__name__}: {exc}"
            else:
                ledger.write(spec, res, pack)
                yield spec.id, _row(res, False)
            finally:
                fut.release()
            bar.update(1)
    finally:
        bar.close()
        for f in futures:
            if not f.done():
                f.cancel()
