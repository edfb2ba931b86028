"""The certification profiles: Hypothesis settings objects that mean the same everywhere.

Each profile sets ``derandomize``, ``database``, ``deadline`` and ``print_blob`` explicitly and
inherits nothing else from the process: its parent is Hypothesis's built-in ``default``
profile, not whatever profile is loaded (Hypothesis loads its own ``ci`` profile when the
``CI`` variable is set, which would make a nightly run derandomised and forgetful). The
settings objects are handed to the certificate searches only (:func:`peclet_verify.search.
search` uses the active one); no profile is ever loaded globally, so a project's own Hypothesis
tests keep their settings.

=========  ============  ============  ===========================================  =========
profile    max_examples  derandomize   database                                     print_blob
=========  ============  ============  ===========================================  =========
dev        25            False         ``<root>/.hypothesis/examples`` (directory)   False
ci         40            True          None (every run draws the same examples)      True
nightly    2000          False         ``<root>/.hypothesis/examples`` (directory)   True
smoke      2             True          None                                          False
=========  ============  ============  ===========================================  =========

``replay`` (``--peclet-replay DIR``, with any profile) re-runs only the examples saved in the
example database ``DIR`` (e.g. the last nightly's), read-only: phases explicit and reuse, no
generation, ``derandomize`` off (a derandomised run ignores the database), nothing written.

``deadline`` is None in every profile: JIT warm-up and out-of-process engines make
per-example timing meaningless. ``smoke`` exists for this suite's own tests of the plugin
(a whole certification run in seconds); it certifies nothing worth reporting.
"""
from __future__ import annotations

import os

__all__ = ["PROFILES", "make_settings", "check_replay_dir", "SHARDS"]

#: Profile name -> (max_examples, derandomize, uses the example database, print_blob).
PROFILES = {
    "dev": (25, False, True, False),
    "ci": (40, True, False, True),
    "nightly": (2000, False, True, True),
    "smoke": (2, True, False, False),
}

#: Shards of the quadrature certificate (each runs 1/SHARDS of the examples, so that
#: ``pytest -n`` spreads the slowest certificate over workers).
SHARDS = 4


def check_replay_dir(path) -> str:
    """``path`` if it is a directory (an example database), else ``ValueError`` naming it."""
    if not isinstance(path, (str, os.PathLike)) or not os.path.isdir(path):
        raise ValueError(f"--peclet-replay {path}: not a directory (an example database, "
                         f"e.g. the nightly's .hypothesis/examples)")
    return path


def make_settings(name: str, root: str = ".", replay=None):
    """The Hypothesis ``settings`` of profile ``name`` (one of :data:`PROFILES`); a database
    profile stores its examples under ``root/.hypothesis/examples``. With ``replay`` (an
    example-database directory) only the examples saved there are re-run, read-only."""
    from hypothesis import HealthCheck, Phase, settings
    from hypothesis.database import DirectoryBasedExampleDatabase, ReadOnlyDatabase

    if name not in PROFILES:
        raise ValueError(f"profile must be one of {', '.join(PROFILES)}, got {name!r}")
    max_examples, derandomize, use_db, print_blob = PROFILES[name]
    database = DirectoryBasedExampleDatabase(
        os.path.join(os.path.abspath(root), ".hypothesis", "examples")) if use_db else None
    phases = tuple(Phase)
    if replay is not None:
        check_replay_dir(replay)
        database = ReadOnlyDatabase(DirectoryBasedExampleDatabase(os.path.abspath(replay)))
        derandomize, phases = False, (Phase.explicit, Phase.reuse)
    return settings(settings.get_profile("default"), max_examples=max_examples,
                    derandomize=derandomize, database=database, deadline=None,
                    print_blob=print_blob, phases=phases,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
