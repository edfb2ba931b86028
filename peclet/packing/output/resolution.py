"""What an export's ``resolution`` may ask and what a bed may weigh: :class:`Resolution`,
:func:`parse_resolution`, :func:`check_bed_triangles` and their bounds (the notes of
:mod:`peclet.packing.output.export` state the forms: ``"Ntri"`` a triangle budget per element,
``"0.01"`` / ``"0.01D"`` a chord error in element diameters D)."""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

from peclet.core.validation import PecletArgumentError

__all__ = ["Resolution", "parse_resolution", "check_bed_triangles", "DEFAULT_RESOLUTION",
           "RESOLUTION_HELP", "MIN_ELEMENT_TRIANGLES", "MAX_ELEMENT_TRIANGLES", "CHORD_MIN",
           "CHORD_MAX", "MAX_BED_TRIANGLES"]

#: The export resolution when none is given: 1000 triangles per element (1000 Pall rings:
#: STL 50 MB, VTU about 23 MB).
DEFAULT_RESOLUTION = "1000tri"

#: Triangle budgets accepted per element. A budget below what keeps the element closed with
#: its topology gives the fewest triangles that do (a Pall ring: 388); above the maximum one
#: element alone is 10 MB of binary STL.
MIN_ELEMENT_TRIANGLES = 100
MAX_ELEMENT_TRIANGLES = 200_000

#: Chord errors accepted, in element diameters D. CHORD_MIN comes from memory: the lattice
#: (spacing at most the chord error) of an element of bounding radius up to 1.2 D then fits
#: in :data:`~peclet.packing.output.meshing.EXPORT_LATTICE_MAX` points per axis.
CHORD_MIN = 0.005
CHORD_MAX = 0.1

#: Largest bed (triangles in all, container included) written as VTU: meshio assembles the
#: whole bed in memory, about 150 bytes a triangle at its peak (3 GB here).
MAX_BED_TRIANGLES = 20_000_000

#: What ``resolution`` accepts, for error messages and command-line help.
RESOLUTION_HELP = (f"a chord error in element diameters D in [{CHORD_MIN:g}, {CHORD_MAX:g}] "
                   f"(e.g. 0.01 or 0.01D) or a triangle budget per element 'Ntri' with N an "
                   f"integer in [{MIN_ELEMENT_TRIANGLES}, {MAX_ELEMENT_TRIANGLES}] "
                   f"(e.g. 2000tri)")


@dataclass(frozen=True)
class Resolution:
    """A parsed export resolution: ``kind`` "triangles" (``value`` the budget per element, an
    int) or "chord" (``value`` the chord error in element diameters D). ``str()`` is the
    canonical text (``"1000tri"``, ``"0.01D"``)."""

    kind: str
    value: float

    def __str__(self):
        return f"{int(self.value)}tri" if self.kind == "triangles" else f"{self.value:g}D"


def parse_resolution(value, name="resolution"):
    """A :class:`Resolution` from ``value``: text ``"Ntri"`` (a triangle budget per element) or
    ``"0.01"`` / ``"0.01D"`` (a chord error in D), a number (a chord error in D) or a
    :class:`Resolution`. Refused (:class:`PecletArgumentError` naming ``name``): anything else,
    a budget outside [:data:`MIN_ELEMENT_TRIANGLES`, :data:`MAX_ELEMENT_TRIANGLES`], a chord
    error outside [:data:`CHORD_MIN`, :data:`CHORD_MAX`] (NaN, zero and negatives included;
    below CHORD_MIN the lattice would not fit in memory)."""
    if isinstance(value, Resolution):
        value = str(value)
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (str, numbers.Real)):
        raise PecletArgumentError(name, RESOLUTION_HELP, value)
    if isinstance(value, str):
        text = value.strip().lower()
        if text.endswith("tri"):
            try:
                n = int(text[:-3])
            except ValueError:
                raise PecletArgumentError(name, RESOLUTION_HELP, value) from None
            if not MIN_ELEMENT_TRIANGLES <= n <= MAX_ELEMENT_TRIANGLES:
                raise PecletArgumentError(name, RESOLUTION_HELP, value,
                                          "triangle budget out of range")
            return Resolution("triangles", n)
        try:
            eps = float(text[:-1] if text.endswith("d") else text)
        except ValueError:
            raise PecletArgumentError(name, RESOLUTION_HELP, value) from None
    else:
        eps = float(value)
    if not (math.isfinite(eps) and CHORD_MIN <= eps <= CHORD_MAX):
        detail = "finer than memory allows" if math.isfinite(eps) and 0 < eps < CHORD_MIN \
            else "chord error out of range"
        raise PecletArgumentError(name, RESOLUTION_HELP, value, detail)
    return Resolution("chord", eps)


def check_bed_triangles(n_elements, resolution, name="resolution", per_element=None):
    """Refuse (naming ``name``) a bed whose VTU would exceed :data:`MAX_BED_TRIANGLES`:
    ``n_elements`` elements of ``per_element`` triangles, by default the budget of
    ``resolution`` (a chord error passes then: its count is known once meshed, see
    :func:`~peclet.packing.output.meshing.export_mesh`'s ``info``). Returns the parsed
    :class:`Resolution`."""
    r = parse_resolution(resolution, name)
    per = r.value if per_element is None and r.kind == "triangles" else per_element
    if per is not None and int(n_elements) * int(per) > MAX_BED_TRIANGLES:
        raise PecletArgumentError(name, f"at most {MAX_BED_TRIANGLES} triangles for the whole "
                                  f"bed (the VTU is assembled in memory)", str(r),
                                  f"{int(n_elements)} elements x {int(per)} triangles")
    return r
