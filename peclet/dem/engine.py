"""The contact-engine seam: the protocol every engine keeps and the registry of contact laws.

An engine advances a :class:`~peclet.dem.world.World` by one step and commits it with
:meth:`World.commit` (which alone advances the state, the walls, the clock and the timings)::

    engine.step(world, dt)                 # dt > 0, checked by the caller
    engine.history(world) -> {name: array} # its per-contact state, for persistence
    engine.restore(world, arrays)          # the inverse, on load

plus ``name`` (the registry's key) and ``parameters`` (a dict of floats, the law's settings,
which persistence saves and :meth:`Simulation.set_contact_law` accepts back). Two kinds are
registered today: the impulse engine (:mod:`peclet.dem.impulse`) and the explicit force-based
engine (:class:`peclet.dem.hertz.engine.ExplicitEngine`) driven by a force law, the
Hertz–Mindlin one (:mod:`peclet.dem.hertz`) or any other, each a folder of its own that
provides a :class:`ForceLaw`.

How to add a contact law (docs/architecture.md §6, "Adding a contact law"): write a
:class:`ForceLaw` in a folder of its own (``peclet/dem/<law>/``) with a ``make(**params)``
returning ``ExplicitEngine(<law>(**params), ...)``, and add one row to :data:`LAWS`.
"""
from __future__ import annotations

import importlib
from inspect import signature
from typing import Protocol, runtime_checkable

from peclet.core.validation import PecletArgumentError


@runtime_checkable
class ContactEngine(Protocol):
    """What :class:`~peclet.dem.Simulation` needs of a contact engine (module notes)."""

    name: str
    parameters: dict

    def step(self, world, dt) -> None: ...

    def history(self, world) -> dict: ...

    def restore(self, world, arrays) -> None: ...


@runtime_checkable
class ForceLaw(Protocol):
    """A force law of the explicit engine (:class:`peclet.dem.hertz.engine.ExplicitEngine`).

    - ``check(world, dt)``: refuse (PecletArgumentError) what the law cannot run;
    - ``pair_parameters(world, pairs, inv_mass)``: the law's per-candidate parameters (a
      tuple of (nc,) arrays; its own layout) for the candidate pairs ``pairs`` (``a``, ``b``
      with a wall as -1 - index, ``feat``), built when the candidate list is;
    - ``with_patches(params, rows, rstar)``: the parameters with the composed rows' effective
      radii (``rstar`` from both surfaces' curvatures) put in, for laws that use them;
    - ``with_distributed(params, rows, depth, force, stiffness, e_n)``: the parameters and
      the kernel's gap for distributed contacts (flat, line, edge contacts: their overlap
      ``depth`` and, as the Hertz overlap law gives them, ``force`` and ``stiffness``);
    - ``modulus(params)``: the effective modulus per candidate the distributed contact's
      region is sampled with (any positive number for laws that ignore it);
    - ``forces(rows, params, motion, dt, out)``: the contact forces (``out.force`` (nc, 3) on
      body a, ``out.fn`` (nc,) normal force) and the updated tangential history ``out.xi``;
      every row writes only its own slots (bitwise at any thread count);
    - ``rolling``: whether rolling resistance applies (the Hertz law's ``rolling_law``).
    """

    name: str
    rolling: bool

    def check(self, world, dt) -> None: ...

    def pair_parameters(self, world, pairs, inv_mass) -> tuple: ...

    def forces(self, rows, params, motion, dt, out) -> None: ...


#: The contact laws :meth:`Simulation.set_contact_law` knows: name -> "module:factory", the
#: factory called with the law's keyword parameters and returning a ContactEngine. Imported on
#: use, so that a law's folder is loaded only by a simulation that runs it.
LAWS = {
    "impulse": "peclet.dem.impulse:ImpulseEngine",
    "hertz": "peclet.dem.hertz.engine:make",
    "linear": "peclet.dem.linear:make",
}


def make_engine(name, **parameters):
    """The engine of the registered law ``name`` (a key of :data:`LAWS`) built with its
    keyword ``parameters``; PecletArgumentError for an unknown name."""
    if not isinstance(name, str) or name not in LAWS:
        raise PecletArgumentError("law", f"one of {sorted(LAWS)}", name)
    module, factory = LAWS[name].split(":")
    make = getattr(importlib.import_module(module), factory)
    try:
        signature(make).bind(**parameters)
    except TypeError as e:
        raise PecletArgumentError("parameters", f"the keyword parameters of {name!r}: "
                                  f"{signature(make)}", sorted(parameters), str(e)) from None
    return make(**parameters)
