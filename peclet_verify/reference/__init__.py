"""Reference oracles: slow, obviously-correct computations that the engine is certified against.

Shipped (not test-only) because downstream certification uses them too. One module each:
``rotor`` (torque-free rigid-body references), ``contacts`` (brute-force contact sets),
``tree_walk`` (recursive evaluation of the flat encoding, node by node).
"""
