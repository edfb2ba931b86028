"""The Hypothesis search driver every certificate family shares: :class:`PropertyResult`, the
statuses, the result constructors (:func:`make_result`, :func:`bad_answer`,
:func:`unavailable`), the active certification profile, and :func:`search`, which runs a
property over a Hypothesis strategy under that profile, keeps the worst figure and, on failure,
the shrunk counterexample (a runnable snippet). Nothing here needs pytest.
"""
from __future__ import annotations

import hashlib
import math
import time
from contextlib import contextmanager, nullcontext
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Callable, Optional

import numpy as np
from hypothesis import Phase, given, seed
from hypothesis.errors import Flaky
from hypothesis import settings as hypothesis_settings

if TYPE_CHECKING:
    from .geometry.recipes import TreeRecipe

__all__ = ["PropertyResult", "search", "set_profile", "active_settings", "profile_settings",
           "capped_settings", "active_profile_name", "set_progress", "unavailable",
           "make_result", "bad_answer", "encode_recipe", "example_rng", "fixed_constant_pool",
           "PASSED", "FAILED", "UNAVAILABLE", "NOT_APPLICABLE", "NOT_CLAIMED"]

PASSED, FAILED, UNAVAILABLE, NOT_APPLICABLE = "passed", "failed", "unavailable", "n/a"
#: Status of a certificate an engine declares it does not claim (reported, never passed).
NOT_CLAIMED = "not claimed"


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


def make_result(name, ok, figure, figure_name, worse, text="", **details) -> PropertyResult:
    """The result of one example: passed iff ``ok``; ``figure`` the value of the figure
    ``figure_name`` (worse in direction ``worse``); ``text`` the counterexample text (kept on
    failure only); ``details`` recorded as given."""
    return PropertyResult(name, bool(ok), 1, float(figure), figure_name,
                          "" if ok else text, PASSED if ok else FAILED, worse, details)


def bad_answer(name, figure_name, worse, why) -> PropertyResult:
    """A failed certificate whose backend gave no usable answer (``why`` shows the answer);
    its figure is the worst possible (-inf for a "min" figure, +inf for a "max" one)."""
    return PropertyResult(name, False, 1, -math.inf if worse == "min" else math.inf, figure_name,
                          f"unusable answer from the engine under certification: {why}", FAILED,
                          worse, {"bad_answer": why})


def unavailable(name, why) -> PropertyResult:
    """A property that could not run (missing engine feature): neither passed nor failed."""
    return PropertyResult(name, False, 0, float("nan"), "", why, UNAVAILABLE)


def encode_recipe(recipe: TreeRecipe):
    """``(builder, root, node_ints, node_reals)`` of a tree recipe (its flat encoding)."""
    b, root = recipe.build()
    ni, nr, _, _ = b.encode()
    return b, root, ni, nr


def example_rng(*keys):
    """A numpy generator seeded by a hash of ``keys`` (the same example draws the same points)."""
    h = hashlib.sha256(repr(keys).encode()).digest()
    return np.random.default_rng(int.from_bytes(h[:8], "little"))


# ---------------------------------------------------------------------------- search
@contextmanager
def fixed_constant_pool():
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
        original = providers._get_local_constants  # noqa: SLF001 -- Hypothesis internal, absent versions handled below
        cache = providers.CONSTANTS_CACHE.cache
        empty = providers.Constants()
    except (ImportError, AttributeError):
        yield
        return
    cache.clear()  # its entries were computed from the process's current pool
    providers._get_local_constants = lambda: empty  # noqa: SLF001
    try:
        yield
    finally:
        providers._get_local_constants = original  # noqa: SLF001
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


def capped_settings(cap: int):
    """The active certification settings with at most ``cap`` examples (the profile's count if
    lower): for certificates whose every example is a run of an engine."""
    return profile_settings(max_examples=min(active_settings().max_examples, int(cap)))


def search(check: Callable, strategy, name: Optional[str] = None, settings=None,
           describe: Callable = repr) -> PropertyResult:
    """Run ``check(example) -> PropertyResult`` over ``strategy`` with Hypothesis.

    The active certification profile (:func:`active_settings`) applies unless ``settings``
    is given. On failure Hypothesis shrinks the input; the returned result carries the shrunk example (``describe(example)``)
    and its own counterexample text. Inputs for which the property does not apply (status
    "n/a") count as examples but never fail. An "unavailable" or "not claimed" result stops
    the search and is returned.

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
        if res.status in (UNAVAILABLE, NOT_CLAIMED):    # the engine cannot or does not
            seen["unavailable"] = res                     # claim it: stop, never fail
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
    run._hypothesis_internal_add_digest = label.encode()  # noqa: SLF001 -- Hypothesis's per-test database key hook
    test = hypothesis_settings(effective, phases=[p for p in effective.phases
                                                  if p is not Phase.explain])(given(strategy)(run))
    pool = nullcontext()
    if effective.derandomize:
        # derandomised: the seed comes from the certificate's name (Hypothesis would hash the
        # source of ``run`` above, the same for every certificate and changed by any edit
        # here) and the examples must not depend on what the process imported before
        test = seed(int.from_bytes(hashlib.sha256(label.encode()).digest()[:8], "little"))(test)
        pool = fixed_constant_pool()
    flaky = False
    try:
        with pool:
            test()
        err = None
    except AssertionError as exc:
        err = exc
    except Flaky as exc:
        # the engine failed an input, then passed it when Hypothesis ran it again (a race, a
        # stale state): a failure of the engine, reported with the input it first failed on,
        # never an error of the certifier
        err, flaky = exc, True
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
            if flaky:
                base.counterexample += ("\n(not reproducible: the engine passed this same input "
                                        "when it was run again)")
                base.details["flaky"] = True
        else:
            base.counterexample = str(err)
    return base
