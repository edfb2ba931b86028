"""peclet.core: the geometry layer (CSG trees, evaluation, certificate, quadrature)."""
