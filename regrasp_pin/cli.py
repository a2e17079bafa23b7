"""The ``regrasp-pin`` command line.

Each sub-command is a module in :mod:`regrasp_pin.commands` that defines ``NAME``,
``HELP``, ``add_arguments(parser)`` and ``run(args) -> int``; heavy imports happen
inside ``run`` so that ``regrasp-pin --help`` stays fast.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from collections.abc import Sequence

from .exceptions import ContactError, PlanningError, RegraspError

#: Sub-command modules, in the order ``--help`` lists them.
COMMAND_MODULES: tuple[str, ...] = ("demo", "plan", "view", "approx", "info", "suite")


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


#: Exit codes of every command.
EXIT_OK = 0  #: done
EXIT_NO_PLAN = 1  #: no plan: a planning (or grasp) failure; a partial plan is written
EXIT_USAGE = 2  #: bad arguments or input files, a missing extra, an unwritable output
EXIT_INTERRUPTED = 130  #: Ctrl-C

_LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR")


def _version() -> str:
    from . import __version__

    return __version__


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every sub-command."""
    parser = argparse.ArgumentParser(
        prog="regrasp-pin",
        description="Regrasp planning for multi-fingered hands (Pinocchio + Coal).",
        epilog="Exit codes: 0 done, 1 no plan found (a partial plan is written), "
        "2 bad arguments or input, 130 interrupted.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    log = parser.add_mutually_exclusive_group()
    log.add_argument(
        "-v", "--verbose", action="count", default=0,
        help="log what the planner does to stderr (-v: info, -vv: debug)",
    )  # fmt: skip
    log.add_argument("-q", "--quiet", action="store_true", help="log errors only")
    log.add_argument(
        "--log-level", choices=_LEVELS, type=str.upper, default=None,
        help="log level on stderr (default: WARNING)",
    )  # fmt: skip
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, mod in _commands().items():
        p = sub.add_parser(name, help=mod.HELP, description=mod.HELP)
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run)
    return parser


def _configure_logging(args: argparse.Namespace) -> None:
    """The root logger at the level asked for, with one handler on the current stderr."""
    if args.log_level:
        level = args.log_level
    elif args.quiet:
        level = "ERROR"
    else:
        level = ("WARNING", "INFO")[min(args.verbose, 1)] if args.verbose < 2 else "DEBUG"
    root = logging.getLogger()
    for h in [h for h in root.handlers if getattr(h, "_regrasp_pin_cli", False)]:
        root.removeHandler(h)  # an earlier main() in this process: its stderr may be gone
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
    handler._regrasp_pin_cli = True  # type: ignore[attr-defined]
    # the handler filters too: a library that sets its own loggers' levels after this
    # (dask's distributed does, when a suite starts its cluster) cannot get past -q
    handler.setLevel(getattr(logging, level))
    root.addHandler(handler)
    root.setLevel(getattr(logging, level))
    for noisy in ("matplotlib", "PIL", "distributed", "asyncio"):
        logging.getLogger(noisy).setLevel(max(getattr(logging, level), logging.WARNING))


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``regrasp-pin`` console script; returns the exit code.

    Every user error is one line on stderr, never a traceback: 1 when no plan was found
    (a planning or grasp outcome), 2 for bad arguments or input (``InputError``, an
    unknown name, a model file, a missing extra, an output that cannot be written).
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    _configure_logging(args)
    try:
        return int(args._run(args) or 0)
    except (PlanningError, ContactError) as exc:
        print(f"regrasp-pin {args.command}: no plan: {exc}", file=sys.stderr)
        return EXIT_NO_PLAN
    except RegraspError as exc:
        print(f"regrasp-pin {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except OSError as exc:  # an output that cannot be written
        where = f" {exc.filename}" if exc.filename else ""
        print(f"regrasp-pin {args.command}: error:{where}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print(f"regrasp-pin {args.command}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
