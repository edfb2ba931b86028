"""pytest plugin: ``--peclet-certify`` turns on tests marked ``peclet_certify``."""
import pytest


def pytest_addoption(parser):
    group = parser.getgroup("peclet", "peclet certification")
    group.addoption("--peclet-certify", action="store_true", default=False,
                    help="run the peclet certification properties (marker peclet_certify)")


def pytest_configure(config):
    config.addinivalue_line("markers", "peclet_certify: a certification property; runs only "
                                       "with --peclet-certify")


def pytest_collection_modifyitems(config, items):
    if config.getoption("--peclet-certify"):
        return
    skip = pytest.mark.skip(reason="certification property: run with --peclet-certify")
    for item in items:
        if "peclet_certify" in item.keywords:
            item.add_marker(skip)
