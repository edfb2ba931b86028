"""Contact material of a pack: restitution and friction (element-element or element-wall).

:class:`Material` is :class:`peclet.dem.materials.Material` (one type in the whole package);
this module adds :func:`as_material`, the packing layer's reader of user input.
"""
from __future__ import annotations

from peclet.core.validation import PecletArgumentError
from peclet.dem.materials import Material

__all__ = ["Material", "as_material"]


# one Material type in the whole package: the DEM's (page defaults e_n 0.15, e_t 0, mu 0.5)


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
