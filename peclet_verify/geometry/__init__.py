"""The geometry family: Equation 1 (the certified bounding ball), sign agreement between
evaluation paths and distance agreement of any engine that evaluates the flat encoding of
docs/architecture.md §2 (``backend``, ``recipes``, ``strategies``, ``answers``,
``properties``, ``suite``; children ``child``, ``wheel_child``)."""
