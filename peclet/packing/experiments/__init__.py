"""Runs beyond a pour: the rotating drum (``drum``), the stirred column (``stir``), growth to
jamming (``grow``) and the turning-wall phase loop and ParaView series they share
(``series``)."""
