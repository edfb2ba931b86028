"""The wire protocol between a certifier and an engine in a child process (stdlib + numpy
only): numpy-array message framing, and the child's request loop for every family.

This module is deliberately free of any ``peclet`` import, so a child process in another
interpreter or virtual environment (one whose ``peclet`` is a different engine) can load it by
file path (with :mod:`peclet_verify.scenario`, which it needs for DEM runs) and serve its
engine. A message is an 8-byte little-endian count of arrays followed by, per array, an
8-byte length and the bytes ``np.save`` writes (``allow_pickle=False``).

Requests: ``[method name (str array), *args]``. Replies: ``["ok", *results]`` or
``["error", message]``. Methods:

- ``methods`` -> ``[names, declared JSON]``: what the child serves, and the engines' declared
  attributes (a DEM engine's ``thread_counts``, ``thread_determinism``; a mass engine's
  ``resolutions``, ``order``, ``constant``, ``floor``; their names);
- geometry: ``evaluate(node_ints, node_reals, root, points) -> phi``, ``evaluate_grad(...) ->
  (phi, grad)``, ``bound(node_ints, node_reals, root) -> (centre, radius, certified)``;
- dem: ``run(scenario JSON, threads) -> [names, *arrays]`` (the recorded trajectory);
- mass: ``mass_properties(node_ints, node_reals, root, lo, hi, resolution) -> [volume, com,
  inertia, claimed]`` (``claimed``: ``[volume_error, moment_error]``, NaN where not claimed);
- impact: ``impact(case JSON) -> [names, *arrays]`` (the answer of
  :class:`peclet_verify.impact.backend.ImpactBackend`; its ``model`` and ``capabilities`` are
  declared with ``methods``);
- ``close``.
"""
from __future__ import annotations

import io
import json
import struct
import sys
import traceback

import numpy as np

if __package__:
    from .impact.cases import Impact
    from .scenario import Scenario
else:  # loaded by file path in a child: its folder is on sys.path
    from impact.cases import Impact
    from scenario import Scenario

#: The geometry methods a child may serve.
METHODS = ("evaluate", "evaluate_grad", "bound")


def write_message(stream, arrays) -> None:
    """Write ``arrays`` (each converted with ``np.asarray``) as one framed message."""
    chunks = []
    for a in arrays:
        buf = io.BytesIO()
        np.save(buf, np.asarray(a), allow_pickle=False)
        data = buf.getvalue()
        chunks.append(struct.pack("<Q", len(data)) + data)
    stream.write(struct.pack("<Q", len(chunks)) + b"".join(chunks))
    stream.flush()


def _read_exact(stream, n):
    data = stream.read(n)
    if data is None or len(data) != n:
        raise EOFError(f"pipe closed: wanted {n} bytes, got {0 if data is None else len(data)}")
    return data


def read_message(stream) -> list:
    """Read one framed message; returns the list of arrays."""
    (count,) = struct.unpack("<Q", _read_exact(stream, 8))
    out = []
    for _ in range(count):
        (size,) = struct.unpack("<Q", _read_exact(stream, 8))
        out.append(np.load(io.BytesIO(_read_exact(stream, size)), allow_pickle=False))
    return out


def declared(geometry=None, dem=None, mass=None, impact=None) -> dict:
    """The attributes the engines declare, as sent with ``methods``."""
    decl = {}
    if geometry is not None:
        decl["geometry_name"] = str(getattr(geometry, "name", type(geometry).__name__))
    if dem is not None:
        decl["thread_counts"] = list(getattr(dem, "thread_counts", (1, 2)))
        decl["thread_determinism"] = bool(getattr(dem, "thread_determinism", True))
        decl["dem_name"] = str(getattr(dem, "name", type(dem).__name__))
    if mass is not None:
        decl["resolutions"] = [float(r) for r in mass.resolutions]
        decl["order"] = float(mass.order)
        for key in ("constant", "floor"):
            c = getattr(mass, key, None)
            decl[key] = None if c is None else float(c)
        decl["mass_name"] = str(getattr(mass, "name", type(mass).__name__))
    if impact is not None:
        decl["impact_model"] = dict(impact.model)
        decl["impact_capabilities"] = sorted(impact.capabilities)
        decl["impact_name"] = str(getattr(impact, "name", type(impact).__name__))
    return decl


def answer(msg, geometry=None, dem=None, mass=None, impact=None) -> list:
    """The reply arrays (after ``"ok"``) to request ``msg``; raises for an unknown method."""
    method = str(msg[0])
    if method == "methods":
        names = [m for m in METHODS if geometry is not None and hasattr(geometry, m)]
        names += [n for n, o in (("run", dem), ("mass_properties", mass), ("impact", impact))
                  if o is not None]
        return [np.array(names or [""]),
                np.array(json.dumps(declared(geometry, dem, mass, impact)))]
    if method in METHODS and geometry is not None and hasattr(geometry, method):
        ni, nr, root = msg[1], msg[2], int(msg[3])
        args = (ni, nr, root) + ((msg[4],) if method != "bound" else ())
        res = getattr(geometry, method)(*args)
        return [np.asarray(r) for r in (list(res) if isinstance(res, tuple) else [res])]
    if method == "run" and dem is not None:
        traj = dem.run(Scenario.from_json(str(msg[1])), int(msg[2]))
        names = sorted(traj)
        return [np.array(names)] + [np.asarray(traj[k]) for k in names]
    if method == "mass_properties" and mass is not None:
        ni, nr, root, lo, hi, res = msg[1], msg[2], int(msg[3]), msg[4], msg[5], float(msg[6])
        ans = mass.mass_properties(ni, nr, root, lo, hi, res)
        claimed = np.full(2, np.nan)
        if len(ans) > 3 and ans[3] is not None:
            c = ans[3]
            if isinstance(c, dict):
                claimed[:] = [c.get("volume", np.nan), c.get("inertia", np.nan)]
            else:
                claimed[0] = float(c)
        return [np.asarray(ans[0], float), np.asarray(ans[1], float),
                np.asarray(ans[2], float), claimed]
    if method == "impact" and impact is not None:
        ans = impact.impact(Impact.from_json(str(msg[1])))
        names = sorted(ans)
        return [np.array(names)] + [np.asarray(ans[k], float) for k in names]
    raise ValueError(f"unknown method {method!r}")


def serve(geometry=None, dem=None, mass=None, stdin=None, stdout=None, impact=None) -> None:
    """Answer requests until EOF or ``close``: ``geometry`` has ``evaluate`` (optionally
    ``evaluate_grad``, ``bound``); ``dem`` has ``run(scenario, threads) -> trajectory dict``;
    ``mass`` has ``mass_properties(ni, nr, root, lo, hi, resolution)`` and declares
    ``resolutions`` and ``order``; ``impact`` has ``impact(case)``, ``model`` and
    ``capabilities``. Anything the engines print goes to stderr, so it cannot
    corrupt the stream; an engine's exception is sent to the parent, which raises it there."""
    stdin = sys.stdin.buffer if stdin is None else stdin
    stdout = sys.stdout.buffer if stdout is None else stdout
    sys.stdout = sys.stderr
    while True:
        try:
            msg = read_message(stdin)
        except EOFError:
            return
        if str(msg[0]) == "close":
            write_message(stdout, ["ok"])
            return
        try:
            reply = answer(msg, geometry, dem, mass, impact)
        except Exception:  # reported to the parent, which raises it there
            write_message(stdout, ["error", traceback.format_exc()])
        else:
            write_message(stdout, ["ok"] + reply)
