"""peclet.ensemble: many packs at once (seeds x parameter sweeps) as Dask tasks.

    from peclet.ensemble import make_specs, run, summarize
    specs = make_specs(seeds=range(1, 33), sweep={"mu": [0.3, 0.5, 0.8]},
                       element="pall_ring", container="box:3.5")
    rows = run(specs, "OUT")               # embedded LocalCluster; or scheduler="tcp://..."
    points = summarize(rows, swept=["mu"])  # mean, standard error, 95% interval per point

Each realization is a deterministic function of its :class:`PackSpec`; results land in
``OUT/<spec-id>/`` (results.json + pack.npz) as they finish and a rerun skips them
(docs/architecture.md §11).
"""
from .ledger import Ledger
from .realize import FIGURES, realize
from .runner import EnsembleError, connect, machine_cores, open_ledger, run
from .spec import SWEEPABLE, PackSpec, ensemble_manifest, make_specs, parse_seeds, parse_sweep
from .summary import summarize, write_csv, write_figure, write_json

__all__ = ["PackSpec", "SWEEPABLE", "parse_seeds", "parse_sweep", "make_specs",
           "ensemble_manifest", "Ledger", "realize", "FIGURES", "run", "connect",
           "open_ledger", "machine_cores", "EnsembleError", "summarize", "write_csv",
           "write_json", "write_figure"]
