"""Compiled kernels from older sources are dropped at ``import peclet`` (peclet.core.jitcache).

Numba checks a cached kernel against its own file only: ``solver.world_inv_inertias`` keeps the
machine code of ``rigid.world_inv_inertia`` (another module) in its cache entry, so after an
edit of rigid.py alone it would go on returning the old tensor. Each test works on a copy of the
package in a temporary directory, in fresh interpreters, with its own Numba cache directory."""
import os
import shutil
import subprocess
import sys

import peclet

_RUN = ("import numpy as np, peclet.dem.solver as s;"
        "print(repr(float(s.world_inv_inertias(np.array([[0.0, 0.0, 0.0, 1.0]]),"
        " np.array([[1.0, 2.0, 3.0]]))[0, 1, 1])))")


def _copy(tmp_path):
    src = os.path.dirname(peclet.__file__)
    dst = tmp_path / "src" / "peclet"
    shutil.copytree(src, dst, ignore=shutil.ignore_patterns("__pycache__"))
    return dst


def _python(tmp_path, code):
    env = dict(os.environ, PYTHONPATH=str(tmp_path / "src"),
               NUMBA_CACHE_DIR=str(tmp_path / "numba"), PYTHONDONTWRITEBYTECODE="1")
    r = subprocess.run([sys.executable, "-c", code], env=env, cwd=tmp_path,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    return r.stdout.strip().splitlines()


def test_an_edited_callee_is_not_run_from_a_callers_stale_cache(tmp_path):
    pkg = _copy(tmp_path)
    check = "import peclet; print(peclet.__file__)"
    assert _python(tmp_path, check)[0].startswith(str(tmp_path))
    assert _python(tmp_path, _RUN) == ["2.0"]          # compiled and cached
    rigid = pkg / "dem" / "rigid.py"
    text = rigid.read_text()
    edited = text.replace("s += R[i, k] * inv_inertia_body[k] * R[j, k]",
                          "s += 10.0 * R[i, k] * inv_inertia_body[k] * R[j, k]")
    assert edited != text
    rigid.write_text(edited)
    # the caller's file (solver.py) is unchanged, so Numba alone would load its old entry
    assert _python(tmp_path, _RUN) == ["20.0"]


def test_unchanged_sources_keep_their_kernels_and_a_foreign_stamp_drops_them(tmp_path):
    _copy(tmp_path)
    probe = ("import os, peclet; from peclet.core import jitcache as j;"
             "r = os.path.dirname(peclet.__file__);"
             "c = {j._cache_dir(d) for d, _, _ in os.walk(r)} - {None};"
             "print(sum(n.endswith(('.nbi', '.nbc')) for x in c for n in os.listdir(x)));"
             "print(os.path.join(j._cache_dir(r), j.STAMP_FILE))")
    _python(tmp_path, _RUN)
    kept, stamp = _python(tmp_path, probe)
    assert int(kept) > 0
    assert _python(tmp_path, probe)[0] == kept         # nothing dropped on a second import
    with open(stamp, "w") as fh:
        fh.write("another peclet")
    assert _python(tmp_path, probe)[0] == "0"          # a stamp that differs: all dropped
    with open(stamp) as fh:
        assert fh.read() != "another peclet"
