"""peclet.core.results_cache: entries come back bit for bit, and anything doubtful is a miss."""
import json
import os

import pytest

from peclet.core import results_cache as rc

PARAMS = dict(thicknesses=[0.1, 0.2], n=8, tol=1e-4)
VALUE = [dict(s=0.1 + 0.2, e=1.0 / 3.0), dict(s=2.0 ** -1074, e=-0.0)]


@pytest.fixture
def cache(monkeypatch, tmp_path):
    monkeypatch.setenv("PECLET_CACHE_DIR", str(tmp_path / "c"))
    return tmp_path / "c"


def test_a_stored_value_comes_back_bit_for_bit(cache):
    assert rc.load("k", PARAMS) is None
    path = rc.store("k", PARAMS, VALUE)
    assert path.startswith(str(cache / "k")) and path.endswith(".json")
    got = rc.load("k", PARAMS)
    assert [float(r["s"]).hex() for r in got] == [float(r["s"]).hex() for r in VALUE]
    assert [str(r["e"]) for r in got] == ["0.3333333333333333", "-0.0"]
    assert rc.load("k", dict(PARAMS, n=9)) is None          # other parameters: another entry
    assert rc.load("other", PARAMS) is None                 # another kind too
    assert not [f for f in os.listdir(cache / "k") if f.startswith(".peclet-tmp-")]


def test_other_code_is_a_miss(cache, monkeypatch):
    rc.store("k", PARAMS, VALUE)
    stamp = rc.code_stamp()
    assert len(stamp) == 64 and rc.code_stamp() == stamp    # computed once per process
    monkeypatch.setattr(rc, "_STAMP", "0" * 64)             # as if peclet's code had changed
    assert rc.load("k", PARAMS) is None


def test_an_unreadable_or_foreign_entry_is_a_miss_and_is_replaced(cache):
    path = rc.store("k", PARAMS, VALUE)
    with open(path, "w") as fh:
        fh.write('{"params": {"n": 8')                       # cut short
    assert rc.load("k", PARAMS) is None
    with open(path, "w") as fh:
        json.dump(dict(params=dict(PARAMS, n=1), value=VALUE), fh)   # not these parameters
    assert rc.load("k", PARAMS) is None
    rc.store("k", PARAMS, VALUE)
    assert rc.load("k", PARAMS) == VALUE
    # the caller's own check rejects what it cannot use
    assert rc.load("k", PARAMS, valid=lambda v: len(v) == 3) is None


def test_off_reads_and_writes_nothing(monkeypatch, tmp_path):
    monkeypatch.setenv("PECLET_CACHE_DIR", "OFF")
    assert rc.cache_dir() is None
    assert rc.store("k", PARAMS, VALUE) is None and rc.load("k", PARAMS) is None


def test_a_cache_that_cannot_be_written_keeps_nothing_and_raises_nothing(monkeypatch, tmp_path):
    (tmp_path / "file").write_text("")
    monkeypatch.setenv("PECLET_CACHE_DIR", str(tmp_path / "file" / "c"))    # under a file
    assert rc.store("k", PARAMS, VALUE) is None and rc.load("k", PARAMS) is None


def test_the_default_directory_follows_xdg(monkeypatch, tmp_path):
    monkeypatch.delenv("PECLET_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert rc.cache_dir() == os.path.join(str(tmp_path), "peclet")
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert rc.cache_dir() == os.path.join(os.path.expanduser("~"), ".cache", "peclet")


def test_a_value_with_nan_is_refused(cache):
    with pytest.raises(ValueError):
        rc.store("k", PARAMS, [float("nan")])
    assert rc.load("k", PARAMS) is None
