"""Bad input to the verification API and the plugin: each case a clear error naming the
argument or the file (or a documented acceptance), raised before any expensive work."""
import json
import sys
import time

import numpy as np
import pytest

from peclet.core.validation import PecletArgumentError
from peclet_verify import planted
from peclet_verify import report as R
from peclet_verify.geometry.answers import ask, ask_bound
from peclet_verify.geometry.backend import SubprocessBackend, load_backend
from peclet_verify.loading import parse_backend_spec
from peclet_verify.profiles import make_settings


# ---------------------------------------------------------------------- backend specs
@pytest.mark.parametrize("spec, says", [
    (5, "'module:factory'"),
    ("a:b:c", "'module:factory'"),
    ("nocolon", "'module:factory'"),
    ("mod:", "'module:factory'"),
    ("bad-name:f", "'module:factory'"),
    ("no_such_module_xyz:f", "cannot import module 'no_such_module_xyz'"),
    ("math:no_such_factory", "math has no callable 'no_such_factory'"),
    ("math:pi", "math has no callable 'pi'"),
    ("peclet_verify.planted:BadAnswerBackend", "BadAnswerBackend() raised TypeError"),
    ("builtins:object", "has none"),  # an object without evaluate
])
def test_load_backend_refuses(spec, says):
    with pytest.raises(ValueError) as exc:
        load_backend(spec)
    assert says in str(exc.value)


@pytest.mark.parametrize("spec", [None, "", "reference"])
def test_reference_specs_are_accepted(spec):
    assert parse_backend_spec(spec) is None
    assert load_backend(spec).name == "peclet-reference"


# ---------------------------------------------------------------------- SubprocessBackend
@pytest.mark.parametrize("kwargs, argument", [
    (dict(cmd="python -c pass"), "cmd"),
    (dict(cmd=[]), "cmd"),
    (dict(cmd=[sys.executable, 3]), "cmd"),
    (dict(cmd=["/no/such/program-h3"]), "cmd"),
    (dict(cmd=[sys.executable], timeout=0), "timeout"),
    (dict(cmd=[sys.executable], timeout="5"), "timeout"),
    (dict(cmd=[sys.executable], timeout=float("nan")), "timeout"),
    (dict(cmd=[sys.executable], timeout=True), "timeout"),
    (dict(cmd=[sys.executable], name=5), "name"),
])
def test_subprocess_backend_argument_errors(kwargs, argument):
    with pytest.raises(PecletArgumentError) as exc:
        SubprocessBackend(**kwargs)
    assert str(exc.value).startswith(argument + " must be")


def test_subprocess_backend_times_out_on_a_silent_child_and_names_it():
    start = time.monotonic()
    with pytest.raises(TimeoutError) as exc:
        SubprocessBackend([sys.executable, "-c", "import time; time.sleep(120)"],
                          name="silent-child", timeout=1.0)
    assert time.monotonic() - start < 30
    assert "silent-child" in str(exc.value) and "1 s" in str(exc.value)


STOPS_READING = """
import sys, time
import numpy as np
from peclet_verify import wire
wire.read_message(sys.stdin.buffer)
wire.write_message(sys.stdout.buffer, ["ok", np.array(["evaluate"])])
time.sleep(120)  # never reads again: a large request fills the pipe
"""


def test_subprocess_backend_times_out_on_a_child_that_stops_reading():
    backend = SubprocessBackend([sys.executable, "-c", STOPS_READING], name="deaf", timeout=1.0)
    start = time.monotonic()
    with pytest.raises(TimeoutError, match="backend 'deaf' did not answer 'evaluate'"):
        backend.evaluate(np.zeros((1, 3), np.int32), np.zeros((1, 16)), 0,
                         np.zeros((200_000, 3)))  # 4.8 MB, far more than a pipe holds
    assert time.monotonic() - start < 30
    with pytest.raises(RuntimeError, match="closed"):  # killed: later calls fail at once
        backend.evaluate(np.zeros((1, 3), np.int32), np.zeros((1, 16)), 0, np.zeros((1, 3)))


def test_subprocess_backend_child_that_exits_is_a_clear_error():
    with pytest.raises(RuntimeError) as exc:
        SubprocessBackend([sys.executable, "-c", "pass"], name="gone", timeout=30)
    assert "backend 'gone' child died" in str(exc.value)


# ---------------------------------------------------------------------- answers
class _Answers:
    """A backend answering whatever it was built with."""
    name = "scripted"

    def __init__(self, value):
        self.value = value

    def evaluate(self, ni, nr, root, p):
        return self.value

    def evaluate_grad(self, ni, nr, root, p):
        return self.value

    def bound(self, ni, nr, root):
        return self.value


P3 = np.zeros((3, 3))


@pytest.mark.parametrize("value, says", [
    (None, "returned None"),
    ("0.0", "returned a string"),
    (np.array(["a", "b", "c"]), "non-numeric"),
    (np.array([True, False, True]), "non-numeric"),
    (np.array([1.0, None, 2.0], dtype=object), "non-numeric"),
    ([[1.0], [2.0, 3.0]], "not an array"),
    (np.zeros((3, 1)), "shape (3, 1)"),
    (np.zeros(4), "shape (4,)"),
    (np.array([0.0, -np.inf, 1.0]), "1 non-finite value(s)"),
    (np.array([0.0, 1.0, np.nan]), "first at flat index 2: nan"),
])
def test_unusable_evaluate_answers_are_named(value, says):
    got, why = ask(_Answers(value), "evaluate", None, None, 0, P3)
    assert got is None and says in why and why.startswith("scripted.evaluate")


def test_a_finite_answer_of_any_real_dtype_is_accepted():
    got, why = ask(_Answers(np.array([1, 2, 3], np.int32)), "evaluate", None, None, 0, P3)
    assert why is None and got.dtype == np.float64 and got.tolist() == [1.0, 2.0, 3.0]


@pytest.mark.parametrize("value, says", [
    (np.zeros(3), "expected a pair (phi, grad)"),
    ((np.zeros(3), np.zeros((3, 2))), "grad returned shape (3, 2)"),
    ((np.zeros(3), np.full((3, 3), np.nan)), "grad returned 9 non-finite"),
])
def test_unusable_gradient_answers_are_named(value, says):
    got, why = ask(_Answers(value), "evaluate_grad", None, None, 0, P3)
    assert got is None and says in why


@pytest.mark.parametrize("value, says", [
    ((np.zeros(3), float("nan"), True), "radius nan"),
    ((np.zeros(3), -1.0, True), "radius -1.0"),
    ((np.zeros(2), 1.0, True), "centre returned shape (2,)"),
    ((np.zeros(3), 1.0, "yes"), "certified=str 'yes', not a bool"),
    ((np.zeros(3), "big", True), "not a number"),
    ((np.zeros(3), 1.0), "expected (centre, radius, certified)"),
])
def test_unusable_bounds_are_named(value, says):
    got, why = ask_bound(_Answers(value), None, None, 0)
    assert got is None and says in why


def test_an_unbounded_ball_is_accepted():
    got, why = ask_bound(_Answers((np.zeros(3), float("inf"), False)), None, None, 0)
    assert why is None and got[1] == float("inf") and got[2] is False


# ---------------------------------------------------------------------- files
@pytest.mark.parametrize("content, says", [
    (None, "no such file"),
    ("{not json", "not a peclet certificate report"),
    ("[1, 2]", "not a peclet certificate report"),
    ('{"certificates": [{"status": "passed"}]}', "not a peclet certificate report"),
    ('{"profile": "x", "backend": "y", "certificates": [{"name": "a", "status": "passed"}]}',
     None),  # a report written before the format key existed is still a report
])
def test_load_report(tmp_path, content, says):
    path = tmp_path / "r.json"
    if content is not None:
        path.write_text(content)
    if says is None:
        assert R.load_report(path)["certificates"][0]["name"] == "a"
        return
    with pytest.raises(R.ReportFileError) as exc:
        R.load_report(path, "--peclet-compare")
    assert str(exc.value).startswith(f"--peclet-compare {path}") and says in str(exc.value)


def test_report_path_of_a_directory_is_refused(tmp_path):
    with pytest.raises(R.ReportFileError, match="--peclet-report must be a file path"):
        R.check_report_path(tmp_path)


def test_report_path_under_a_file_is_refused(tmp_path):
    (tmp_path / "f").write_text("x")
    with pytest.raises(R.ReportFileError, match="is a file, not a directory"):
        R.check_report_path(tmp_path / "f" / "r.json")


def test_report_path_of_a_read_only_report_is_refused(tmp_path):
    path = tmp_path / "r.json"
    R.write_report(path, {"profile": "p", "backend": "b", "certificates": []})
    path.chmod(0o444)
    with pytest.raises(R.ReportFileError, match="the existing file is read-only"):
        R.check_report_path(path)


def test_report_path_in_a_read_only_directory_is_refused(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        with pytest.raises(R.ReportFileError, match="is read-only"):
            R.check_report_path(ro / "sub" / "r.json")
    finally:
        ro.chmod(0o755)


def test_report_never_overwrites_a_file_that_is_not_a_report(tmp_path):
    path = tmp_path / "test_something.py"
    path.write_text("def test(): pass\n")
    with pytest.raises(R.ReportFileError, match="refusing to overwrite"):
        R.check_report_path(path)
    assert path.read_text() == "def test(): pass\n"


def test_report_json_is_strict_with_non_finite_details(tmp_path):
    path = tmp_path / "r.json"
    R.write_report(path, {"profile": "p", "backend": "b", "certificates": [
        {"name": "a", "status": "passed", "details": {"observed_order": float("inf")}}]})
    text = path.read_text()
    assert "Infinity" not in text and json.loads(text)["certificates"][0]["details"] == \
        {"observed_order": "inf"}


@pytest.mark.parametrize("name, content, says", [
    ("x.json", '{"nope": "r"}', "unknown certificate 'nope'"),
    ("x.json", '{"equation1": ""}', "needs a non-empty reason"),
    ("x.json", '{"equation1": {"reason": "r", "kinds": "torus"}}', "kinds must be a list"),
    ("x.json", '{"equation1": {"reason": "r", "why": 1}}', "unknown key(s) ['why']"),
    ("x.json", "[]", "expected a table"),
    ("x.json", "{}", "expected a table"),
    ("x.toml", "[equation1\nreason=", "cannot parse it"),
    ("x.json", None, "no such file"),
])
def test_xfails_file_errors_name_the_file(tmp_path, name, content, says):
    path = tmp_path / name
    if content is not None:
        path.write_text(content)
    with pytest.raises(R.ReportFileError) as exc:
        R.load_xfails(path, R.KNOWN_CERTIFICATES)
    msg = str(exc.value)
    assert msg.startswith(f"--peclet-xfails {path}") and says in msg and "\n" not in msg


def test_xfails_bare_reason_and_kind_filter(tmp_path):
    path = tmp_path / "x.json"
    path.write_text('{"sign_agreement": {"reason": "upstream bug", "kinds": ["superquadric"]},'
                    ' "equation1": "known"}')
    w_sign, w_eq = R.load_xfails(path, R.KNOWN_CERTIFICATES)
    cert = {"name": "sign agreement (same solid)", "status": "failed",
            "details": {"property": "sign_agreement"},
            "counterexample": "n0 = b.add_leaf('superquadric', [1.0])"}
    assert R.find_waiver([w_sign, w_eq], cert) is w_sign
    assert R.find_waiver([w_sign], dict(cert, counterexample="b.add_leaf('torus', [1])")) is None
    assert R.find_waiver([w_sign], dict(cert, status="passed")) is None
    assert w_eq.reason == "known" and w_eq.kinds == ()


# ---------------------------------------------------------------------- profiles, planted
def test_unknown_profile_is_refused():
    with pytest.raises(ValueError, match="profile must be one of dev, ci, nightly, smoke"):
        make_settings("weekly")


def test_unknown_planted_answer_is_refused():
    with pytest.raises(ValueError, match="bad must be one of"):
        planted.BadAnswerBackend("sometimes")


# ---------------------------------------------------------------------- plugin options
@pytest.mark.parametrize("args, says", [
    (["--peclet-profile", "weekly"], "invalid choice: 'weekly'"),
    (["--peclet-certify", "--peclet-backend", "nope"], "--peclet-backend"),
    (["--peclet-certify", "--peclet-backend", "no_such_module_h3:f"],
     "cannot import module 'no_such_module_h3'"),
    (["--peclet-certify", "--peclet-xfails", "missing.toml"], "missing.toml: no such file"),
    (["--peclet-certify", "--peclet-compare", "missing.json"], "missing.json: no such file"),
    (["--peclet-report", "r.json"], "--peclet-report has no effect without --peclet-certify"),
    (["--peclet-backend", "reference"], "--peclet-backend has no effect"),
])
def test_plugin_option_errors_are_one_line(pytester, args, says):
    pytester.makepyfile("def test_x():\n    pass\n")
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider", *args)
    assert result.ret in (pytest.ExitCode.USAGE_ERROR, 2), result.stdout.str()
    err = result.stderr.str()
    assert says in err and "Traceback" not in err, err
