"""The one list of peclet's certificate families and certificates. Stdlib only: the plugin
reads it at configure time, before the engine is imported.

:data:`FAMILIES` holds one :class:`Family` record per family (``geometry``: Equation 1, sign
and distance agreement; ``mass``: quadrature against the closed forms of the leaf table;
``dem``: determinism, contact buffers; ``mechanics``: closed-form mechanics of any DEM engine;
``impact``: the Chung & Ooi single-contact benchmarks of any engine with a Hertz or linear law):
the subpackage ``peclet_verify.<name>`` holding it, its pytest option, hook and fixture, its
backend module and its suite module. The pytest plugin (:mod:`peclet_verify.plugin`,
:mod:`peclet_verify.fixtures`) is driven by these records.

:data:`CERTIFICATES` registers each certificate once with its family, its property id, its
title (the name a report lists) and the label of its worst figure. Everything that names
certificates derives from here: the report's lists and the names an xfails file may use
(:mod:`peclet_verify.report`), the titles the suites search under (each family's ``suite``,
``properties/``) and the figure labels the properties report (:func:`figure`). Scopes say what
a certificate judges: ``suite`` an engine plugged in as a geometry backend, ``repo`` peclet
itself, ``dem`` a DEM backend, ``mass`` a mass-property backend, ``impact`` an impact backend.
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Family", "FAMILIES", "FAMILY_NAMES", "family", "Certificate", "SCOPES", "FIGURES",
           "CERTIFICATES", "certificate", "title", "titles", "properties", "figure",
           "known_names"]


@dataclass(frozen=True)
class Family:
    """One certificate family, held by the subpackage ``peclet_verify.<name>``.

    ``option`` the pytest option naming the engine to certify (``"module:factory"``),
    ``hook`` the hook a ``conftest.py`` implements to return it (:mod:`peclet_verify.hooks`),
    ``fixture`` the session fixture that provides it to the suite, ``backend`` the module with
    the family's protocol and its ``load_backend(spec, option)``, ``check_backend(backend)``
    and ``default_backend()``, ``suite`` the test module a downstream project imports, and
    ``engine`` what the option's factory returns (its help text). Families that certify the
    same engine (dem and mechanics) share the option, hook, fixture and backend module.
    """

    name: str
    option: str
    hook: str
    fixture: str
    backend: str
    suite: str
    engine: str

    @property
    def package(self) -> str:
        return f"peclet_verify.{self.name}"


#: Every family, in report order.
FAMILIES = (
    Family("geometry", "--peclet-backend", "pytest_peclet_make_backend", "peclet_backend",
           "peclet_verify.geometry.backend", "peclet_verify.geometry.suite",
           "an object with evaluate(node_ints, node_reals, root, points) (default: the "
           "reference engine)"),
    Family("mass", "--peclet-mass-backend", "pytest_peclet_make_mass_backend",
           "peclet_mass_backend", "peclet_verify.mass.backend", "peclet_verify.mass.suite",
           "an object with mass_properties(...), resolutions and order (default: peclet's "
           "quadrature)"),
    Family("dem", "--peclet-dem-backend", "pytest_peclet_make_dem_backend",
           "peclet_dem_backend", "peclet_verify.dem.backend", "peclet_verify.dem.suite",
           "an object with run(scenario, threads) (default: peclet.dem)"),
    Family("mechanics", "--peclet-dem-backend", "pytest_peclet_make_dem_backend",
           "peclet_dem_backend", "peclet_verify.mechanics.backend",
           "peclet_verify.mechanics.suite",
           "an object with run(scenario, threads) (default: peclet.dem)"),
    Family("impact", "--peclet-impact-backend", "pytest_peclet_make_impact_backend",
           "peclet_impact_backend", "peclet_verify.impact.backend",
           "peclet_verify.impact.suite",
           "an object with impact(case), model and capabilities (default: peclet.dem's "
           "Hertz law)"),
)
FAMILY_NAMES = tuple(f.name for f in FAMILIES)


def family(name: str) -> Family:
    """The family record named ``name`` (KeyError naming the families otherwise)."""
    for f in FAMILIES:
        if f.name == name:
            return f
    raise KeyError(f"no family {name!r}; registered: {', '.join(FAMILY_NAMES)}")


SCOPES = ("suite", "repo", "dem", "mass", "impact")

#: Worst-figure label -> (direction, compare factor, compare floor). Direction "max": larger
#: is worse; "min": smaller is worse. ``--peclet-compare`` fails a run when the figure's
#: badness (its value, negated for "min") exceeds factor x max(badness before, floor); the
#: floor keeps round-off (a slack of -1e-16 after 0.0) from counting. A property's reported
#: figure starts with its label (the quadrature adds the quantity and the tolerance).
FIGURES = {
    "min slack": ("min", 10.0, 1e-12),                # Equation 1: worst violation x10
    "sign disagreement rate": ("max", 1.0, 0.0),      # any disagreement is already a failure
    "max |phi_a - phi_b|": ("max", 10.0, 1e-14),      # distance agreement: worst x10
    "rel error": ("max", 10.0, 1e-12),                # quadrature, slide to roll: worst x10
    "distinct state hashes": ("max", 1.0, 1.0),       # determinism: more than one hash
    "differing contact sets": ("max", 1.0, 0.0),      # buffer growth: any
    "error / allowed": ("max", 1.0, 1.0),             # over 1 already fails
    "|ratio - e|": ("max", 10.0, 1e-12),              # binary restitution: worst x10
}


@dataclass(frozen=True)
class Certificate:
    """One certificate: ``key`` (how code refers to it), ``family`` (:data:`FAMILY_NAMES`),
    ``scope`` (:data:`SCOPES`), ``prop`` (the property it searches, the name of its
    :class:`~peclet_verify.search.PropertyResult`), ``title`` (its name in reports) and
    ``figure`` (its worst-figure label, a key of :data:`FIGURES`)."""

    key: str
    family: str
    scope: str
    prop: str
    title: str
    figure: str

    def __post_init__(self):
        if self.family not in FAMILY_NAMES or self.scope not in SCOPES or \
                self.figure not in FIGURES:
            raise ValueError(f"certificate {self.key!r}: family {self.family!r}, scope "
                             f"{self.scope!r} or figure {self.figure!r} is not registered")


def _c(*args):
    return Certificate(*args)


#: Every certificate, in report order.
CERTIFICATES = (
    _c("equation1_reference", "geometry", "suite", "equation1", "equation1 (reference rule)",
       "min slack"),
    _c("equation1_backend", "geometry", "suite", "equation1", "equation1 (backend claims)",
       "min slack"),
    _c("sign_paths", "geometry", "suite", "sign_agreement",
       "sign agreement (evaluation paths)", "sign disagreement rate"),
    _c("sign_same_solid", "geometry", "suite", "sign_agreement", "sign agreement (same solid)",
       "sign disagreement rate"),
    _c("distance_backend", "geometry", "suite", "distance_agreement",
       "distance agreement (backend vs reference)", "max |phi_a - phi_b|"),
    _c("distance_tree_walk", "geometry", "repo", "distance_agreement",
       "distance agreement (program vs tree walk)", "max |phi_a - phi_b|"),
    _c("quadrature", "mass", "repo", "quadrature_convergence",
       "quadrature convergence", "rel error"),
    _c("determinism", "dem", "repo", "determinism", "determinism (1 thread twice, 2 threads)",
       "distinct state hashes"),
    _c("buffer_growth", "dem", "repo", "buffer_growth", "buffer growth",
       "differing contact sets"),
    _c("dem_determinism_one_thread", "dem", "dem", "determinism_one_thread",
       "determinism at one thread (DEM backend)", "distinct state hashes"),
    _c("dem_determinism_across_threads", "dem", "dem", "determinism_across_threads",
       "determinism across threads (DEM backend)", "distinct state hashes"),
    _c("dem_buffer_growth", "dem", "dem", "buffer_growth", "buffer growth (DEM backend)",
       "differing contact sets"),
    _c("binary_restitution", "mechanics", "dem", "binary_restitution", "binary restitution",
       "|ratio - e|"),
    _c("slide_to_roll", "mechanics", "dem", "slide_to_roll", "slide to roll", "rel error"),
    _c("incline", "mechanics", "dem", "incline", "incline stick/slip", "error / allowed"),
    _c("free_rigid_body", "mechanics", "dem", "free_rigid_body", "free rigid body",
       "error / allowed"),
    _c("mass_closed_forms", "mass", "mass", "mass_properties",
       "mass properties (closed forms)", "error / allowed"),
    _c("grid_equation1", "geometry", "repo", "grid_equation1", "equation1 (grid leaves)",
       "min slack"),
    _c("grid_sign", "geometry", "repo", "grid_sign", "sign agreement (grid leaf vs source)",
       "sign disagreement rate"),
    _c("grid_mass", "mass", "repo", "grid_mass", "mass properties (grid leaf vs mesh)",
       "error / allowed"),
) + tuple(
    _c(f"chung_ooi_{n}", "impact", "impact", f"chung_ooi_{n}", f"Chung & Ooi {n}: {what}",
       "|ratio - e|" if n == 3 else "rel error")
    for n, what in ((1, "elastic sphere-sphere"), (2, "elastic sphere-plane"),
                    (3, "restitution over e and speed"), (4, "oblique, constant speed"),
                    (5, "oblique, constant normal speed"), (6, "spin on a plane"),
                    (7, "two spinning spheres"), (8, "unequal spinning spheres")))

_BY_KEY = {c.key: c for c in CERTIFICATES}
_FIGURE_OF_PROP = {}
for _cert in CERTIFICATES:
    if _FIGURE_OF_PROP.setdefault(_cert.prop, _cert.figure) != _cert.figure:
        raise ValueError(f"property {_cert.prop!r} is registered with two figures")
if len(_BY_KEY) != len(CERTIFICATES) or \
        len({c.title for c in CERTIFICATES}) != len(CERTIFICATES):
    raise ValueError("certificate keys and titles must be unique")


def certificate(key: str) -> Certificate:
    """The certificate registered under ``key`` (KeyError naming the known keys otherwise)."""
    try:
        return _BY_KEY[key]
    except KeyError:
        raise KeyError(f"no certificate {key!r}; registered: {', '.join(_BY_KEY)}") from None


def title(key: str) -> str:
    """The report name of certificate ``key``."""
    return certificate(key).title


def titles(scope=None, family=None) -> tuple:
    """Titles of the certificates of ``scope`` and/or ``family`` (all by default), in order."""
    return tuple(c.title for c in CERTIFICATES
                 if scope in (None, c.scope) and family in (None, c.family))


def properties(scope=None, family=None) -> tuple:
    """Property ids of the certificates of ``scope`` and/or ``family``, each once, in order."""
    return tuple(dict.fromkeys(c.prop for c in CERTIFICATES
                               if scope in (None, c.scope) and family in (None, c.family)))


def figure(prop: str) -> str:
    """The worst-figure label of property ``prop`` (one per property)."""
    try:
        return _FIGURE_OF_PROP[prop]
    except KeyError:
        raise KeyError(f"no property {prop!r}; registered: {', '.join(_FIGURE_OF_PROP)}") \
            from None


def known_names() -> frozenset:
    """Every name an xfails file may use: a certificate's title, or a property id (all the
    certificates of that property)."""
    return frozenset(titles() + properties())
