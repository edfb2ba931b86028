"""Bad arguments to the validation scripts (``python validation/<script>.py``): one line
``<script>: error: argument <flag>: must be ...`` naming the flag and the accepted range,
exit code 2, no traceback, before any work (a full run takes minutes: a check that let one
through would hit the timeout here instead of passing). The scripts share the argument
handling of ``validation/__init__.py``; its types are also tested in-process below."""
import argparse
import os
import subprocess
import sys

import numba
import pytest

import validation as vargs
from peclet.core.validation import PecletArgumentError

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CAP = int(numba.config.NUMBA_NUM_THREADS)

CASES = [
    # (script, argv, the flag named, a phrase of the accepted range)
    ("drum", ["--workers", "0"], "--workers", "[1, 64]"),
    ("drum", ["--workers", "abc"], "--workers", "an integer in [1, 64]"),
    ("drum", ["--json", "/nonexistent/dir/x.json"], "--json", "an existing, writable directory"),
    ("silo", ["--workers", "0"], "--workers", "[1, 64]"),
    ("silo", ["--orifices", "5,1"], "--orifices", "each in (1.5, 100]"),
    ("silo", ["--window", "nan"], "--window", "a finite number in [0.5, 100]"),
    ("silo", ["--json", "/nonexistent/dir/x.json"], "--json", "an existing, writable directory"),
    ("haff", ["--count", "0"], "--count", "[100, 1e+06]"),
    ("haff", ["--e", "1"], "--e", "[0, 1)"),
    ("grow", ["--counts", "100,abc"], "--counts", "each in [2, 100000]"),
    ("grow", ["--rings", "-1"], "--rings", "[0, 100000]"),
    ("chung_ooi", ["--threads", "0"], "--threads", f"[1, {CAP}]"),
    ("chung_ooi", ["--steps", "10"], "--steps", "[50, 1e+07]"),
    ("chung_ooi", ["--tests", "9"], "--tests", "1-8"),
    ("sanity", ["--threads", "abc"], "--threads", f"[1, {CAP}]"),
    ("sanity", ["--json", "/nonexistent/dir/x.json"], "--json", "does not exist"),
    ("thickness", ["--workers", "0"], "--workers", "[1, 64]"),
    ("spheres", ["--out", "/nonexistent/dir/x.json"], "--out", "does not exist"),
    ("flow", ["--page-pack", "/nonexistent/pack.npz"], "--page-pack", "an existing"),
    ("bean", ["--count", "-1"], "--count", "[0, 100000]"),
    ("bean", ["--spacings", "0.04,1"], "--spacings", "each in [0.002, 0.2]"),
    ("bean", ["--grown", "/nonexistent/results.json"], "--grown", "does not exist"),
]


@pytest.mark.parametrize("script,argv,flag,phrase", CASES,
                         ids=[f"{c[0]} {' '.join(c[1])}" for c in CASES])
def test_a_bad_argument_is_one_line_and_exit_code_2(tmp_path, script, argv, flag, phrase):
    p = subprocess.run([sys.executable, os.path.join(ROOT, "validation", f"{script}.py")]
                       + argv, capture_output=True, text=True, timeout=180, cwd=tmp_path)
    err = p.stderr.strip().splitlines()
    assert p.returncode == 2, (p.returncode, p.stderr[-2000:])
    assert "Traceback" not in p.stderr
    assert len(err) == 1, err
    assert err[0].startswith(f"{script}.py: error: argument {flag}: must be"), err
    assert phrase in err[0], err
    assert p.stdout == ""                           # no work started
    assert os.listdir(tmp_path) == []


def _refusal(conv, text):
    with pytest.raises(argparse.ArgumentTypeError) as ex:
        conv(text)
    return str(ex.value)


def test_the_shared_types_accept_the_range_and_name_it_when_refusing(tmp_path):
    assert vargs.integer(1, 64)("3") == 3 and vargs.integer(1, 64)("64.0") == 64
    for bad in ("0", "65", "2.5", "abc", "nan", "inf", ""):
        assert "an integer in [1, 64]" in _refusal(vargs.integer(1, 64), bad)
    assert vargs.real(0.0, 1.0, hi_open=True)("0") == 0.0
    for bad in ("1", "-0.1", "nan", "x"):
        assert "[0, 1)" in _refusal(vargs.real(0.0, 1.0, hi_open=True), bad)
    assert vargs.real_list(1.5, 100.0, lo_open=True)("5, 6,7") == (5.0, 6.0, 7.0)
    for bad in ("1.5,6", ",", "5;6"):
        assert "(1.5, 100]" in _refusal(vargs.real_list(1.5, 100.0, lo_open=True), bad)
    assert vargs.integer_list(2, 10)("2,10") == (2, 10)
    assert "each in [2, 10]" in _refusal(vargs.integer_list(2, 10), "2,11")
    assert vargs.threads(str(CAP)) == CAP
    assert "NUMBA_NUM_THREADS" in _refusal(vargs.threads, str(CAP + 1))
    # an output file: in an existing, writable directory, not a directory, not under a file
    ok = str(tmp_path / "x.json")
    assert vargs.output_file(ok) == ok
    assert "it is a directory" in _refusal(vargs.output_file, str(tmp_path))
    (tmp_path / "f").write_text("")
    assert "is a file" in _refusal(vargs.output_file, str(tmp_path / "f" / "x.json"))
    assert "does not exist" in _refusal(vargs.output_file, str(tmp_path / "no" / "x.json"))
    assert vargs.input_file(str(tmp_path / "f")) == str(tmp_path / "f")
    assert "it is not a file" in _refusal(vargs.input_file, str(tmp_path))


def test_run_turns_a_late_argument_error_into_one_line(capsys):
    def main(argv):
        raise PecletArgumentError("window", "a fill taller than the head + start-up", 0.5)

    assert vargs.run(main) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].endswith("error: window must be a fill taller than the "
                                             "head + start-up, got 0.5"), err
    assert vargs.run(lambda argv: 0) == 0
