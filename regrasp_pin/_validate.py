"""Input checks shared by the public API: each raises :class:`InputError` naming the argument."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from .exceptions import InputError, UnknownNameError


def as_array(
    value: object,
    argument: str,
    shape: Sequence[int | None],
    *,
    finite: bool = True,
    dtype: type = np.float64,
) -> np.ndarray:
    """Convert ``value`` to a float array of the given shape (None = any size).

    Raises:
        InputError: if the value is not numeric, has the wrong shape, or (``finite``)
            contains NaN or inf.
    """
    try:
        arr: np.ndarray = np.asarray(value, dtype=dtype)
    except (TypeError, ValueError) as exc:
        raise InputError(argument, f"not a numeric array ({exc})", _shape_text(shape)) from None
    if arr.ndim != len(shape) or any(
        want is not None and have != want for have, want in zip(arr.shape, shape, strict=False)
    ):
        raise InputError(argument, f"has shape {arr.shape}", f"shape {_shape_text(shape)}")
    if finite and not np.isfinite(arr).all():
        raise InputError(argument, "contains NaN or inf", "finite values")
    return arr


def as_batch(
    value: object, argument: str, width: int, *, finite: bool = True
) -> tuple[np.ndarray, bool]:
    """Accept ``(width,)`` or ``(N, width)``; return ``(N, width)`` and whether it was 1-D."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(argument, f"not a numeric array ({exc})", f"shape (N, {width})") from None
    given = arr.shape
    single = arr.ndim == 1
    if single:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != width:
        raise InputError(argument, f"has shape {given}", f"shape ({width},) or (N, {width})")
    if finite and not np.isfinite(arr).all():
        raise InputError(argument, "contains NaN or inf", "finite values")
    return arr, single


def positive(value: float, argument: str, *, allow_zero: bool = False) -> float:
    """Return ``float(value)`` if it is finite and > 0 (>= 0 with ``allow_zero``)."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(argument, f"{value!r} is not a number", "a positive number") from None
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        expected = "a finite number >= 0" if allow_zero else "a finite number > 0"
        raise InputError(argument, f"{value!r} is not allowed", expected)
    return v


#: Largest length a hand-held object or its distance from the palm can have [m]: a
#: larger one is a length in millimetres by mistake.
MAX_LENGTH_M = 1.0


def hand_scale(length_m: float, argument: str) -> float:
    """Return ``length_m`` if it is at most :data:`MAX_LENGTH_M`; else an InputError that
    says lengths are in metres."""
    if length_m > MAX_LENGTH_M:
        raise InputError(
            argument,
            f"is {length_m:g} m, larger than anything a hand holds ({MAX_LENGTH_M:g} m)",
            f"lengths in metres (32 mm is 0.032, not 32; here {length_m / 1000:g}?)",
        )
    return length_m


def positive_int(value: object, argument: str, minimum: int = 1) -> int:
    """Return ``int(value)`` if it is an integer >= ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise InputError(argument, f"{value!r} is not an integer", f"an integer >= {minimum}")
    if value < minimum:
        raise InputError(argument, f"{value} is too small", f"an integer >= {minimum}")
    return int(value)


def choice(value: object, argument: str, valid: Sequence[str]) -> str:
    """Return ``value`` if it is one of ``valid``; else raise :class:`UnknownNameError`."""
    if not isinstance(value, str) or value not in valid:
        raise UnknownNameError(argument, value, valid)
    return value


def _shape_text(shape: Sequence[int | None]) -> str:
    parts = ["N" if s is None else str(s) for s in shape]
    return "(" + ", ".join(parts) + ("," if len(parts) == 1 else "") + ")"


def frozen(arr: np.ndarray) -> np.ndarray:
    """A contiguous, read-only view (or copy) of ``arr``: results hand out arrays that
    callers cannot change behind the object's back."""
    arr = np.ascontiguousarray(arr)
    arr.setflags(write=False)
    return arr


def known_fields(d: Any, cls: type, argument: str) -> None:
    """Check that ``d`` is a dict holding the fields of dataclass ``cls`` (no unknown
    field, every field without a default); InputError naming ``argument`` otherwise."""
    if not isinstance(d, dict):
        raise InputError(argument, f"is a {type(d).__name__}", "a dict")
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(d) - set(fields))
    if unknown:
        raise InputError(argument, f"unknown field(s) {unknown}", f"fields of {cls.__name__}")
    missing = sorted(
        n
        for n, f in fields.items()
        if n not in d
        and f.default is dataclasses.MISSING
        and f.default_factory is dataclasses.MISSING
    )
    if missing:
        raise InputError(argument, f"missing field(s) {missing}", f"fields of {cls.__name__}")
