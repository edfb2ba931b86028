"""The DEM family: determinism (at one thread, across threads, across fresh processes) and
contact-buffer growth, of peclet's engine and of any DEM engine (``backend``, ``strategies``,
``properties``, ``buffers``, ``suite``; children ``child``, ``wheel_child``)."""
