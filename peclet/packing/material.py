"""Contact material of a pack: restitution and friction (element-element or element-wall)."""
from __future__ import annotations

from dataclasses import asdict, dataclass

from peclet.core.validation import PecletArgumentError, check_float

__all__ = ["Material", "as_material"]


@dataclass(frozen=True)
class Material:
    """Contact material (dimensionless).

    e_n: normal restitution in [0, 1]; e_t: tangential (Walton) restitution in [-1, 1] (the
    DEM's ``set_material_params``); mu: Coulomb friction >= 0. For a wall only e_n and mu are
    used (the DEM's walls carry no tangential restitution). The defaults are the page's.
    """

    e_n: float = 0.15
    e_t: float = 0.0
    mu: float = 0.5

    def __post_init__(self):
        object.__setattr__(self, "e_n", check_float("e_n", self.e_n, 0.0, 1.0))
        object.__setattr__(self, "e_t", check_float("e_t", self.e_t, -1.0, 1.0))
        object.__setattr__(self, "mu", check_float("mu", self.mu, 0.0))

    def as_tuple(self):
        """(e_n, e_t, mu), the order of ``Simulation.set_material_params``."""
        return (self.e_n, self.e_t, self.mu)

    def to_dict(self):
        return asdict(self)


def as_material(value, name="material"):
    """A :class:`Material` from a Material, a dict of its fields or an (e_n, e_t, mu) triple."""
    if isinstance(value, Material):
        return value
    try:
        if isinstance(value, dict):
            return Material(**value)
        if isinstance(value, (tuple, list)) and len(value) == 3:
            return Material(*value)
    except PecletArgumentError as exc:
        raise PecletArgumentError(f"{name}.{exc.argument}", str(exc).split(" must be ", 1)[1]
                                  .rsplit(", got", 1)[0], exc.value) from None
    except TypeError:
        pass
    raise PecletArgumentError(name, "a Material, a dict (e_n, e_t, mu) or a triple", value)
