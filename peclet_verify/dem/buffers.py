"""Contact-buffer growth of peclet's own engine (:func:`buffer_growth`): the contacts of a
scene shape found under every contact capacity equal those at ample capacity and the
brute-force reference (:func:`peclet_verify.reference.contacts.brute_force_contacts`), in a
child process with ``NUMBA_BOUNDSCHECK=1``. Any DEM backend's buffer growth is
:func:`peclet_verify.dem.properties.dem_buffer_growth`.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np

from .. import registry as REG
from ..geometry.recipes import TreeRecipe
from ..geometry.strategies import surface_points
from ..reference.contacts import brute_force_contacts
from ..search import PropertyResult, encode_recipe, example_rng, make_result, unavailable

__all__ = ["buffer_growth", "buffer_growth_in_process", "DemEngine"]


_BUFFER_CHILD = r"""
import json, sys
import numpy as np
from peclet_verify.dem.buffers import buffer_growth_in_process
args = json.loads(sys.stdin.read())
print(json.dumps(buffer_growth_in_process(**args)))
"""


def buffer_growth(recipe: TreeRecipe, capacities, state, engine: str = "reference",
                  n_probes: int = 64, timeout: float = 600.0) -> PropertyResult:
    """Contacts found under every contact capacity in ``capacities`` (applied in order with
    ``set_contact_capacity``) equal the contacts at ample capacity, and the touching pairs
    equal the brute-force reference (:func:`brute_force_contacts`); nothing is written out of
    bounds. Runs in a subprocess with ``NUMBA_BOUNDSCHECK=1`` (read at import), so an
    out-of-bounds write is an IndexError there rather than silent corruption.

    ``engine`` is ``"reference"`` (peclet.dem.Simulation) or ``"module:factory"`` with
    ``factory(node_ints, node_reals, root, probes, radius, state) -> engine`` exposing
    ``set_contact_capacity(n)`` and ``detect_contacts()``. Figure: number of contact sets
    that differ from the reference.
    """
    b, root, ni, nr = encode_recipe(recipe)
    c, r, _ = b.node_bound(root)
    rng = example_rng("probes", ni.tobytes(), nr.tobytes())
    probes = surface_points(b, root, c + rng.uniform(-r, r, (n_probes, 3)), iterations=12)
    args = dict(node_ints=ni.tolist(), node_reals=nr.tolist(), root=int(root),
                probes=probes.tolist(), radius=float(np.max(np.linalg.norm(probes, axis=1))),
                positions=np.asarray(state.positions).tolist(),
                quaternions=np.asarray(state.quaternions).tolist(),
                capacities=[int(x) for x in capacities], engine=engine)
    env = dict(os.environ, NUMBA_BOUNDSCHECK="1")
    proc = subprocess.run([sys.executable, "-c", _BUFFER_CHILD], input=json.dumps(args),
                          capture_output=True, text=True, env=env, timeout=timeout)
    name = "buffer_growth"
    fig = REG.figure(name)
    if proc.returncode != 0 or not proc.stdout.strip():
        return make_result(name, False, float("inf"), fig, "max",
                       f"child crashed (exit {proc.returncode}):\n{proc.stderr[-2000:]}")
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    if out.get("unavailable"):
        return unavailable(name, out["unavailable"])
    return make_result(name, out["ok"], out["differing"], fig, "max",
                   out["text"], reference_pairs=out["reference_contacts"],
                   engine_contacts=out.get("engine_contacts"))


class DemEngine:
    """peclet.dem.Simulation set up with one scene shape at the given state."""

    def __init__(self, ni, nr, root, probes, radius, positions, quaternions):
        from peclet.dem import Simulation
        n = len(positions)
        self.sim = Simulation(n)
        lo = np.min(positions, axis=0) - 4 * radius
        hi = np.max(positions, axis=0) + 4 * radius
        self.sim.set_domain(tuple(lo), tuple(hi))
        shape = self.sim.add_scene_shape(ni, nr, root, probes, radius)
        self.sim.set_positions(positions)
        self.sim.set_shape_ids(np.full(n, shape, np.int32))
        self.sim.set_quaternions(quaternions)

    def set_contact_capacity(self, n):
        self.sim.set_contact_capacity(n)

    def detect_contacts(self):
        return self.sim.detect_contacts()


def _contact_rows(contacts):
    """Normalise an engine's contacts to sorted rows (a, b, point[3], normal[3], depth
    [, feature])."""
    def col(key):
        v = contacts[key] if isinstance(contacts, dict) else getattr(contacts, key)
        return np.asarray(v, dtype=np.float64)
    a, b = col("body_a"), col("body_b")
    cols = [a, b, col("point").reshape(len(a), 3), col("normal").reshape(len(a), 3),
            col("depth")]
    has_feature = "feature" in contacts if isinstance(contacts, dict) else \
        hasattr(contacts, "feature")
    if has_feature:
        cols.append(col("feature"))
    rows = np.column_stack(cols) if len(a) else np.zeros((0, 9 + has_feature))
    order = np.lexsort(rows.T[::-1]) if len(rows) else np.zeros(0, int)
    return rows[order]


def buffer_growth_in_process(node_ints, node_reals, root, probes, radius, positions,
                             quaternions, capacities, engine):
    """The buffer-growth check, in this process (the child of :func:`buffer_growth` runs it):
    a JSON-able dict with ``ok``, ``differing``, ``text`` and the contact counts, or
    ``unavailable``."""
    ni = np.asarray(node_ints, np.int32)
    nr = np.asarray(node_reals, np.float64)
    probes = np.asarray(probes)
    pos = np.asarray(positions, float)
    quat = np.asarray(quaternions, float)
    try:
        if engine == "reference":
            make = DemEngine
        else:
            mod, attr = engine.split(":")
            make = getattr(__import__(mod, fromlist=[attr]), attr)
        eng = make(ni, nr, root, probes, radius, pos, quat)
        eng.set_contact_capacity
        eng.detect_contacts
    except (ImportError, AttributeError, NotImplementedError) as exc:
        return {"unavailable": f"engine {engine!r} not available: {type(exc).__name__}: {exc}"}
    from peclet.core.geom import SceneBuilder
    ref = {tuple(sorted(c[:2])) for c in
           brute_force_contacts(SceneBuilder.decode(ni, nr), root, probes, pos, quat)}
    def detect(cap):
        eng.set_contact_capacity(int(cap))
        return _contact_rows(eng.detect_contacts())

    ample_cap = max(4 * len(probes) * len(pos) * max(len(pos) - 1, 1), 16)
    differing, text = 0, ""
    try:
        ample = detect(ample_cap)
    except IndexError as exc:
        return {"ok": False, "differing": 1, "reference_contacts": len(ref),
                "text": f"out-of-bounds write at ample capacity {ample_cap} "
                        f"(NUMBA_BOUNDSCHECK=1): {exc}"}
    # speculative contacts (depth <= 0: still apart) are not penetrations
    got_pairs = {tuple(sorted((int(x), int(y)))) for x, y in ample[ample[:, 8] > 0, :2]}
    if got_pairs != ref:
        differing += 1
        text += (f"at ample capacity the touching pairs {sorted(got_pairs)} differ from the "
                 f"brute-force reference {sorted(ref)}\n")
    for cap in capacities:
        try:
            rows = detect(cap)
        except IndexError as exc:
            return {"ok": False, "differing": differing + 1, "reference_contacts": len(ref),
                    "text": text + f"out-of-bounds write at capacity {cap} (NUMBA_BOUNDSCHECK=1)"
                                   f": {exc}"}
        if rows.shape != ample.shape or not np.array_equal(rows, ample):
            differing += 1
            text += (f"capacity {cap}: {len(rows)} contacts, at ample capacity {len(ample)}"
                     " (contacts lost or changed)\n")
    return {"ok": differing == 0, "differing": differing, "text": text,
            "reference_contacts": len(ref), "engine_contacts": int(len(ample))}
