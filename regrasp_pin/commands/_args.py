"""Argument types shared by the sub-commands."""

from __future__ import annotations

import argparse
from pathlib import Path

BUNDLED_HANDS = ("five_finger", "allegro")
HAND_METAVAR = "{five_finger,allegro,FILE.json}"


def hand_argument(value: str) -> str:
    """A bundled hand's name or a JSON hand file's path (argparse ``type=``)."""
    if value in BUNDLED_HANDS or value.endswith(".json"):
        return value
    raise argparse.ArgumentTypeError(
        f"{value!r} is not a hand: expected five_finger, allegro or a .json hand file"
    )


def output_folder(path: str | Path, option: str) -> Path:
    """The folder ``path``, created if needed; an InputError naming ``option`` when it
    cannot be (a regular file in the way, no permission)."""
    from ..exceptions import InputError

    folder = Path(path)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(
            option, f"cannot create the folder {str(folder)!r} ({exc.strerror})", "a folder path"
        ) from None
    return folder


def output_file(path: str | Path, option: str) -> Path:
    """``path`` for a file to write: its folder must exist (checked before any work)."""
    from ..exceptions import InputError

    file = Path(path)
    if not file.parent.is_dir():
        raise InputError(
            option,
            f"the folder {str(file.parent)!r} does not exist",
            "a file path in an existing folder",
        )
    if file.is_dir():
        raise InputError(option, f"{str(file)!r} is a folder", "a file path")
    return file


def _at_least_zero(value: str, convert: type[int] | type[float], what: str) -> float:
    """``convert(value)`` if it is finite and >= 0, else an ArgumentTypeError saying it
    is not ``what`` (argparse ``type=`` helpers)."""
    try:
        x = convert(value)
    except ValueError:
        x = -1
    if not 0 <= x < float("inf"):
        raise argparse.ArgumentTypeError(f"{value!r} is not {what}")
    return x


def _backups(value: str) -> int:
    """A whole number >= 0 (argparse ``type=`` of ``--grasp-backups``)."""
    return int(_at_least_zero(value, int, "a whole number >= 0"))


def add_grasp_backups(group: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    """The ``--grasp-backups K`` option (``plan_scenario(grasp_backups=K)``)."""
    group.add_argument(
        "--grasp-backups", type=_backups, default=1, metavar="K",
        help="a plan that fails at a finger still on its start contact is planned again "
        "from another initial grasp, up to K times, on the rest of the step budget "
        "(default: 1; 0: never)",
    )  # fmt: skip


def add_time_law(group: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    """The ``--time-law LAW`` option (``RegraspParams.time_law``)."""
    from ..planning.timing import TIME_LAWS

    group.add_argument(
        "--time-law", choices=TIME_LAWS, default=None,
        help="how a regrasp spreads its progress over its duration: minimum-jerk (the "
        "smoothest) or cruise (a regrasp bound by its joints' velocity limits lands in 0.76 "
        "of the time, with larger accelerations); default: the hand's (a hand file's "
        "scenario.time_law, else minimum-jerk)",
    )  # fmt: skip


def chosen_time_law(args: argparse.Namespace) -> str:
    """The time law of ``--time-law``, or the hand's (``args.hand``'s:
    :func:`~regrasp_pin.scenarios.setup_time_law`) when it is not given."""
    from ..scenarios import setup_time_law

    return args.time_law or setup_time_law(args.hand)


def _torsion_mm(value: str) -> float:
    """A finite number >= 0 (argparse ``type=`` of ``--torsion-mm``)."""
    return float(_at_least_zero(value, float, "a number >= 0 [mm]"))


def add_torsion(group: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    """The ``--torsion-mm MM`` option (``ContactModel.torsion_m``, in mm)."""
    group.add_argument(
        "--torsion-mm", type=_torsion_mm, default=0.0, metavar="MM",
        help="soft fingertips: the torque about its normal a contact resists per newton "
        "pressing it [mm] (about 2/3 mu times the contact patch's radius; with it two "
        "fingers can hold alone); default 0: point contacts with friction",
    )  # fmt: skip
