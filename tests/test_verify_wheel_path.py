"""A wheel child imports the wheel's ``peclet`` even when PYTHONPATH names our tree.

The upstream wheels install a package named ``peclet`` as we do; with ``PYTHONPATH`` pointing
at a clone of this project, a child adapter used to import our engine and certify it under the
wheel's name. Here a stand-in clone (``peclet`` and ``peclet_verify`` side by side) and a
stand-in wheel (``peclet`` alone, carrying a marker) are both on PYTHONPATH, clone first, and a
real interpreter (``-S``: no site-packages, so no install of ours interferes) runs the child's
start-up lines.
"""
import ast
import os
import subprocess
import sys

import peclet_verify

HERE = os.path.dirname(os.path.abspath(peclet_verify.__file__))

# the start-up of a wheel child (geometry/wheel_child.py), then the import it exists for
CHILD = f"""
import os, sys
sys.path.insert(0, {HERE!r})
import wheel_path
dropped = wheel_path.drop_this_project() if sys.argv[1] == "drop" else []
import peclet
print(getattr(peclet, "WHICH", "ours"), len(dropped))
"""


def _tree(root):
    clone, wheel = root / "clone", root / "wheel"
    for pkg in (clone / "peclet", clone / "peclet_verify", wheel / "peclet"):
        pkg.mkdir(parents=True)
        (pkg / "__init__.py").write_text("")
    (wheel / "peclet" / "__init__.py").write_text("WHICH = 'wheel'\n")
    return clone, wheel


def _run(tmp_path, mode):
    clone, wheel = _tree(tmp_path / mode)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(clone), str(wheel)]))
    out = subprocess.run([sys.executable, "-S", "-c", CHILD, mode], env=env, cwd=tmp_path,
                         capture_output=True, text=True, timeout=60, check=True)
    return out.stdout.split()


def test_without_the_rule_the_clone_shadows_the_wheel(tmp_path):
    assert _run(tmp_path, "keep") == ["ours", "0"]


def test_the_child_drops_our_tree_and_imports_the_wheel(tmp_path):
    assert _run(tmp_path, "drop") == ["wheel", "1"]


def test_every_wheel_child_applies_the_rule_before_importing_peclet():
    for name in ("geometry/wheel_child.py", "mass/wheel_child.py", "dem/wheel_child.py"):
        tree = ast.parse(open(os.path.join(HERE, name)).read())
        calls = [n.lineno for n in tree.body if isinstance(n, ast.Expr)
                 and ast.unparse(n.value) == "wheel_path.drop_this_project()"]
        imports = [n.lineno for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)
                   and (n.module or "").split(".")[0] == "peclet"]
        assert len(calls) == 1 and all(calls[0] < line for line in imports), name
