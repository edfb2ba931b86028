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
from .spec import PackSpec, ensemble_manifest

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
    naming ``name``. A ``distributed.Client``: used as is (not closed). A cluster object (has
    ``scheduler_address``): a client on it. On an existing cluster each task uses
    ``threads_per_worker`` Numba threads (default 1: size the workers one per core).
    """
    from distributed import Client

    cores = machine_cores()
    if threads_per_worker is not None:
        threads_per_worker = check_int("threads_per_worker", threads_per_worker, 1, cores
                                       if scheduler is None else 4096)
    if n_workers is not None:
        n_workers = check_int("n_workers", n_workers, 1, 4096)
    connect_timeout = check_float("connect_timeout", connect_timeout, 0.0, 600.0, lo_open=True)
    if scheduler is None:
        scheduler = os.environ.get("DASK_SCHEDULER_ADDRESS") or None
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
    try:
        client = Client(scheduler, timeout=connect_timeout, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        detail = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise PecletArgumentError(name, what, scheduler,
                                  f"unreachable within {connect_timeout:g} s: {detail}") from None
    try:
        yield client, threads
    finally:
        client.close()


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
