"""Repository-wide pytest configuration (the peclet_verify plugin loads via its entry point)."""
import subprocess
import sys

import pytest

pytest_plugins = ["pytester"]


@pytest.fixture(scope="session")
def peclet_geom_python(tmp_path_factory):
    """The interpreter of a fresh venv holding the upstream ``peclet-geom`` wheel (it ships a
    ``peclet`` namespace that must not meet ours); built once per session, skipped with the
    installer's reason when the wheel cannot be installed from the package index."""
    venv = tmp_path_factory.mktemp("peclet-geom-venv")
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=300)
    py = str(venv / "bin" / "python")
    proc = subprocess.run([py, "-m", "pip", "install", "-q", "peclet-geom"],
                          capture_output=True, text=True, timeout=600)
    if proc.returncode != 0:
        pytest.skip(f"peclet-geom could not be installed from the package index: "
                    f"{proc.stderr.strip()[-300:]}")
    return py
