"""Shared fixtures of the tracked benchmarks (pytest-benchmark): the page's ring, built once."""
import pytest


@pytest.fixture(scope="session")
def page_ring():
    from peclet.packing.bed import elements

    return elements.pall_ring()


@pytest.fixture(scope="session")
def page_particle(page_ring):
    from peclet.dem import scene_particle

    b, root = page_ring
    return scene_particle.build(b, root, bounds=page_ring.bounds, n=32, shell_resolution=112,
                                target_shell_points=1200)
