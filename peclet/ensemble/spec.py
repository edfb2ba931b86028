"""What one realization is: :class:`PackSpec`, its id, and the ensemble built from seeds x sweep.

A realization is a deterministic function of its :class:`PackSpec` (element, container, count,
protocol, material, seed, ...). Its id is readable and content-addressed: ``s<seed>-<16 hex>``,
the hex the start of the SHA-256 of the spec's canonical JSON, so the same spec always lands in
the same ``OUT/<spec-id>/`` directory and two different specs never share one.

``--seeds`` text: comma-separated integers >= 0 and inclusive ranges, e.g. ``1-32`` or
``1-4,10,20-22``. ``--sweep`` text: ``KEY=V1,V2,...`` with KEY one of :data:`SWEEPABLE` or a
numeric construction parameter of the spec's element (``thickness=0.03,0.06,0.12`` for a Pall
ring: ``peclet.packing.bed.elements.PARAMS``); several sweeps combine as a Cartesian product.

The element is text, ``NAME`` or ``NAME:KEY=V,...`` (``pall_ring:thickness=0.024``), stored in
its canonical form (parameters in ``PARAMS`` order, floats as their shortest repr): the same
element always gives the same id, and two thicknesses two ids. A spec without parameters keeps
the id it had before parameters existed.
"""
from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import math
import re

from peclet.core.spec import Custom, Float, Int, Spec, Text, field
from peclet.core.validation import PecletArgumentError, check_choice, check_int

__all__ = ["PackSpec", "SWEEPABLE", "PROTOCOLS", "check_field", "parse_seeds", "parse_sweep",
           "make_specs", "ensemble_manifest", "MAX_REALIZATIONS", "element_params",
           "sweepable_element_params"]

#: Version of the spec / results layout; part of every id, so a layout change never reuses
#: an old directory.
FORMAT = "peclet-ensemble/1"

#: Largest ensemble one call accepts (seeds x sweep points); a typo like ``1-1000000`` is
#: refused before anything runs.
MAX_REALIZATIONS = 100_000
_MAX_SEED = 2 ** 63 - 1

#: Parameters a sweep may vary, with their check (the same one a fixed value goes through).
SWEEPABLE = ("mu", "e_n", "e_t", "count", "steps_scale")

#: Protocols of ``peclet.packing.pack`` a spec may name.
PROTOCOLS = ("page", "rain")


def _count(arg, value, c=None):
    """pack()'s cap (work and memory: peclet.packing.bed.api.count_cap)."""
    from peclet.packing.bed.api import count_cap

    cap, why = count_cap()
    v = check_int(arg, value, 1)
    if v > cap:
        raise PecletArgumentError(arg, f"an integer in [1, {cap}]", value, why)
    return v


def _mc_samples(arg, value, c=None):
    """About 100 bytes per sample at the sampling's peak: 1 GB."""
    v = check_int(arg, value, 1000)
    if v > 10_000_000:
        raise PecletArgumentError(arg, "an integer in [1000, 10000000]", value,
                                  "about 100 bytes per sample at the sampling's peak: "
                                  "10^7 samples are about 1 GB")
    return v


#: The numeric fields: what :func:`check_field` checks.
_NUMERIC = ("mu", "e_n", "e_t", "count", "steps_scale", "seed", "mc_samples")


def check_field(name, value, arg=None):
    """``value`` checked against the accepted range of the numeric spec field ``name`` as
    :class:`PackSpec` declares it, in one place (fixed and swept values alike); errors name
    ``arg`` (default ``name``)."""
    if name not in _NUMERIC:
        raise KeyError(name)
    return PackSpec.check_value(name, value, arg)


@dataclasses.dataclass(frozen=True)
class PackSpec(Spec):
    """One realization: pour ``count`` copies of ``element`` into ``container`` with
    ``protocol`` (its step counts times ``steps_scale``), body material (e_n, e_t, mu) (walls
    the same), start cloud from ``seed``; then measure eps, f_env (``mc_samples`` Monte Carlo
    points in the first bulk window) and the mean coordination Z.

    element: a library name (``peclet.packing.ELEMENTS``), optionally with construction
    parameters ``NAME:KEY=V,...`` (checked and stored canonically, see the module docstring;
    :attr:`element_params` reads them back); container: ``"box:L"`` etc. as
    ``peclet.packing.pack`` reads it; lengths in element diameters D. Each field's range is
    declared here once (:mod:`peclet.core.spec`).
    """

    check_first = ("element", "container", "protocol")

    element: str = field("pall_ring", Text())
    container: str = field("box:3.5", Text())
    count: int = field(48, Custom(_count))
    protocol: str = field("page", Text())
    steps_scale: float = field(1.0, Float(0.0, 100.0, lo_open=True))
    e_n: float = field(0.15, Float(0.0, 1.0))
    e_t: float = field(0.0, Float(-1.0, 1.0))
    mu: float = field(0.5, Float(0.0))
    seed: int = field(5, Int(0, _MAX_SEED))
    mc_samples: int = field(400_000, Custom(_mc_samples))

    def __post_init__(self):
        self._check_in_place()
        # the same cheap checks pack() makes, here so a bad spec fails before a cluster starts
        from peclet.packing.bed.containers import parse_container
        from peclet.packing.bed.elements import element_text, parse_element
        from peclet.packing.bed.user_shapes import file_element_text

        text = file_element_text(self.element)
        object.__setattr__(self, "element", text if text is not None
                           else element_text(*parse_element(self.element, "element")))
        parse_container(self.container)
        check_choice("protocol", self.protocol, PROTOCOLS)
        if self.steps_scale != 1.0 and self.protocol != "page":
            raise PecletArgumentError("steps_scale", "1 unless protocol is 'page'",
                                      self.steps_scale)

    @property
    def element_params(self):
        """The element's given construction parameters (name -> value; {} for the defaults)."""
        return element_params(self.element)

    def as_dict(self):
        """The spec as a JSON-able dict (field name -> value)."""
        return dataclasses.asdict(self)

    def canonical(self):
        """Canonical JSON text (sorted keys, floats as their shortest round-trip repr)."""
        from peclet.packing.bed.user_shapes import file_digest, is_file_element

        extra = {}
        if is_file_element(self.element):
            # an element from a file is its contents: an edited file is another realization
            extra["element_sha256"] = file_digest(self.element)
        return json.dumps(dict(self.as_dict(), format=FORMAT, **extra), sort_keys=True,
                          separators=(",", ":"))

    @property
    def id(self):
        """``s<seed>-<first 16 hex of SHA-256(canonical())>``: a directory name."""
        h = hashlib.sha256(self.canonical().encode()).hexdigest()[:16]
        return f"s{self.seed}-{h}"

    @classmethod
    def from_dict(cls, d):
        """Inverse of :meth:`as_dict` (unknown keys are an error)."""
        names = {f.name for f in dataclasses.fields(cls)}
        extra = sorted(set(d) - names)
        if extra:
            raise PecletArgumentError("spec", f"a dict with keys from {sorted(names)}",
                                      extra, "unknown keys")
        return cls(**d)


_INT = r"\d+"


def parse_seeds(text, name="seeds"):
    """``"1-32"`` / ``"1,3,5"`` / ``"1-4,10"`` -> sorted list of distinct ints >= 0.

    Raises PecletArgumentError naming ``name`` on empty items, a reversed range, a negative or
    non-integer seed, a seed given twice, or more than :data:`MAX_REALIZATIONS` seeds.
    """
    what = "comma-separated seeds >= 0 or ranges A-B (A <= B), e.g. 1-32 or 1-4,10"
    if not isinstance(text, str) or not text.strip():
        raise PecletArgumentError(name, what, text)
    seen = []
    for item in text.split(","):
        item = item.strip()
        m = re.fullmatch(rf"({_INT})(?:\s*-\s*({_INT}))?", item)
        if not m:
            raise PecletArgumentError(name, what, text, f"bad item {item!r}")
        a = int(m.group(1))
        b = int(m.group(2)) if m.group(2) is not None else a
        if b < a:
            raise PecletArgumentError(name, what, text, f"reversed range {item!r}")
        if b > _MAX_SEED:
            raise PecletArgumentError(name, what, text, f"seed above 2**63-1 in {item!r}")
        if len(seen) + (b - a + 1) > MAX_REALIZATIONS:
            raise PecletArgumentError(name, what, text,
                                      f"more than {MAX_REALIZATIONS} seeds")
        seen.extend(range(a, b + 1))
    if len(set(seen)) != len(seen):
        dup = sorted({s for s in seen if seen.count(s) > 1})[:3]
        raise PecletArgumentError(name, what, text, f"seed(s) {dup} given twice")
    return sorted(seen)


def element_params(element):
    """The given construction parameters of an element text (``"pall_ring:thickness=0.024"``
    -> ``{"thickness": 0.024}``; ``"pall_ring"`` and a file element -> ``{}``), checked."""
    from peclet.packing.bed.elements import parse_element
    from peclet.packing.bed.user_shapes import is_file_element

    return {} if is_file_element(element) else parse_element(element, "element")[1]


def sweepable_element_params(element="pall_ring"):
    """Names of the element's numeric construction parameters (a sweep may vary them; none
    for an element from a file)."""
    from peclet.packing.bed.elements import PARAMS, parse_element
    from peclet.packing.bed.user_shapes import is_file_element

    if is_file_element(element):
        return ()
    kind = parse_element(element, "element")[0]
    return tuple(p.name for p in PARAMS[kind] if p.kind != "triple")


def _check_element_value(element, key, num, arg):
    """``num`` as the element's parameter ``key`` (its range given the element's other
    parameters, then the constructor's cross-checks); returns the value (float or int)."""
    from peclet.packing.bed.elements import ELEMENTS, check_param, parse_element

    kind, given = parse_element(element, "element")
    if key in given:
        raise PecletArgumentError(arg, f"a parameter not also fixed in the element {element!r}",
                                  key)
    v = check_param(kind, key, num, given, arg)
    try:
        ELEMENTS[kind](**dict(given, **{key: v}))
    except ValueError as exc:
        raise PecletArgumentError(arg, f"{kind} parameters consistent with each other", num,
                                  str(exc)) from None
    return v


def parse_sweep(items, name="sweep", element=None):
    """``["mu=0.3,0.5,0.8", "count=24,48"]`` (or one string) -> ``{"mu": [...], ...}`` in the
    given order; each value checked like a fixed value of that parameter.

    KEY is one of :data:`SWEEPABLE` or a numeric construction parameter of ``element`` (the
    ensemble's element text; None: ``"pall_ring"``, PackSpec's default), e.g.
    ``thickness=0.03,0.06,0.12``, each value checked against the parameter's range given the
    element's other parameters (``peclet.packing.bed.elements.PARAMS``).

    Raises PecletArgumentError naming ``name`` on a missing ``=``, a key that is neither, a
    key swept twice, an empty or unparsable value, a value out of range, or a value given
    twice.
    """
    element = "pall_ring" if element is None else element
    if items is None:
        return {}
    elem_keys = sweepable_element_params(element)
    what = (f"KEY=V1,V2,... with KEY one of {', '.join(SWEEPABLE)} or a parameter of "
            f"{element.partition(':')[0]} ({', '.join(elem_keys)})")
    if isinstance(items, str):
        items = [items]
    out = {}
    for item in items:
        if not isinstance(item, str) or "=" not in item:
            raise PecletArgumentError(name, what, item)
        key, _, vals = item.partition("=")
        key = key.strip()
        if key not in SWEEPABLE and key not in elem_keys:
            raise PecletArgumentError(name, what, item, f"unknown parameter {key!r}"
                                      + _other_elements(key, element))
        if key in out:
            raise PecletArgumentError(name, what, item, f"{key} swept twice")
        parsed = []
        for v in vals.split(","):
            v = v.strip()
            try:
                num = float(v)
            except ValueError:
                raise PecletArgumentError(name, what, item, f"{v!r} is not a number") from None
            if key == "count" and not (math.isfinite(num) and num.is_integer()):
                raise PecletArgumentError(name, what, item, f"count {v!r} is not an integer")
            try:
                parsed.append(check_field(key, num, f"{name} {key}") if key in SWEEPABLE
                              else _check_element_value(element, key, num, f"{name} {key}"))
            except PecletArgumentError as exc:
                raise PecletArgumentError(name, what, item, str(exc)) from None
        if len(set(parsed)) != len(parsed):
            raise PecletArgumentError(name, what, item, "a value given twice")
        out[key] = parsed
    return out


def _other_elements(key, element):
    from peclet.packing.bed.elements import PARAMS

    kind = element.partition(":")[0]
    if any(p.name == key and p.kind == "triple" for p in PARAMS.get(kind, ())):
        return f"; {key!r} is a triple (a/b/c): set it in the element, it is not sweepable"
    owners = [k for k, ps in PARAMS.items() if any(p.name == key for p in ps)]
    return (f"; {key!r} is a parameter of {', '.join(owners)}, not of {kind}") \
        if owners else ""


def make_specs(seeds, sweep=None, **fixed):
    """Every (sweep point, seed) as a :class:`PackSpec`, sweep points in the given order and
    seeds inner. ``fixed``: the other PackSpec fields; a swept key must not also be fixed.
    A swept element parameter (e.g. ``thickness``) goes into the element text of each point,
    beside the parameters the fixed ``element`` already gives (which must not include it)."""
    from peclet.packing.bed.elements import element_text, parse_element
    from peclet.packing.bed.user_shapes import is_file_element

    sweep = dict(sweep or {})
    clash = sorted(set(sweep) & {k for k, v in fixed.items() if v is not None})
    if clash:
        raise PecletArgumentError("sweep", "parameters not also given as fixed values",
                                  clash)
    fixed = {k: v for k, v in fixed.items() if v is not None}
    names = {f.name for f in dataclasses.fields(PackSpec)}
    elem_keys = [k for k in sweep if k not in names]
    element = fixed.get("element", PackSpec.element)
    kind, given = (element, {}) if is_file_element(element) \
        else parse_element(element, "element")
    for k in elem_keys:   # what parse_sweep checks, again for a sweep built by hand
        if k not in sweepable_element_params(kind):
            raise PecletArgumentError("sweep", f"a spec field ({', '.join(SWEEPABLE)}) or a "
                                      f"parameter of {kind} "
                                      f"({', '.join(sweepable_element_params(kind))})", k,
                                      "unknown parameter" + _other_elements(k, kind))
        if k in given:
            raise PecletArgumentError("sweep", "parameters not also fixed in the element",
                                      k)
    keys = list(sweep)
    points = list(itertools.product(*(sweep[k] for k in keys))) if keys else [()]
    if len(points) * len(seeds) > MAX_REALIZATIONS:
        raise PecletArgumentError("sweep", f"at most {MAX_REALIZATIONS} realizations in all",
                                  len(points) * len(seeds), "seeds x sweep points")
    specs = []
    for p in points:
        point = dict(zip(keys, p))
        kw = dict(fixed, **{k: v for k, v in point.items() if k in names})
        if elem_keys:
            kw["element"] = element_text(kind, dict(given, **{k: point[k]
                                                             for k in elem_keys}))
        specs.extend(PackSpec(**kw, seed=s) for s in seeds)
    return specs


def ensemble_manifest(specs, swept=None):
    """What identifies an ensemble (written to ``OUT/ensemble.json``): the fields shared by
    every spec except the seed and the swept ones, and the swept names. Adding seeds or sweep
    values later keeps the manifest; changing a fixed field or what is swept changes it."""
    if not specs:
        raise PecletArgumentError("specs", "a non-empty list of PackSpec", specs)
    dicts = [s.as_dict() for s in specs]
    varying = sorted(k for k in dicts[0] if k != "seed"
                     and any(d[k] != dicts[0][k] for d in dicts))
    swept = sorted(set(varying) | set(swept or ()))
    fixed = {k: v for k, v in dicts[0].items() if k != "seed" and k not in swept}
    return dict(format=FORMAT, fixed=fixed, swept=swept)
