"""The ``peclet`` command line: one module per subcommand, assembled here.

    peclet pall-ring ...   the reference page end to end (peclet.cli.pall_ring)
    peclet pack ...        any element into any container (peclet.cli.pack)
    peclet ensemble ...    many packs at once on Dask (peclet.cli.ensemble)

Each subcommand module exposes ``add_parser(subparsers)`` (registers its options and sets
``func``) and is listed in :data:`SUBCOMMANDS`. A :class:`~peclet.core.validation.
PecletArgumentError` raised while a command runs is a bad argument: it is printed as one line
``peclet <command>: error: ...`` with exit code 2, no traceback.
"""
from __future__ import annotations

import argparse
import importlib
import sys

__all__ = ["main", "build_parser", "SUBCOMMANDS"]

#: Modules (relative to this package) that each add one subcommand.
SUBCOMMANDS = ("pall_ring", "ensemble", "pack")


def build_parser():
    p = argparse.ArgumentParser(prog="peclet", description="peclet: composed analytic "
                                "particles — certified CSG trees, quadrature, DEM, packing.")
    sub = p.add_subparsers(dest="command", required=True)
    for name in SUBCOMMANDS:
        importlib.import_module(f".{name}", __name__).add_parser(sub)
    return p


def main(argv=None):
    from peclet.core.validation import PecletArgumentError

    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except PecletArgumentError as exc:
        print(f"peclet {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"peclet {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
