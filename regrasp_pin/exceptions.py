"""One exception hierarchy for regrasp_pin.

Every error the library raises on purpose derives from :class:`RegraspError`, so a
caller can catch everything with one ``except``. Input errors also derive from
``ValueError`` (or ``KeyError``/``FileNotFoundError``) so that generic code that
catches the built-in types keeps working. Exceptions carry the data that explains
them (the argument, the accepted values, the finger, the time).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any


class RegraspError(Exception):
    """Base class of every error raised by regrasp_pin."""


class InputError(RegraspError, ValueError):
    """An argument has the wrong shape, type, value or contains NaN/inf.

    Attributes:
        argument: Name of the offending argument.
        expected: Human-readable description of what is accepted.
    """

    def __init__(self, argument: str, message: str, expected: str | None = None) -> None:
        self.argument = argument
        self.expected = expected
        text = f"{argument}: {message}"
        if expected:
            text += f" (expected {expected})"
        super().__init__(text)


class UnknownNameError(RegraspError, KeyError):
    """A finger, frame, joint, deviation or method name is not known.

    Attributes:
        argument: Name of the argument that held the name.
        name: The name that was given.
        valid: The names that are accepted.
    """

    def __init__(self, argument: str, name: Any, valid: Iterable[Any]) -> None:
        self.argument = argument
        self.name = name
        self.valid = tuple(valid)
        super().__init__(name)

    def __str__(self) -> str:
        valid = ", ".join(repr(v) for v in self.valid)
        return f"{self.argument}: unknown name {self.name!r}; valid names are: {valid}"


class ModelFileError(RegraspError, FileNotFoundError):
    """A model file (URDF) does not exist or cannot be parsed."""

    def __init__(self, path: Any, reason: str) -> None:
        self.path = path
        self.reason = reason
        super().__init__(f"{path}: {reason}")


class GeometryError(RegraspError, ValueError):
    """An object description is empty, degenerate or not convex where it must be."""


class ContactError(RegraspError):
    """No feasible contact could be found (initial grasp or new contact Q).

    Attributes:
        finger: The finger concerned (or None for the whole grasp).
        time_s: The time at which it was needed [s] (or None).
        reason: Why no contact could be found.
    """

    def __init__(self, reason: str, finger: str | None = None, time_s: float | None = None) -> None:
        self.finger = finger
        self.time_s = time_s
        self.reason = reason
        where = []
        if finger is not None:
            where.append(f"finger {finger!r}")
        if time_s is not None:
            where.append(f"t={time_s:.3f} s")
        prefix = (", ".join(where) + ": ") if where else ""
        super().__init__(prefix + reason)


class PlanningError(RegraspError):
    """A regrasp or a whole-hand plan could not be found and verified.

    Attributes:
        finger: The finger concerned (or None).
        time_s: When the failure happened [s] (or None).
        reason: What failed (e.g. which check, by how much).
        partial: Whatever was planned before the failure (e.g. a partial plan), or None.
    """

    def __init__(
        self,
        reason: str,
        finger: str | None = None,
        time_s: float | None = None,
        partial: Any = None,
    ) -> None:
        self.finger = finger
        self.time_s = time_s
        self.reason = reason
        self.partial = partial
        where = []
        if finger is not None:
            where.append(f"finger {finger!r}")
        if time_s is not None:
            where.append(f"t={time_s:.3f} s")
        prefix = (", ".join(where) + ": ") if where else ""
        super().__init__(prefix + reason)


class VerificationError(PlanningError):
    """A trajectory failed its Coal / joint-limit verification."""


class MissingExtraError(RegraspError, ImportError):
    """An optional dependency is not installed."""

    def __init__(self, module: str, extra: str) -> None:
        self.module = module
        self.extra = extra
        super().__init__(
            f"{module} is required for this feature: pip install 'regrasp-pin[{extra}]'"
        )
