"""What this machine can hold: its physical memory, and the one check every long job makes of
its estimated memory before it starts (issue 45: a job is refused up front, with its estimate,
rather than failing with a raw MemoryError after it has run for a while)."""
from __future__ import annotations

import os

from .validation import PecletArgumentError

#: A job may plan to use at most this fraction of the physical memory: the rest is the
#: operating system's, the interpreter's and whatever else runs beside it.
MEMORY_FRACTION = 0.5


def physical_memory():
    """Bytes of physical memory (None where the OS does not say)."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return None


def check_memory(name, value, need, what):
    """Refuse (PecletArgumentError naming the user's ``name``, whose value is ``value``) a job
    estimated to need ``need`` bytes when that exceeds :data:`MEMORY_FRACTION` of the physical
    memory; ``what`` says what the estimate is of (e.g. "a 512 x 90 x 512 lattice at 512 B a
    cell"). Nothing is refused where the memory cannot be told."""
    mem = physical_memory()
    if mem is None or need <= MEMORY_FRACTION * mem:
        return
    raise PecletArgumentError(
        name, f"a value whose job fits in {MEMORY_FRACTION:g} of this machine's "
        f"{mem / 2 ** 30:.1f} GiB", value, f"{what}: about {need / 2 ** 30:.3g} GiB")
