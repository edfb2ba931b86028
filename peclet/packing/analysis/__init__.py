"""Measuring a frozen pack: cover fractions, overlaps and the wall sweep on the exact trees
(``geometry``), coordination from the engine's contacts (``coordination``), radial and axial
column profiles (``profiles``)."""
