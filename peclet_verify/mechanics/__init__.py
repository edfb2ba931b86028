"""The mechanics family: closed-form mechanics of any DEM engine (binary restitution, slide to
roll, incline stick/slip, the free rigid body) (``backend``: the DEM family's engine,
``strategies``, ``properties``, ``suite``)."""
