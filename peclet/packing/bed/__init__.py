"""The bed: elements, containers, materials, deposition protocols (one base; the page's, rain),
:func:`~peclet.packing.bed.api.pack` / ``resume`` (any element into any container), the pour,
the frozen :class:`~peclet.packing.bed.freeze.Pack`, progress bars, thread counts and the run
checkpoints shared with the drum (:mod:`~peclet.packing.bed.checkpoint`)."""
