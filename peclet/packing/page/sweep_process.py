"""Step 6's wall-thickness sweep in a child process at a low priority, beside the pour.

The sweep (:func:`peclet.packing.analysis.geometry.sweep_fractions`: six quadratures of the ring at
other wall thicknesses, about 10 s of two cores) needs no pack, and the pour, the analysis and
the figures that follow the element's measurement leave a core partly idle (the pour's step is
not all parallel; the analysis and figures are mostly one thread). :class:`SweepProcess` runs
the sweep in a child in Linux's idle scheduling class (``SCHED_IDLE``; elsewhere at ``nice``
+19), so that it takes only what nothing else wants and yields at once to everything else:
the pour's ms/step is a reported figure, and on a cold first run the DEM kernels compiling in
other children gate the pour. (At ``nice`` +10 the child still slowed the pour's step by a
quarter: a pour thread woken for a parallel region waited for it. In the idle class, the page's
pour at 2 threads with a sweep child beside it against alone, three interleaved pairs: 1.84,
2.26, 2.18 against 1.87, 1.80, 2.14 ms/step, a difference inside this machine's noise; stopping
the child during the pour cost the warm run 5 s and is not done. ``bench_vs_bullet`` times the
pour alone.) On a cold Numba cache the child is started only
once the quadrature's kernels are compiled (by the element's measurement), so that it loads
them instead of compiling them a second time.

The child computes exactly what the run would (the same function, the same arguments, the
same bits at any thread count); its rows come back as JSON, whose floats round-trip exactly.
If it fails, :meth:`SweepProcess.rows` computes the sweep in this process instead, which
raises the error, if any, where the user sees it.

The sweep depends on its thicknesses, ``n`` and ``tol`` and on peclet's code, not on the run
(ring count, seed, threads), so its rows are kept in the results cache
(:mod:`peclet.core.results_cache`, keyed by the code and the libraries): a later run of the
page reads them, bit for bit, and starts no child (the warm page run: 19 s -> 12 s on 2 cores,
the time it waited for the sweep). ``PECLET_CACHE_DIR=off`` computes it every time.
"""
from __future__ import annotations

import json
import subprocess
import sys

from peclet.core import results_cache

__all__ = ["SweepProcess", "NICE"]

#: The child's niceness increment where the idle scheduling class is not available (see
#: :class:`SweepProcess`).
NICE = 19

# the results cache's name for these rows, and the fields of a row
_CACHE_KIND = "pall_ring_sweep"
_ROW_KEYS = {"t", "t_over_d", "s", "s_err"}

_CHILD = """
import json, os, sys
try:
    os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
except (AttributeError, OSError):
    try:
        os.nice({nice})
    except (AttributeError, OSError):
        pass
import numba
from peclet.packing.analysis.geometry import sweep_fractions
args = json.loads(sys.argv[1])
if args["threads"] is not None:
    numba.set_num_threads(args["threads"])
rows = sweep_fractions(args["thicknesses"], n=args["n"], tol=args["tol"])
sys.stdout.write(json.dumps(rows))
"""


class SweepProcess:
    """``sweep_fractions(thicknesses, n=n, tol=tol)`` computed in a low-priority child.

    thicknesses: wall thicknesses (D); n, tol: the quadrature's resolution and tolerance;
    threads: the child's Numba thread count (None: Numba's default); use_cache: read and keep
    the rows in the results cache. Nothing is started for an empty list, nor when the cache
    holds the rows (``from_cache`` True). :meth:`rows` waits for the child and returns its rows
    (if no child could be started, or it failed, it computes them here) and keeps them."""

    def __init__(self, thicknesses, n, tol, threads=None, use_cache=True):
        self.args = dict(thicknesses=[float(t) for t in thicknesses], n=int(n),
                         tol=float(tol), threads=None if threads is None else int(threads))
        self.child = None
        self._rows = None
        self.use_cache = bool(use_cache)
        if self.use_cache and self.args["thicknesses"]:
            self._rows = results_cache.load(_CACHE_KIND, self._key(), self._valid)
        self.from_cache = self._rows is not None
        if self.args["thicknesses"] and not self.from_cache:
            try:
                self.child = subprocess.Popen(
                    [sys.executable, "-c", _CHILD.format(nice=NICE), json.dumps(self.args)],
                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            except OSError:
                pass                     # no child: rows() computes the sweep here

    def rows(self):
        """The sweep's rows (a list of dicts, as :func:`sweep_fractions` returns them)."""
        if self._rows is None:
            self._rows = self._collect()
            if self.use_cache and self._rows:
                results_cache.store(_CACHE_KIND, self._key(), self._rows)
        return self._rows

    def _key(self):
        # what the rows depend on (the thread count changes no bit)
        a = self.args
        return dict(thicknesses=a["thicknesses"], n=a["n"], tol=a["tol"])

    def _valid(self, rows):
        # a kept entry holds one row per thickness, in order, with every field a float
        return (isinstance(rows, list) and len(rows) == len(self.args["thicknesses"])
                and all(isinstance(r, dict) and set(r) == _ROW_KEYS
                        and all(isinstance(r[k], float) for k in _ROW_KEYS)
                        and r["t"] == t for r, t in zip(rows, self.args["thicknesses"])))

    def stop(self):
        """Kill the child if it is still running (a run that fails before Step 6)."""
        if self.child is not None and self.child.poll() is None:
            self.child.kill()
            self.child.communicate()

    def _collect(self):
        from ..analysis.geometry import sweep_fractions

        a = self.args
        if not a["thicknesses"]:
            return []
        if self.child is not None:
            out, _ = self.child.communicate()
            if self.child.returncode == 0:
                try:
                    return json.loads(out)
                except ValueError:
                    pass
        # no child, or it failed: the sweep here, where an error reaches the user
        return sweep_fractions(a["thicknesses"], n=a["n"], tol=a["tol"])
