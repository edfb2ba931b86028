"""peclet_verify: the certifier of peclet, and of any engine plugged in as a backend.

One subpackage per certificate family (``geometry``, ``mass``, ``dem``, ``mechanics``), each
with its ``backend``, ``strategies``, ``properties`` and ``suite`` modules; the families are
registered in :mod:`peclet_verify.registry` and driven by the pytest plugin
(:mod:`peclet_verify.plugin`). Shared machinery at the top: :mod:`~peclet_verify.search`,
:mod:`~peclet_verify.profiles`, :mod:`~peclet_verify.report`, :mod:`~peclet_verify.wire`,
:mod:`~peclet_verify.scenario`, :mod:`~peclet_verify.processes`,
:mod:`~peclet_verify.loading`, :mod:`~peclet_verify.fixtures`. See docs/architecture.md §12.
Importing this package imports nothing.
"""
