"""Certification properties as plain functions returning :class:`PropertyResult`.

Each property checks ONE input (a tree recipe, a state, a capacity sequence) and returns a
result with its measured figure; :func:`search` runs a property over a Hypothesis strategy,
keeps the worst figure and, on failure, the shrunk counterexample (a runnable snippet).
Nothing here needs pytest.

Conventions: phi < 0 inside (docs/architecture.md §2); "slack" of Equation 1 is
``phi(p) - (|p - c| - r)`` (must be >= 0 for a certified root); distances are in the tree's
length unit; relative errors are dimensionless.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import subprocess
import sys
import time
from contextlib import contextmanager, nullcontext
from dataclasses import asdict, dataclass, field
from typing import Callable, Optional

import numpy as np
from hypothesis import Phase, given, seed
from hypothesis import settings as hypothesis_settings

from .answers import ask, ask_bound
from .reference.contacts import brute_force_contacts
from .backends import ReferenceBackend, backend_name, check_backend
from .strategies import TreeRecipe, surface_points

__all__ = ["PropertyResult", "search", "set_profile", "active_settings", "profile_settings",
           "active_profile_name", "equation1", "sign_agreement", "distance_agreement",
           "quadrature_convergence", "closed_form", "determinism", "buffer_growth",
           "state_hash", "reference_measure", "reference_pour", "brute_force_contacts"]

PASSED, FAILED, UNAVAILABLE, NOT_APPLICABLE = "passed", "failed", "unavailable", "n/a"


@dataclass
class PropertyResult:
    """Outcome of a property. ``worst`` is the worst value of the figure ``worst_name`` seen
    (its direction is ``worse``: "min" or "max"); ``examples`` the number of inputs checked."""

    name: str
    passed: bool
    examples: int = 1
    worst: float = float("nan")
    worst_name: str = ""
    counterexample: str = ""
    status: str = PASSED
    worse: str = "max"
    details: dict = field(default_factory=dict)

    @property
    def verdict(self) -> str:
        return self.status

    def to_dict(self) -> dict:
        d = asdict(self)
        d["worst"] = None if not math.isfinite(self.worst) else float(self.worst)
        return d


def _result(name, ok, figure, figure_name, worse, text="", **details):
    return PropertyResult(name, bool(ok), 1, float(figure), figure_name,
                          "" if ok else text, PASSED if ok else FAILED, worse, details)


def _bad_answer(name, figure_name, worse, why) -> PropertyResult:
    """A failed certificate whose backend gave no usable answer (``why`` shows the answer);
    its figure is the worst possible (-inf for a "min" figure, +inf for a "max" one)."""
    return PropertyResult(name, False, 1, -math.inf if worse == "min" else math.inf, figure_name,
                          f"unusable answer from the engine under certification: {why}", FAILED,
                          worse, {"bad_answer": why})


def unavailable(name, why) -> PropertyResult:
    """A property that could not run (missing engine feature): neither passed nor failed."""
    return PropertyResult(name, False, 0, float("nan"), "", why, UNAVAILABLE)


def _encode(recipe: TreeRecipe):
    b, root = recipe.build()
    ni, nr, _, _ = b.encode()
    return b, root, ni, nr


def _rng(*keys):
    h = hashlib.sha256(repr(keys).encode()).digest()
    return np.random.default_rng(int.from_bytes(h[:8], "little"))


# ---------------------------------------------------------------------------- search
@contextmanager
def _fixed_constant_pool():
    """Make Hypothesis draw the same examples whatever modules the process has imported.

    Hypothesis (>= 6.131) mixes "local constants" into generation: literals scanned from every
    non-test module of the user's code found in ``sys.modules`` at draw time. Which modules are
    loaded depends on what ran before (a DEM certificate imports ``peclet.dem`` and its
    constants), so a derandomised search drew different examples alone and after other files.
    Inside this context the local pool is empty (Hypothesis's own global constants still
    apply) and the constants cache is cleared on entry and exit. It uses Hypothesis internals;
    on a version without them nothing needs fixing and this is a no-op.
    """
    try:
        from hypothesis.internal.conjecture import providers
        original = providers._get_local_constants
        cache = providers.CONSTANTS_CACHE.cache
        empty = providers.Constants()
    except (ImportError, AttributeError):
        yield
        return
    cache.clear()  # its entries were computed from the process's current pool
    providers._get_local_constants = lambda: empty
    try:
        yield
    finally:
        providers._get_local_constants = original
        cache.clear()


#: Called as ``progress(name, examples, max_examples, seconds)`` at every tenth of a long search
#: (see :func:`set_progress`); None: silent.
_progress: Optional[Callable] = None
#: Searches with fewer examples than this report no progress.
PROGRESS_MIN_EXAMPLES = 100


def set_progress(callback: Optional[Callable]) -> None:
    """Report the progress of long searches (``max_examples >= PROGRESS_MIN_EXAMPLES``) to
    ``callback(name, examples, max_examples, seconds)`` at every tenth of ``max_examples``;
    None turns it off. The pytest plugin points it at the terminal."""
    global _progress
    _progress = callback


#: The certification profile's settings (see :mod:`peclet_verify.profiles`), set by the pytest
#: plugin with :func:`set_profile`; None: Hypothesis's loaded default applies.
_profile = None
_profile_name: Optional[str] = None


def set_profile(settings_obj, name: Optional[str] = None) -> None:
    """Make ``settings_obj`` (a Hypothesis ``settings``) the one :func:`search` uses when it
    is given none; None restores Hypothesis's loaded default. Nothing global in Hypothesis is
    touched, so other Hypothesis tests in the process keep their own settings."""
    global _profile, _profile_name
    _profile, _profile_name = settings_obj, (name if settings_obj is not None else None)


def active_settings():
    """The settings :func:`search` uses by default: the certification profile if one is set,
    else Hypothesis's loaded default."""
    return _profile if _profile is not None else hypothesis_settings.default


def active_profile_name() -> Optional[str]:
    """Name of the profile set with :func:`set_profile` (None if none)."""
    return _profile_name


def profile_settings(**overrides):
    """The active certification settings with ``overrides`` (e.g. fewer ``max_examples`` for a
    certificate whose examples are expensive); build it inside the test, not at import."""
    return hypothesis_settings(active_settings(), **overrides)


def search(check: Callable, strategy, name: Optional[str] = None, settings=None,
           describe: Callable = repr) -> PropertyResult:
    """Run ``check(example) -> PropertyResult`` over ``strategy`` with Hypothesis.

    The active certification profile (:func:`active_settings`) applies unless ``settings``
    is given. On failure Hypothesis shrinks the input; the returned result carries the shrunk example (``describe(example)``)
    and its own counterexample text. Inputs for which the property does not apply (status
    "n/a") count as examples but never fail. An "unavailable" result stops the search.

    ``examples`` counts the inputs checked up to and including the first failure; the runs
    Hypothesis makes after it (shrinking, replay) are in ``details["runs_after_failure"]``.
    Under a derandomised profile (``derandomize=True``, e.g. ``ci``) the seed is a hash of
    ``name`` (else of ``check.__qualname__``) and the examples drawn do not depend on what else
    ran in the process: Hypothesis's pool of constants scanned from imported modules is
    replaced by an empty one during the search.
    """
    seen = {"n": 0, "applicable": 0, "worst": None, "last_fail": None, "unavailable": None,
            "first_fail_at": None, "calls": 0}
    effective = settings if settings is not None else active_settings()
    label = name or getattr(check, "__qualname__", "property")
    every = (effective.max_examples // 10
             if _progress is not None and effective.max_examples >= PROGRESS_MIN_EXAMPLES else 0)
    start = time.perf_counter()

    def run(example):
        res = check(example)
        if res.status == UNAVAILABLE:
            seen["unavailable"] = res
            return
        seen["calls"] += 1
        seen.setdefault("property", res.name)
        if every and seen["calls"] % every == 0 and seen["first_fail_at"] is None:
            _progress(label, seen["calls"], effective.max_examples, time.perf_counter() - start)
        before_failure = seen["first_fail_at"] is None
        seen["n"] += before_failure
        if res.status == NOT_APPLICABLE:
            return
        seen["applicable"] += before_failure
        w = seen["worst"]
        if math.isfinite(res.worst) and (w is None or not math.isfinite(w.worst)
                                         or (res.worst < w.worst if res.worse == "min"
                                             else res.worst > w.worst)):
            seen["worst"] = res
        if not res.passed:
            if seen["first_fail_at"] is None:
                seen["first_fail_at"] = seen["calls"]
            seen["last_fail"] = (example, res)
            raise AssertionError(f"{res.name} failed:\n{res.counterexample}")

    # no explain phase: it re-runs the failing input hundreds of times to annotate Hypothesis's
    # own report, which search never shows (the counterexample is describe(shrunk input))
    # every certificate gets its own example-database key (``run`` has the same source for all)
    run._hypothesis_internal_add_digest = label.encode()
    test = hypothesis_settings(effective, phases=[p for p in effective.phases
                                                  if p is not Phase.explain])(given(strategy)(run))
    pool = nullcontext()
    if effective.derandomize:
        # derandomised: the seed comes from the certificate's name (Hypothesis would hash the
        # source of ``run`` above, the same for every certificate and changed by any edit
        # here) and the examples must not depend on what the process imported before
        test = seed(int.from_bytes(hashlib.sha256(label.encode()).digest()[:8], "little"))(test)
        pool = _fixed_constant_pool()
    try:
        with pool:
            test()
        err = None
    except AssertionError as exc:
        err = exc
    if seen["unavailable"] is not None:
        return seen["unavailable"]
    worst = seen["worst"]
    base = PropertyResult(name or (worst.name if worst else "property"), err is None,
                          seen["n"], worst.worst if worst else float("nan"),
                          worst.worst_name if worst else "", "",
                          PASSED if err is None else FAILED,
                          worst.worse if worst else "max",
                          {"applicable": seen["applicable"]})
    if "property" in seen:
        base.details["property"] = seen["property"]
    if seen["first_fail_at"] is not None:
        base.details["runs_after_failure"] = seen["calls"] - seen["first_fail_at"]
    if seen["applicable"] == 0 and err is None:
        base.status = NOT_APPLICABLE
    if err is not None:
        example, res = seen["last_fail"] if seen["last_fail"] else (None, None)
        if res is not None:
            base.name = name or res.name
            base.worst, base.worst_name, base.worse = res.worst, res.worst_name, res.worse
            base.counterexample = (f"shrunk input:\n{describe(example)}\n\n{res.counterexample}")
            base.details.update(res.details)
        else:
            base.counterexample = str(err)
    return base


# ---------------------------------------------------------------------------- Equation 1
def _probe_outside(c, r, n, rng, max_factor=10.0):
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    # half the probes just outside the ball, half spread out to max_factor radii
    u = np.concatenate([rng.uniform(0, 0.05, n // 2), rng.uniform(0, max_factor, n - n // 2)])
    return c + d * (r * (1.0 + u) + 1e-9)[:, None]


def equation1(recipe: TreeRecipe, backend=None, n: int = 256, claimed_by: str = "backend",
              tol: float = 1e-9) -> PropertyResult:
    """Equation 1, ``phi(p) >= |p - c| - r``, at ``n`` points outside the root's ball.

    The ball and the ``certified`` claim come from ``backend.bound`` when the backend has one
    (``claimed_by="backend"``), else from the reference rule (docs/architecture.md §4). Applies
    only to trees claimed certified (status "n/a" otherwise). Figure: minimum slack
    (>= -tol * (1 + r) passes); the violation rate is in ``details``. An unusable answer from
    ``evaluate`` or ``bound`` (see :mod:`peclet_verify.answers`) fails, with the answer in the
    text.
    """
    backend = check_backend(backend or ReferenceBackend())
    b, root, ni, nr = _encode(recipe)
    name = "equation1"
    if claimed_by == "backend" and callable(getattr(backend, "bound", None)):
        claim, why = ask_bound(backend, ni, nr, root)
        if why:
            return _bad_answer(name, "min slack", "min", why)
        c, r, cert = claim
    else:
        c, r, cert = b.node_bound(root)
    c = np.asarray(c, float)
    if not cert or not math.isfinite(r):
        return PropertyResult(name, True, 1, float("nan"), "min slack", "", NOT_APPLICABLE, "min")
    p = _probe_outside(c, r, n, _rng("eq1", ni.tobytes(), nr.tobytes()))
    phi, why = ask(backend, "evaluate", ni, nr, root, p)
    if why:
        return _bad_answer(name, "min slack", "min", why)
    slack = phi - (np.linalg.norm(p - c, axis=1) - r)
    bad = slack < -tol * (1.0 + r)
    k = int(np.argmin(slack))
    text = (f"{backend_name(backend)} claims the root certified with ball c={c.tolist()}, "
            f"r={r!r}, but at p={p[k].tolist()} phi={float(phi[k])!r} < |p-c|-r="
            f"{float(phi[k] - slack[k])!r} (slack {slack[k]:.3e}); {int(bad.sum())}/{n} points violate")
    return _result(name, not bad.any(), slack.min(), "min slack", "min", text,
                   violation_rate=float(bad.mean()))


# ---------------------------------------------------------------------------- sign agreement
def _sign_points(b, root, n, rng):
    c, r, _ = b.node_bound(root)
    if not math.isfinite(r):
        c, r = np.zeros(3), 2.0
    raw = c + rng.uniform(-1.2, 1.2, (n, 3)) * r
    near = surface_points(b, root, raw[: n // 2], iterations=3)
    near += rng.normal(scale=1e-3 * r, size=near.shape)
    return np.concatenate([near, raw[n // 2:]]), r


def sign_agreement(recipe: TreeRecipe, other: Optional[TreeRecipe] = None, backend=None,
                   n: int = 256, band: float = 1e-9) -> PropertyResult:
    """Every way of evaluating the solid agrees on inside/outside at ``n`` probe points.

    Compared with the reference ``eval_root`` of ``recipe``: ``eval_root_grad``, ``bake`` (one
    lattice through the probes' first point per row is not possible, so a small lattice is
    baked and compared with ``eval_root`` at the lattice nodes), the scene query
    (``eval_scene``, pruned and brute, one instance at identity), ``decode(encode())``, the
    ``backend`` (and its ``evaluate_grad``) and, when given, a second recipe ``other`` for the
    same solid. Points with ``|phi| <= band * (1 + r)`` (on the surface) are skipped; at the
    others an answer of exactly 0 disagrees too. An unusable answer from the backend (see
    :mod:`peclet_verify.answers`: None, NaN/inf, wrong shape, raised) fails at once.
    Figure: the fraction of points whose sign disagrees.
    """
    backend = check_backend(backend or ReferenceBackend())
    b, root, ni, nr = _encode(recipe)
    rng = _rng("sign", ni.tobytes(), nr.tobytes())
    p, r = _sign_points(b, root, n, rng)
    ref = b.eval_root(root, p)
    views = {"eval_root_grad": b.eval_root_grad(root, p)[0],
             "decode(encode())": SceneBuilder_decode(ni, nr).eval_root(root, p)}
    methods = ["evaluate"] + (["evaluate_grad"] if callable(getattr(backend, "evaluate_grad",
                                                                     None)) else [])
    for method in methods:
        answer, why = ask(backend, method, ni, nr, root, p)
        if why:
            return _bad_answer("sign_agreement", "sign disagreement rate", "max", why)
        views[backend_name(backend) + ("" if method == "evaluate" else "." + method)] = \
            answer if method == "evaluate" else answer[0]
    if math.isfinite(r):
        sb = SceneBuilder_decode(ni, nr)
        sb.add_instance(root)
        views["eval_scene(pruned)"] = sb.eval_scene(p, method="pruned")
        views["eval_scene(brute)"] = sb.eval_scene(p, method="brute")
    if other is not None:
        ob, oroot = other.build()
        views["other recipe"] = ob.eval_root(oroot, p)
    keep = np.abs(ref) > band * (1.0 + (r if math.isfinite(r) else 1.0))
    worst_rate, text = 0.0, ""
    for label, phi in views.items():
        # a view answering 0 (on the surface) where the reference is clearly off it
        # disagrees too: an engine answering constant zero must not pass
        dis = keep & (np.sign(phi) != np.sign(ref))
        rate = float(dis.sum()) / max(int(keep.sum()), 1)
        if rate > worst_rate:
            k = int(np.argmax(dis))
            worst_rate = rate
            text = (f"{label} disagrees with eval_root on the sign at {int(dis.sum())}/"
                    f"{int(keep.sum())} points, e.g. p={p[k].tolist()}: eval_root={float(ref[k])!r}, "
                    f"{label}={float(phi[k])!r}")
    bake_rate, bake_text = _bake_check(b, root, rng)
    if bake_rate > worst_rate:
        worst_rate, text = bake_rate, bake_text
    return _result("sign_agreement", worst_rate == 0.0, worst_rate, "sign disagreement rate",
                   "max", text)


def SceneBuilder_decode(ni, nr):
    from peclet.core.geom import SceneBuilder
    return SceneBuilder.decode(ni, nr)


def _bake_check(b, root, rng, dims=(5, 4, 3)):
    c, r, _ = b.node_bound(root)
    if not math.isfinite(r):
        c, r = np.zeros(3), 2.0
    origin = c - r * rng.uniform(0.5, 1.0, 3)
    spacing = 2 * r * rng.uniform(0.2, 0.4, 3)
    baked = b.bake(root, origin, spacing, dims)
    i, j, k = np.meshgrid(*(np.arange(d) for d in dims), indexing="ij")
    idx = np.stack([i.ravel(order="F"), j.ravel(order="F"), k.ravel(order="F")], axis=1)
    pts = origin + idx * spacing
    ref = b.eval_root(root, pts)
    dis = np.sign(baked) != np.sign(ref)
    if not dis.any():
        return 0.0, ""
    m = int(np.argmax(dis))
    return float(dis.mean()), (f"bake disagrees with eval_root at lattice node {idx[m].tolist()} "
                               f"p={pts[m].tolist()}: bake={float(baked[m])!r} eval_root={float(ref[m])!r}")


# ---------------------------------------------------------------------------- distance
def distance_agreement(recipe: TreeRecipe, backend_a=None, backend_b=None, n: int = 256,
                       rtol: float = 1e-9) -> PropertyResult:
    """Two backends give the same phi within ``rtol * (1 + r)`` at ``n`` points in and around
    the root ball (r its radius). Figure: the largest absolute difference."""
    a = check_backend(backend_a or ReferenceBackend())
    bb = check_backend(backend_b or ReferenceBackend())
    b, root, ni, nr = _encode(recipe)
    p, r = _sign_points(b, root, n, _rng("dist", ni.tobytes(), nr.tobytes()))
    pa, why_a = ask(a, "evaluate", ni, nr, root, p)
    pb, why_b = ask(bb, "evaluate", ni, nr, root, p)
    if why_a or why_b:
        return _bad_answer("distance_agreement", "max |phi_a - phi_b|", "max", why_a or why_b)
    diff = np.abs(pa - pb)
    k = int(np.argmax(diff))
    tol = rtol * (1.0 + (r if math.isfinite(r) else 1.0))
    text = (f"{backend_name(a)} and {backend_name(bb)} differ by {diff[k]:.3e} (> {tol:.1e}) "
            f"at p={p[k].tolist()}: {float(pa[k])!r} vs {float(pb[k])!r}; {int((diff > tol).sum())}/{n} "
            "points differ")
    return _result("distance_agreement", diff.max() <= tol, diff.max(), "max |phi_a - phi_b|",
                   "max", text)


# ---------------------------------------------------------------------------- quadrature
def closed_form(recipe: TreeRecipe):
    """(volume, centre of mass (3,), principal moments (3,) ascending) of a one-leaf recipe at
    unit density, moved by the leaf's transform (rotation, scale s: volume s^3, moments s^5),
    from the leaf table's closed forms
    (:func:`peclet.core.geom.leaves.closed_form_mass_properties`); None if it has none."""
    from .mass_backends import closed_form_leaf
    leaf = closed_form_leaf(recipe)
    if leaf is None:
        return None
    exact, s, _, com = leaf
    principal = np.sort(np.linalg.eigvalsh(np.asarray(exact.inertia, float))) * s ** 5
    return exact.volume * s ** 3, com, principal


def reference_measure(builder, root, lo, hi, tol):
    """Mass properties by the reference engine's ``SceneBuilder.body_properties`` asked for
    relative accuracy ``tol`` (its refinement knob; n = 32: 8 top cells per axis): (volume, com,
    principal ascending). Raises AttributeError when the engine has no quadrature yet."""
    res = builder.body_properties(root, lo, hi, n=32, tol=tol)

    def get(key, *alt):
        for k in (key,) + alt:
            if isinstance(res, dict) and k in res:
                return res[k]
            if hasattr(res, k):
                return getattr(res, k)
        raise AttributeError(f"body_properties result has no {key!r}")
    return (float(get("volume")), np.asarray(get("com"), float),
            np.sort(np.asarray(get("principal"), float)))


def quadrature_convergence(recipe: TreeRecipe, measure: Optional[Callable] = None,
                           tols=(1e-3, 1e-4, 1e-5), rtol: float = 1e-4,
                           slack: float = 10.0) -> PropertyResult:
    """Quadrature of a one-leaf solid against its closed form, refined by its tolerance.

    ``measure(builder, root, lo, hi, tol) -> (volume, com, principal)`` (default: the
    reference engine, whose refinement knob is the requested relative accuracy). Passes when
    every level honours its request (relative volume error <= ``slack * tol``, or round-off
    1e-12) and the relative errors (volume, com / size, principal moments) at the finest level
    are <= ``rtol``. The observed order of the volume error against ``tol`` between the two
    finest levels is reported. Figure: the worst relative error at the finest level. Status
    "n/a" for leaves without a closed form here.
    """
    name = "quadrature_convergence"
    exact = closed_form(recipe)
    if exact is None:
        return PropertyResult(name, True, 1, float("nan"), "rel error", "", NOT_APPLICABLE)
    measure = measure or reference_measure
    b, root = recipe.build()
    c, r, _ = b.node_bound(root)
    lo, hi = c - 1.02 * r, c + 1.02 * r
    v0, com0, mom0 = exact
    size = v0 ** (1 / 3)
    errs = []
    try:
        for tol in tols:
            v, com, mom = measure(b, root, lo, hi, tol)
            e = {"volume": abs(v - v0) / v0,
                 "com": float(np.linalg.norm(np.asarray(com) - com0)) / size}
            if mom0 is not None:
                e["principal"] = float(np.max(np.abs(np.sort(mom) - mom0)) / np.max(mom0))
            errs.append(e)
    except (AttributeError, ImportError, NotImplementedError) as exc:
        return unavailable(name, f"quadrature not available: {exc}")
    fin = errs[-1]
    worst_key = max(fin, key=fin.get)
    ev = [e["volume"] for e in errs]
    order = (math.log(ev[-2] / ev[-1]) / math.log(tols[-2] / tols[-1])
             if ev[-1] > 1e-12 and ev[-2] > 0 else float("inf"))
    honoured = all(e <= max(slack * t, 1e-12) for e, t in zip(ev, tols))
    ok = fin[worst_key] <= rtol and honoured
    text = (f"relative errors by tol {list(tols)}: " +
            "; ".join(f"tol={t:g}: " + ", ".join(f"{k} {v:.2e}" for k, v in e.items())
                      for t, e in zip(tols, errs)) +
            f"; observed volume order in tol {order:.2f}; every level within {slack:g} x tol: "
            f"{honoured}; finest error <= {rtol}: {fin[worst_key] <= rtol}")
    return _result(name, ok, fin[worst_key], f"rel error ({worst_key}, tol={tols[-1]:g})",
                   "max", text, observed_order=order)


# ---------------------------------------------------------------------------- determinism
def state_hash(arrays) -> str:
    """sha256 of the bytes of a sequence (or dict, by sorted key) of arrays."""
    if isinstance(arrays, dict):
        arrays = [arrays[k] for k in sorted(arrays)]
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(str(a.dtype).encode() + str(a.shape).encode() + a.tobytes())
    return h.hexdigest()


def reference_pour(state, steps: int = 20):
    """A short pour of spheres (radius 0.25) from ``state`` on a floor with peclet.dem;
    returns the final (positions, quaternions, velocities, angular velocities)."""
    from peclet.dem import Simulation
    import numpy as _np
    n = state.n
    sim = Simulation(n)
    lo = state.positions.min(axis=0) - 1.0
    hi = state.positions.max(axis=0) + 1.0
    sim.set_domain(tuple(lo), tuple(hi))
    sim.set_gravity(0.0, -9.81, 0.0)
    sim.set_material_params(0.3, 0.0, 0.5)
    shape = sim.add_sphere_shape(0.25)
    sim.set_positions(state.positions)
    sim.set_shape_ids(_np.full(n, shape, _np.int32))
    sim.set_quaternions(state.quaternions)
    sim.set_velocities(state.velocities)
    sim.set_angular_velocities(state.angular_velocities)
    sim.set_inv_mass(_np.ones(n))
    sim.set_inv_inertia(_np.full((n, 3), 1.0 / (0.4 * 0.25 ** 2)))
    for _ in range(steps):
        sim.step(1e-3)
    return [_np.asarray(sim.get_positions()), _np.asarray(sim.get_quaternions()),
            _np.asarray(sim.get_velocities()), _np.asarray(sim.get_angular_velocities())]


def determinism(state, pour: Optional[Callable] = None, threads=(1, 2)) -> PropertyResult:
    """``pour(state)`` gives bitwise the same state twice at one thread and at every thread
    count in ``threads`` (numba.set_num_threads; counts above the pool size are dropped).
    Figure: the number of distinct state hashes (1 passes)."""
    import numba
    name = "determinism"
    pour = pour or reference_pour
    cap = numba.config.NUMBA_NUM_THREADS
    counts = [t for t in threads if 1 <= t <= cap]
    before = numba.get_num_threads()
    hashes = {}
    try:
        numba.set_num_threads(counts[0])
        runs = [(f"{counts[0]} thread(s), run {i + 1}", counts[0]) for i in range(2)]
        runs += [(f"{t} thread(s)", t) for t in counts[1:]]
        for label, t in runs:
            numba.set_num_threads(t)
            hashes[label] = state_hash(pour(state))
    except (ImportError, AttributeError, NotImplementedError) as exc:
        return unavailable(name, f"pour not available: {exc}")
    finally:
        numba.set_num_threads(before)
    distinct = len(set(hashes.values()))
    text = "state hashes differ: " + "; ".join(f"{k}: {v[:16]}" for k, v in hashes.items())
    return _result(name, distinct == 1, distinct, "distinct state hashes", "max", text,
                   hashes=hashes, thread_counts=counts)


# ---------------------------------------------------------------------------- buffer growth
_BUFFER_CHILD = r"""
import json, sys
import numpy as np
from peclet_verify.properties import _buffer_growth_inprocess
args = json.loads(sys.stdin.read())
print(json.dumps(_buffer_growth_inprocess(**args)))
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
    b, root, ni, nr = _encode(recipe)
    c, r, _ = b.node_bound(root)
    rng = _rng("probes", ni.tobytes(), nr.tobytes())
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
    if proc.returncode != 0 or not proc.stdout.strip():
        return _result(name, False, float("inf"), "differing contact sets", "max",
                       f"child crashed (exit {proc.returncode}):\n{proc.stderr[-2000:]}")
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    if out.get("unavailable"):
        return unavailable(name, out["unavailable"])
    return _result(name, out["ok"], out["differing"], "differing contact sets", "max",
                   out["text"], reference_pairs=out["reference_contacts"],
                   engine_contacts=out.get("engine_contacts"))


class _DemEngine:
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


def _buffer_growth_inprocess(node_ints, node_reals, root, probes, radius, positions,
                             quaternions, capacities, engine):
    ni = np.asarray(node_ints, np.int32)
    nr = np.asarray(node_reals, np.float64)
    probes = np.asarray(probes)
    pos = np.asarray(positions, float)
    quat = np.asarray(quaternions, float)
    try:
        if engine == "reference":
            make = _DemEngine
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
