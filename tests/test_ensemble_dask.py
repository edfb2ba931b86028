"""peclet.ensemble on a REAL distributed.LocalCluster (2 worker processes, 1 Numba thread
each) with tiny packs: results equal a serial run bit for bit, a worker killed mid-run (by pid)
does not lose or tear a result, a rerun skips finished realizations.

The serial reference runs in this process at its own Numba thread count, so the equality also
checks thread-count independence.
"""
import json
import math
import logging
import os
import signal
import threading
import time

import pytest

from peclet.ensemble import make_specs, realize, run
from peclet.packing.bed.freeze import load_pack

pytestmark = pytest.mark.slow

#: Tiny realizations: a few elements, the page protocol at a few percent of its steps. Spheres
#: (the DEM's exact sphere path) keep each worker's start-up short: a Pall ring is measured
#: once per process (~15 s); benchmarks/bench_ensemble.py checks the page's rings the same way.
TINY = dict(element="sphere", count=4, steps_scale=0.03, mc_samples=20_000, container="box:3")


@pytest.fixture(scope="module")
def client():
    from distributed import Client, LocalCluster

    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                           dashboard_address=":0", silence_logs=logging.CRITICAL)
    c = Client(cluster, set_as_default=False)
    yield c
    c.close()
    cluster.close()


def _serial(specs):
    return {s.id: realize(s)[0] for s in specs}


def _hash_of_file(path):
    import hashlib

    import numpy as np

    p = load_pack(path)
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(p.positions, np.float64).tobytes())
    h.update(np.ascontiguousarray(p.quaternions, np.float64).tobytes())
    return h.hexdigest()


def _check_ledger(out, specs, reference):
    """Every spec present exactly once, complete, and equal to the serial reference."""
    names = sorted(os.listdir(out))
    assert names == sorted(["ensemble.json"] + [s.id for s in specs]), names
    for s in specs:
        d = os.path.join(out, s.id)
        assert sorted(os.listdir(d)) == ["pack.npz", "results.json"]
        with open(os.path.join(d, "results.json")) as fh:
            res = json.load(fh)
        ref = reference[s.id]
        assert res["state_hash"] == ref["state_hash"]
        assert _hash_of_file(os.path.join(d, "pack.npz")) == ref["state_hash"]
        for k in ("eps", "f_env", "z_mean", "rattlers"):
            # results.json writes a NaN (f_env of an element with no envelope) as null
            assert res[k] == ref[k] or (res[k] is None and math.isnan(ref[k])), (s.id, k)


def test_dask_results_equal_serial_and_rerun_skips(client, tmp_path):
    specs = make_specs([1, 2, 3], {"mu": [0.3, 0.8]}, **TINY)
    ref = _serial(specs)
    out = str(tmp_path / "out")
    rows = run(specs, out, scheduler=client, progress=False)
    assert [r["id"] for r in rows] == [s.id for s in specs]
    assert not any(r["reused"] for r in rows)
    assert [r["state_hash"] for r in rows] == [ref[s.id]["state_hash"] for s in specs]
    _check_ledger(out, specs, ref)
    pids = set()
    for s in specs:
        with open(os.path.join(out, s.id, "results.json")) as fh:
            res = json.load(fh)
        pids.add(res["pid"])
        assert res["threads"] == 1                   # set inside the task
    assert os.getpid() not in pids and len(pids) == 2   # both worker processes worked

    # a rerun skips every finished realization (no cluster needed: an unreachable address)
    mtimes = {s.id: os.path.getmtime(os.path.join(out, s.id, "results.json")) for s in specs}
    again = run(specs, out, scheduler="tcp://127.0.0.1:9", progress=False)
    assert all(r["reused"] for r in again)
    assert [r["state_hash"] for r in again] == [r["state_hash"] for r in rows]
    # a lost result is recomputed, and only that one
    lost = specs[1]
    os.rename(os.path.join(out, lost.id), str(tmp_path / "moved"))
    third = run(specs, out, scheduler=client, progress=False)
    assert [r["reused"] for r in third] == [s.id != lost.id for s in specs]
    _check_ledger(out, specs, ref)
    assert all(os.path.getmtime(os.path.join(out, s.id, "results.json")) == mtimes[s.id]
               for s in specs if s.id != lost.id)


def test_worker_killed_mid_run_loses_nothing(client, tmp_path):
    specs = make_specs([1, 2, 3, 4, 5, 6], **dict(TINY, count=8, steps_scale=0.12))
    ref = _serial(specs)
    out = str(tmp_path / "out")
    ours = {f"peclet-realize-{s.id}": s.id for s in specs}
    killed = {}

    def killer():
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not killed:
            for addr, keys in client.processing().items():
                busy = [ours[k] for k in keys if k in ours]
                if busy:
                    # the worker process's pid (scheduler_info() does not carry it)
                    pid = client.run(os.getpid, workers=[addr])[addr]
                    killed.update(pid=pid, busy=busy, t=time.time())
                    os.kill(pid, signal.SIGKILL)
                    return
            time.sleep(0.01)

    th = threading.Thread(target=killer, daemon=True)
    th.start()
    rows = run(specs, out, scheduler=client, progress=False)
    th.join()
    assert killed, "no realization was caught running"
    assert len(rows) == len(specs) and not any(r["reused"] for r in rows)
    _check_ledger(out, specs, ref)                  # all present once, none half-written
    for sid in killed["busy"]:
        # what ran on the killed worker was either finished before the kill or redone elsewhere
        p = os.path.join(out, sid, "results.json")
        with open(p) as fh:
            res = json.load(fh)
        assert res["pid"] != killed["pid"] or os.path.getmtime(p) <= killed["t"]


def test_embedded_cluster_is_sized_to_the_machine(monkeypatch):
    from peclet.ensemble import connect, machine_cores

    monkeypatch.delenv("DASK_SCHEDULER_ADDRESS", raising=False)
    # workers x Numba threads = cores, one task at a time per worker; closed on exit
    with connect() as (c, threads):
        info = c.scheduler_info()["workers"]
        assert len(info) * threads == machine_cores()
        assert all(w["nthreads"] == 1 for w in info.values())
    assert c.status == "closed"


def test_cli_writes_the_summary(client, tmp_path, capsys):
    import numpy as np

    from peclet.cli import main

    out = tmp_path / "ens"
    argv = ["ensemble", "--element", "sphere", "--container", "box:3", "--seeds", "1-3",
            "--sweep", "mu=0.3,0.8", "--count", "4", "--steps-scale", "0.03",
            "--mc-samples", "20000", "--out", str(out), "--quiet",
            "--scheduler", client.scheduler.address]
    assert main(argv) == 0
    table = capsys.readouterr().out
    assert {"summary.csv", "summary.json", "summary.png", "ensemble.json"} \
        <= set(os.listdir(out))
    doc = json.loads((out / "summary.json").read_text())
    assert [p["mu"] for p in doc["points"]] == [0.3, 0.8]
    for p in doc["points"]:
        # recomputed independently from the ledger's results.json files
        res = [json.loads((out / d / "results.json").read_text()) for d in os.listdir(out)
               if (out / d).is_dir()]
        eps = [r["eps"] for r in res if r["spec"]["mu"] == p["mu"]]
        assert p["n"] == len(eps) == 3
        assert p["eps_mean"] == pytest.approx(np.mean(eps), rel=1e-14)
        assert p["eps_se"] == pytest.approx(np.std(eps, ddof=1) / np.sqrt(3), rel=1e-12)
    assert len(table.strip().splitlines()) == 4          # header, rule, two points


@pytest.mark.heavy
def test_an_ensemble_of_a_mesh_element_runs_on_the_cluster(client, tmp_path):
    # a user's STL (a 25 mm sphere drawn in mm) as the element of every realization: the
    # workers read the file by its absolute path and agree with a serial run bit for bit
    import trimesh

    mesh = tmp_path / "pellet.stl"
    trimesh.creation.icosphere(subdivisions=3, radius=12.5).export(mesh)
    specs = make_specs([1, 2], element=f"{mesh}:scale=0.04,resolution=0.1", count=4,
                       steps_scale=0.03, mc_samples=20_000, container="box:3")
    ref = _serial(specs)
    out = str(tmp_path / "out")
    rows = run(specs, out, scheduler=client, progress=False)
    assert [r["state_hash"] for r in rows] == [ref[s.id]["state_hash"] for s in specs]
    _check_ledger(out, specs, ref)
    for s in specs:
        res = json.loads(open(os.path.join(out, s.id, "results.json")).read())
        assert res["spec"]["element"] == str(specs[0].element)
        assert 0.0 < res["eps"] < 1.0
