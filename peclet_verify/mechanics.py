"""The DEM certificates' names as first published here (one import for a test module):
properties from :mod:`peclet_verify.properties.dem` and :mod:`peclet_verify.properties.mechanics`,
cases and strategies from :mod:`peclet_verify.strategies.dem` and
:mod:`peclet_verify.strategies.mechanics`. ``buffer_growth`` here is the DEM-backend one
(:func:`peclet_verify.properties.dem.dem_buffer_growth`)."""
from .properties.core import NOT_CLAIMED
from .properties.dem import (dem_buffer_growth as buffer_growth, determinism_across_threads,
                             determinism_one_thread, run_checked, trajectory_hash)
from .properties.mechanics import binary_restitution, free_rigid_body, incline, slide_to_roll
from .strategies.dem import G, Pour, capacity_hints, pour_scenario, pours
from .strategies.mechanics import (Collision, Incline, Roll, Rotor, collisions, cube_shell,
                                   inclines, rolls, rotors)

__all__ = ["NOT_CLAIMED", "Pour", "pours", "pour_scenario", "determinism_one_thread",
           "determinism_across_threads", "buffer_growth", "capacity_hints",
           "Collision", "collisions", "binary_restitution", "Roll", "rolls", "slide_to_roll",
           "Incline", "inclines", "incline", "Rotor", "rotors", "free_rigid_body", "G",
           "run_checked", "trajectory_hash", "cube_shell"]
