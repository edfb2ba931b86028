"""Mass-property certificates: peclet's quadrature against the closed forms of the leaf table
and under refinement (:func:`quadrature_convergence`), and any mass-property engine against
the same closed forms at its stated order, its claimed errors bounding the true ones
(:func:`mass_properties_certificate`, see :mod:`peclet_verify.mass.backend` for the
protocol). Units: the tree's length unit, unit density; relative errors are dimensionless.
"""
from __future__ import annotations

import math
from typing import Callable, Optional

import numpy as np

from .. import registry as REG
from ..geometry.recipes import TreeRecipe
from ..loading import backend_name
from ..search import NOT_APPLICABLE, PropertyResult, bad_answer, make_result, unavailable
from .backend import DEFAULT_FLOOR, MAX_FLOOR

__all__ = ["closed_form", "closed_form_leaf", "closed_form_world", "reference_measure",
           "quadrature_convergence", "mass_properties_certificate", "declared_floor"]



def closed_form(recipe: TreeRecipe):
    """(volume, centre of mass (3,), principal moments (3,) ascending) of a one-leaf recipe at
    unit density, moved by the leaf's transform (rotation, scale s: volume s^3, moments s^5),
    from the leaf table's closed forms
    (:func:`peclet.core.geom.leaves.closed_form_mass_properties`); None if it has none."""
    leaf = closed_form_leaf(recipe)
    if leaf is None:
        return None
    exact, s, _, com = leaf
    principal = np.sort(np.linalg.eigvalsh(np.asarray(exact.inertia, float))) * s ** 5
    return exact.volume * s ** 3, com, principal


def reference_measure(builder, root, lo, hi, tol, cache=None):
    """Mass properties by the reference engine's ``SceneBuilder.body_properties`` asked for
    relative accuracy ``tol`` (its refinement knob; n = 32: 8 top cells per axis): (volume, com,
    principal ascending). Raises AttributeError when the engine has no quadrature yet.

    ``cache`` (a dict kept by the caller) is handed to ``body_properties``, which then does the
    box check and integrates each cell once for all the calls on one tree and box (the
    tolerance levels of one example share their top cells and most refined ones); its results
    are bitwise those without it."""
    res = (builder.body_properties(root, lo, hi, n=32, tol=tol) if cache is None else
           builder.body_properties(root, lo, hi, n=32, tol=tol, cache=cache))

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
                           slack: float = 10.0, fast: bool = True) -> PropertyResult:
    """Quadrature of a one-leaf solid against its closed form, refined by its tolerance.

    ``measure(builder, root, lo, hi, tol) -> (volume, com, principal)`` (default: the
    reference engine, whose refinement knob is the requested relative accuracy). Passes when
    every level honours its request (relative volume error <= ``slack * tol``, or round-off
    1e-12) and the relative errors (volume, com / size, principal moments) at the finest level
    are <= ``rtol``. The observed order of the volume error against ``tol`` between the two
    finest levels is reported. Figure: the worst relative error at the finest level. Status
    "n/a" for leaves without a closed form here.

    ``fast`` (default) lets the reference engine's levels share one cache (the box check and
    every integrated cell done once per example, see :func:`reference_measure`): each level's
    answer is bitwise the one it gives alone, so the result (verdict, figure, text) is the
    same as with ``fast=False``, the straightforward path kept as the reference. A custom
    ``measure`` is called as given either way.
    """
    name = "quadrature_convergence"
    fig = REG.figure(name)
    exact = closed_form(recipe)
    if exact is None:
        return PropertyResult(name, True, 1, float("nan"), fig, "", NOT_APPLICABLE)
    if measure is None:
        cache = {} if fast else None

        def measure(builder, root_, lo_, hi_, tol):
            return reference_measure(builder, root_, lo_, hi_, tol, cache=cache)
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
    return make_result(name, ok, fin[worst_key], f"{fig} ({worst_key}, tol={tols[-1]:g})",
                   "max", text, observed_order=order)


# ---------------------------------------------------------------------------- any mass backend
def closed_form_leaf(recipe):
    """``(exact, s, R, com)`` of a one-leaf recipe: the leaf table's closed form ``exact``
    (:func:`peclet.core.geom.leaves.closed_form_mass_properties`, at unit density in the leaf's
    frame), the leaf's scale ``s`` and rotation matrix ``R``, and its centre of mass in the
    root's parent frame; None without a closed form."""
    from peclet.core.geom import quat_to_matrix
    from peclet.core.geom.leaves import closed_form_mass_properties
    node = recipe.root
    if not hasattr(node, "kind") or recipe.reframes:
        return None
    exact = closed_form_mass_properties(node.kind, list(node.params))
    if exact is None:
        return None
    tr = node.transform
    s = float(tr.scale)
    R = quat_to_matrix(np.asarray(tr.rotation, float))
    com = np.asarray(tr.translation, float) + s * R @ np.asarray(exact.com, float)
    return exact, s, R, com


def closed_form_world(recipe):
    """(volume, com (3,), inertia (3, 3)) of a one-leaf recipe at unit density in the root's
    parent frame (the leaf's transform applied: volume s^3, inertia s^5 R I R^T), from
    :func:`closed_form_leaf`; None without a closed form."""
    leaf = closed_form_leaf(recipe)
    if leaf is None:
        return None
    exact, s, R, com = leaf
    inertia = s ** 5 * R @ np.asarray(exact.inertia, float) @ R.T
    return exact.volume * s ** 3, com, inertia


def _answer_problem(ans):
    if ans is None:
        return "returned None"
    if not isinstance(ans, (tuple, list)) or len(ans) not in (3, 4):
        return f"returned {type(ans).__name__} {ans!r:.80}, not (volume, com, inertia[, claimed])"
    try:
        v = float(ans[0])
        com = np.asarray(ans[1], float)
        inertia = np.asarray(ans[2], float)
    except (TypeError, ValueError) as exc:
        return f"returned values that are not numbers: {exc}"
    if com.shape != (3,) or inertia.shape != (3, 3):
        return f"com has shape {com.shape}, inertia {inertia.shape}; expected (3,) and (3, 3)"
    if not (math.isfinite(v) and np.all(np.isfinite(com)) and np.all(np.isfinite(inertia))):
        return f"non-finite answer: volume {v!r}, com {com.tolist()}, inertia {inertia.tolist()}"
    return None


def _claims(ans):
    c = ans[3] if len(ans) > 3 else None
    if c is None:
        return {}
    if isinstance(c, dict):
        return {k: float(c[k]) for k in ("volume", "inertia") if c.get(k) is not None}
    return {"volume": float(c)}


def declared_floor(backend) -> float:
    """The relative-error floor ``backend`` declares (:data:`~peclet_verify.mass.backend.
    DEFAULT_FLOOR` if none): the error below which its precision is reached."""
    floor = getattr(backend, "floor", None)
    return DEFAULT_FLOOR if floor is None else float(floor)


def mass_properties_certificate(recipe, backend, slack: float = 10.0,
                                roundoff: float = 1e-14):
    """The engine's mass properties of a one-leaf solid against the leaf table's closed form.

    At every declared resolution: relative errors of volume, centre of mass (over V^(1/3)) and
    inertia (worst entry over the largest entry of the exact tensor). Passes when

    - the error falls as stated: at each level ``max error <= slack x C h^p`` (C stated, or
      from the coarsest level's error), or below the engine's ``floor``, which may be at most
      :data:`~peclet_verify.mass.backend.MAX_FLOOR` (a larger declared floor fails the
      certificate: it would excuse real error); and
    - every claim bounds the true error: ``|V - V0| <= claimed volume + roundoff V0`` and
      ``max |I - I0| <= claimed inertia + roundoff max|I0|``.

    Figure: the worst ratio of an error to what it is allowed (<= 1 passes). The observed
    order (least squares of log error on log h over the levels above the floor) is in
    ``details["observed_order"]``, the floor judged with in ``details["declared_floor"]`` (and
    in the text). Status "n/a" for a leaf without a closed form.
    """
    name = "mass_properties"
    fig = REG.figure(name)
    floor = declared_floor(backend)
    if not floor <= MAX_FLOOR:  # a NaN floor too
        return make_result(name, False, math.inf, fig, "max",
                           f"{backend_name(backend)} declares floor {floor:g} (the relative "
                           f"error it is excused below), more than the maximum {MAX_FLOOR:g} "
                           f"(peclet_verify.mass.backend.MAX_FLOOR): a floor that large would "
                           f"pass real error as precision reached", declared_floor=floor)
    exact = closed_form_world(recipe)
    if exact is None:
        return PropertyResult(name, True, 1, float("nan"), fig, "", NOT_APPLICABLE)
    v0, com0, I0 = exact
    b, root = recipe.build()
    ni, nr, _, _ = b.encode()
    c, r, _ = b.node_bound(root)
    lo, hi = c - 1.02 * r, c + 1.02 * r
    res = [float(x) for x in backend.resolutions]
    decreasing = res[0] > res[-1]
    h = [x if decreasing else 1.0 / x for x in res]
    p = float(backend.order)
    C = getattr(backend, "constant", None)
    size, imax = v0 ** (1.0 / 3.0), float(np.abs(I0).max())
    levels = []
    for x in res:
        try:
            ans = backend.mass_properties(ni, nr, root, lo, hi, x)
        except Exception as exc:  # the engine's failure is the certificate's failure
            return bad_answer(name, fig, "max", f"mass_properties(..., {x!r}) raised "
                               f"{type(exc).__name__}: {exc}")
        why = _answer_problem(ans)
        if why:
            return bad_answer(name, fig, "max", f"{backend_name(backend)} at resolution {x!r} "
                               f"{why}")
        v, com, inertia = float(ans[0]), np.asarray(ans[1], float), np.asarray(ans[2], float)
        levels.append(dict(res=x, volume=abs(v - v0) / v0,
                           com=float(np.linalg.norm(com - com0)) / size,
                           inertia=float(np.abs(inertia - I0).max()) / imax,
                           abs_volume=abs(v - v0), abs_inertia=float(np.abs(inertia - I0).max()),
                           claims=_claims(ans)))
    errs = [max(lv["volume"], lv["com"], lv["inertia"]) for lv in levels]
    if C is None:
        C = max(errs[0], floor) / h[0] ** p
    ratios, lines = [], []
    for lv, e, hh in zip(levels, errs, h):
        allowed = max(slack * C * hh ** p, floor)
        ratios.append(e / allowed)
        line = (f"resolution {lv['res']:g}: relative errors volume {lv['volume']:.2e}, com "
                f"{lv['com']:.2e}, inertia {lv['inertia']:.2e}; allowed {allowed:.2e}")
        for key, true in (("volume", lv["abs_volume"]), ("inertia", lv["abs_inertia"])):
            if key in lv["claims"]:
                claim = lv["claims"][key]
                scale_ = v0 if key == "volume" else imax
                bound = claim + roundoff * scale_
                ratios.append(true / bound if bound > 0 else math.inf)
                line += (f"; {key} error {true:.2e} vs claimed {claim:.2e}"
                         f"{' (CLAIM VIOLATED)' if true > bound else ''}")
        lines.append(line)
    above = [(math.log(hh), math.log(e)) for e, hh in zip(errs, h) if e > floor]
    order = float(np.polyfit(*zip(*above), 1)[0]) if len(above) >= 2 else float("nan")
    worst = max(ratios)
    text = (f"{backend_name(backend)} (stated: relative error <= {'' if getattr(backend, 'constant', None) is not None else 'C0 x '}"
            f"{slack:g} x {C:.3g} h^{p:g}, h = {'resolution' if decreasing else '1/resolution'}"
            f"; declared floor {floor:g}, at most {MAX_FLOOR:g}; observed order {order:.2f})\n" + "\n".join(lines))
    return make_result(name, worst <= 1.0, worst, fig, "max", text, observed_order=order,
                       declared_floor=floor, stated_order=p,
                       levels=[{k: lv[k] for k in ("res", "volume", "com", "inertia")}
                               for lv in levels])
