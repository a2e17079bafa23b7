"""The ``regrasp-pin`` command line.

Each sub-command is a module in :mod:`regrasp_pin.commands` that defines ``NAME``,
``HELP``, ``add_arguments(parser)`` and ``run(args) -> int``; heavy imports happen
inside ``run`` so that ``regrasp-pin --help`` stays fast.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from .exceptions import RegraspError

#: Sub-command modules, in the order ``--help`` lists them.
COMMAND_MODULES: tuple[str, ...] = ("demo", "view", "approx", "info", "suite")


def _commands() -> dict:
    mods = {}
    for name in COMMAND_MODULES:
        try:
            mod = importlib.import_module(f"regrasp_pin.commands.{name}")
        except ModuleNotFoundError as exc:  # a command whose module is not there yet
            if exc.name == f"regrasp_pin.commands.{name}":
                continue
            raise
        mods[mod.NAME] = mod
    return mods


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every sub-command."""
    parser = argparse.ArgumentParser(
        prog="regrasp-pin",
        description="Regrasp planning for multi-fingered hands (Pinocchio + Coal).",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, mod in _commands().items():
        p = sub.add_parser(name, help=mod.HELP, description=mod.HELP)
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``regrasp-pin`` console script; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args._run(args) or 0)
    except RegraspError as exc:
        print(f"regrasp-pin {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
