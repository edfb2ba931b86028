"""The ``peclet`` command line: one module per subcommand, assembled here.

    peclet pall-ring ...   the reference page end to end (peclet.cli.pall_ring)
    peclet pack ...        any element into any container (peclet.cli.pack)
    peclet ensemble ...    many packs at once on Dask (peclet.cli.ensemble)
    peclet drum ...        a rotating drum: dynamic angle and flow regime (peclet.cli.drum)
    peclet flow ...        permeability of a frozen pack, lattice Boltzmann (peclet.cli.flow)
    peclet stir ...        a stirred column: Lacey mixing index (peclet.cli.stir)
    peclet warm            compile the kernels ahead into Numba's cache (peclet.cli.warm)

Each subcommand module exposes ``add_parser(subparsers)`` (registers its options and sets
``func``) and is listed in :data:`SUBCOMMANDS`. A :class:`~peclet.core.validation.
PecletArgumentError` raised while a command runs is a bad argument: it is printed as one line
``peclet <command>: error: ...`` with exit code 2, no traceback. What argparse itself refuses
(an unknown option, a missing value) is one such line too, and a negative value written
after its option (``--box -inf``, ``--x -1e3``) is taken as that option's value.
"""
from __future__ import annotations

import argparse
import importlib
import re
import sys

__all__ = ["main", "build_parser", "SUBCOMMANDS"]

#: Modules (relative to this package) that each add one subcommand.
SUBCOMMANDS = ("pall_ring", "ensemble", "pack", "drum", "stir", "flow", "warm")


#: A token that is a negative number (argparse alone takes only -1 and -.5 for one).
_NEGATIVE = re.compile(r"^-(inf(inity)?|nan|(\d+\.?\d*|\.\d+)(e[+-]?\d+)?)$", re.IGNORECASE)


class _Parser(argparse.ArgumentParser):
    """argparse with its refusals as one line, ``<prog>: error: <message>``, exit code 2."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}\n")


def _join_negative_values(argv):
    """``--opt -x`` -> ``--opt=-x`` where -x is a negative number, so argparse reads it as
    the value (and the option's own check then judges it) rather than as an unknown option."""
    out = []
    for tok in argv:
        if (out and _NEGATIVE.match(tok) and out[-1].startswith("--")
                and "=" not in out[-1]):
            out[-1] = f"{out[-1]}={tok}"
        else:
            out.append(tok)
    return out


def build_parser():
    p = _Parser(prog="peclet", description="peclet: composed analytic "
                "particles — certified CSG trees, quadrature, DEM, packing.")
    sub = p.add_subparsers(dest="command", required=True)
    for name in SUBCOMMANDS:
        importlib.import_module(f".{name}", __name__).add_parser(sub)
    return p


def main(argv=None):
    from peclet.core.validation import PecletArgumentError

    parser = build_parser()
    args = parser.parse_args(_join_negative_values(sys.argv[1:] if argv is None else argv))
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
