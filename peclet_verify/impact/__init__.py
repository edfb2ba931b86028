"""The impact family: the Chung & Ooi (2011) single-contact benchmarks as certificates of any
engine with a Hertz or linear contact law (cases, closed forms, backend protocol, strategies,
properties, suite)."""
