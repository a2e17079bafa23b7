"""Argument types shared by the sub-commands."""

from __future__ import annotations

import argparse

BUNDLED_HANDS = ("five_finger", "allegro")
HAND_METAVAR = "{five_finger,allegro,FILE.json}"


def hand_argument(value: str) -> str:
    """A bundled hand's name or a JSON hand file's path (argparse ``type=``)."""
    if value in BUNDLED_HANDS or value.endswith(".json"):
        return value
    raise argparse.ArgumentTypeError(
        f"{value!r} is not a hand: expected five_finger, allegro or a .json hand file"
    )
