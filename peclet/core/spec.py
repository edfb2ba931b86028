"""Specs that declare each field once: its default and its check, side by side.

A spec is a frozen dataclass deriving from :class:`Spec` whose fields are made with
:func:`field`, e.g. ``radius: float = field(10.0, Float(3.0, 200.0))``. :meth:`Spec.checked`
(or :meth:`Spec.check_fields`) then checks every declared field in declaration order (fields
named in ``check_first`` first), each error a :class:`~peclet.core.validation.PecletArgumentError`
naming the field (or ``names[field]``, e.g. the command line's flag) with the range the
declaration states (:func:`~peclet.core.validation.check_float` and friends word it).

A bound may name another field: its checked value is used (that field is checked first). A
field may default to None and resolve it (``if_none``: a value, or a callable of the
:class:`Checking` in progress). :class:`Custom` takes a rule that needs more (several fields at
once); it can read the other fields' checked values through the :class:`Checking`.
"""
from __future__ import annotations

import dataclasses
import math

from .validation import PecletArgumentError, check_choice, check_float, check_int

__all__ = ["Spec", "field", "Float", "Int", "Choice", "Text", "Custom", "Checking"]

_REFUSED = object()     # if_none: None is refused like any other bad value


def field(default, check):
    """A dataclass field with ``default`` whose value ``check`` (a :class:`Float`,
    :class:`Int`, :class:`Choice`, :class:`Text` or :class:`Custom`) accepts."""
    return dataclasses.field(default=default, metadata={"check": check})


class Checking:
    """The checks of one spec in progress: :meth:`value` gives a field's checked value
    (checking it now if it was not yet), :meth:`name` the name its errors carry."""

    def __init__(self, spec, names=None):
        self.spec = spec
        self.names = names or {}
        self.checks = {f.name: f.metadata["check"] for f in dataclasses.fields(spec)
                       if "check" in f.metadata}
        self.done = {}

    def name(self, fname):
        return self.names.get(fname, fname)

    def value(self, fname):
        if fname not in self.done:
            self.done[fname] = self.checks[fname].check(self.name(fname),
                                                        getattr(self.spec, fname), self)
        return self.done[fname]

    def bound(self, b):
        return self.value(b) if isinstance(b, str) else b


def _none(check, ctx):
    v = check.if_none
    return v(ctx) if callable(v) else v


@dataclasses.dataclass(frozen=True)
class Float:
    """A finite float in [lo, hi] (ends open as stated); a bound may name another field."""

    lo: float | str = -math.inf
    hi: float | str = math.inf
    lo_open: bool = False
    hi_open: bool = False
    if_none: object = _REFUSED

    def check(self, arg, value, ctx):
        if value is None and self.if_none is not _REFUSED:
            return _none(self, ctx)
        return check_float(arg, value, ctx.bound(self.lo), ctx.bound(self.hi), self.lo_open,
                           self.hi_open)


@dataclasses.dataclass(frozen=True)
class Int:
    """An integer in [lo, hi]; a bound may name another field."""

    lo: int | str = -math.inf
    hi: int | str = math.inf
    if_none: object = _REFUSED

    def check(self, arg, value, ctx):
        if value is None and self.if_none is not _REFUSED:
            return _none(self, ctx)
        return check_int(arg, value, ctx.bound(self.lo), ctx.bound(self.hi))


@dataclasses.dataclass(frozen=True)
class Choice:
    """One of ``choices``."""

    choices: tuple

    def check(self, arg, value, ctx):
        return check_choice(arg, value, self.choices)


@dataclasses.dataclass(frozen=True)
class Text:
    """A non-empty string; the error says it must be ``what``."""

    what: str = "a non-empty string"

    def check(self, arg, value, ctx):
        if not isinstance(value, str) or not value:
            raise PecletArgumentError(arg, self.what, value)
        return value


@dataclasses.dataclass(frozen=True)
class Custom:
    """A rule of its own: ``rule(arg, value, checking)`` returns the checked value (or raises
    PecletArgumentError naming ``arg``)."""

    rule: object

    def check(self, arg, value, ctx):
        return self.rule(arg, value, ctx)


class Spec:
    """Base of the run specs (a frozen dataclass deriving from it declares its fields with
    :func:`field`). ``check_first``: fields checked before the rest (declaration order)."""

    check_first = ()

    def check_fields(self, names=None):
        """{field: checked value} of every declared field (errors name ``names[field]``)."""
        ctx = Checking(self, names)
        for fname in tuple(self.check_first) + tuple(ctx.checks):
            ctx.value(fname)
        return ctx.done

    def checked(self, names=None):
        """The spec with every declared field checked and its defaults resolved."""
        return dataclasses.replace(self, **self.check_fields(names))

    def _check_in_place(self):
        """Check every declared field and store the checked values (for ``__post_init__``
        of a frozen spec)."""
        for k, v in self.check_fields().items():
            object.__setattr__(self, k, v)

    @classmethod
    def check_value(cls, fname, value, arg=None):
        """``value`` checked as field ``fname`` of this spec (errors name ``arg``, default
        ``fname``); a field without a declared check: KeyError."""
        checks = {f.name: f.metadata["check"] for f in dataclasses.fields(cls)
                  if "check" in f.metadata}
        if fname not in checks:
            raise KeyError(fname)
        return checks[fname].check(arg or fname, value, _Alone(cls, fname))


class _Alone(Checking):
    """One field checked on its own: a bound naming another field is refused (KeyError)."""

    def __init__(self, cls, fname):
        self.names, self.done, self.checks = {}, {}, {}
        self.fname = fname

    def value(self, fname):
        raise KeyError(f"{self.fname}'s check needs {fname}")
