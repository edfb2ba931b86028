"""Certification of a DEM engine through the page's API (peclet.dem unless
``--peclet-dem-backend`` names another): determinism at one thread and across threads,
contact-buffer growth, and the closed-form mechanics. The same certificates a downstream
project imports (:mod:`peclet_verify.dem.suite`, :mod:`peclet_verify.mechanics.suite`)."""
from peclet_verify.dem.suite import *  # noqa: F401,F403
from peclet_verify.mechanics.suite import *  # noqa: F401,F403
