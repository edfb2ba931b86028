"""Figures leave the user's matplotlib backend alone (peclet.core.figures): every figure is a
Figure on its own Agg canvas; nothing calls ``matplotlib.use`` or imports ``pyplot``."""
import ast
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

_CHILD = r"""
import math, os, sys, tempfile
import matplotlib
matplotlib.use("svg")                      # the user's choice, not Agg
before = matplotlib.get_backend()
from peclet.core.figures import new_figure, save_png, subplots
from peclet.packing.experiments import drum_output, grow, stir
from peclet.ensemble import summary
d = tempfile.mkdtemp()
samples = [dict(phase=p, revolutions=0.1 * i, angle=30.0 + i) for i, p in
           enumerate(["warmup", "measure", "measure"])]
drum_output._angle_figure(os.path.join(d, "angle.png"), samples,
                          dict(angle=dict(mean=31.5), froude=0.01, regime="rolling"))
stir._lacey_figure(os.path.join(d, "lacey.png"),
                   dict(samples=[dict(revolutions=0.0, lacey=0.0),
                                 dict(revolutions=1.0, lacey=0.8)], grains=10,
                        spec=dict(omega=1.5), lacey_start=0.0, lacey_end=0.8))
grow._figure(os.path.join(d, "grow.png"),
             dict(history=[dict(t=0.0, phi=0.2), dict(t=1.0, phi=0.6)], count=10,
                  element="sphere", phi=0.6, z_mean=6.0, g_r=[1.0, 1.1], g=[3.0, 1.0],
                  g_peak=3.0, g_peak_r=1.0))
fig, ax = subplots(figsize=(2, 2))
ax.plot([0, 1], [0, 1])
save_png(fig, os.path.join(d, "line.png"), dpi=50)
new_figure((1, 1))
sizes = [os.path.getsize(os.path.join(d, f)) for f in ("angle.png", "lacey.png", "grow.png",
                                                       "line.png")]
with open(os.path.join(d, "angle.png"), "rb") as fh:
    png = fh.read(8) == b"\x89PNG\r\n\x1a\n"
print(before, matplotlib.get_backend(), "matplotlib.pyplot" in sys.modules, png,
      min(sizes) > 0)
"""


def test_figures_leave_the_users_backend_unchanged():
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    env.pop("MPLBACKEND", None)
    r = subprocess.run([sys.executable, "-c", _CHILD], capture_output=True, text=True, env=env,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    before, after, pyplot, png, written = r.stdout.split()
    assert before == "svg" and after == before        # the user's backend, unchanged
    assert pyplot == "False"                          # pyplot never imported
    assert png == "True" and written == "True"


def test_no_module_switches_the_backend_or_uses_pyplot():
    """Static: no peclet module calls matplotlib.use / pyplot.switch_backend or imports
    pyplot (figures go through peclet.core.figures)."""
    found = []
    for top in ("peclet",):
        for root, _, files in os.walk(os.path.join(ROOT, top)):
            for f in files:
                if not f.endswith(".py"):
                    continue
                path = os.path.join(root, f)
                with open(path) as fh:
                    tree = ast.parse(fh.read())
                for node in ast.walk(tree):
                    if isinstance(node, ast.Attribute) and node.attr in ("use",
                                                                         "switch_backend"):
                        if isinstance(node.value, ast.Name) and node.value.id in (
                                "matplotlib", "plt", "pyplot"):
                            found.append(f"{path}:{node.lineno}")
                    if isinstance(node, ast.ImportFrom) and node.module and \
                            "pyplot" in node.module:
                        found.append(f"{path}:{node.lineno}")
                    if isinstance(node, ast.Import) and any("pyplot" in a.name
                                                            for a in node.names):
                        found.append(f"{path}:{node.lineno}")
    assert not found, found
