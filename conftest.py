"""Repository-wide pytest configuration (the peclet_verify plugin loads via its entry point)."""
pytest_plugins = ["pytester"]
