"""The mass-property family: peclet's quadrature under refinement and any mass-property engine
against the closed forms of the leaf table, at its declared order (``backend``,
``strategies``, ``properties``, ``suite``; children ``child``, ``wheel_child``)."""
