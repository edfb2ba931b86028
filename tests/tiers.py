"""The heavy tier (conftest.py: --tier) for some values of a parametrized test."""
import pytest


def heavy_params(values, *heavy):
    """``values`` as parameters, those in ``heavy`` marked for the heavy tier."""
    return [pytest.param(v, marks=pytest.mark.heavy) if v in heavy else v for v in values]
