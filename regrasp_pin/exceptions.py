"""One exception hierarchy for regrasp_pin.

Every error the library raises on purpose derives from :class:`RegraspError`, so a
caller can catch everything with one ``except``. Input errors also derive from
``ValueError`` (or ``KeyError``/``FileNotFoundError``) so that generic code that
catches the built-in types keeps working. Exceptions carry the data that explains
them (the argument, the accepted values, the finger, the time).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import asdict, dataclass
from enum import Enum
from typing import Any


def _rebuild(cls: type[RegraspError], args: tuple, state: dict) -> RegraspError:
    err = cls.__new__(cls)
    Exception.__init__(err, *args)
    err.__dict__.update(state)
    return err


class RegraspError(Exception):
    """Base class of every error raised by regrasp_pin.

    Errors pickle with all their data (for worker processes and distributed runs).
    """

    def __reduce__(self) -> tuple:
        return (_rebuild, (type(self), self.args, dict(self.__dict__)))


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


class UnfoldError(GeometryError):
    """No chain of adjacent faces joins P's face to Q's face without overlapping once
    unfolded: the surface route between them cannot be gridded (a regrasp then takes
    its joint-space fallback)."""


class FailureKind(str, Enum):
    """Why a planning step failed: what a caller (or the planner itself) decides on.

    Every :class:`ContactError`, :class:`PlanningError` and :class:`Attempt` carries one.
    Decisions read the kind and its numbers, never the message text.
    """

    IK_UNREACHABLE = "ik-unreachable"
    """The fingertip target is out of reach of IK (residual above tolerance)."""
    VELOCITY = "velocity"
    """A joint would exceed its velocity limit [rad/s]."""
    JOINT_LIMIT = "joint-limit"
    """A joint would leave its limits [rad]."""
    FINGER_COLLISION = "finger-collision"
    """The moving finger comes too close to another finger [m]."""
    OBJECT_CLEARANCE = "object-clearance"
    """The moving finger comes too close to (or into) the object [m]."""
    GRID_UNREACHABLE = "grid-unreachable"
    """No path on the unfolded surface grid joins P and Q."""
    NO_CANDIDATE = "no-candidate"
    """No new contact Q satisfies the conditions (inside the limits at arrival, ...)."""
    FORCE_CLOSURE = "force-closure"
    """The fingers that would hold are not in force closure."""
    TOO_LATE = "too-late"
    """A regrasp would not end before the motion does."""
    SHORT_HOLD = "short-hold"
    """The new contact would be lost sooner after landing than a regrasp takes [s]."""
    FINGER_BUSY = "finger-busy"
    """A finger must let go while another is still in the air."""
    TOO_FEW_FINGERS = "too-few-fingers"
    """Fewer fingers than required would hold."""
    BUDGET = "budget"
    """The search budget (attempts or seconds) ran out."""
    INFEASIBLE = "infeasible"
    """No plan exists: a finger cannot let go (no grasp without it is in force closure)
    for longer than any of its contacts stays within its joint limits [s]."""


# what to change, per kind, for the message of a failed plan
ADVICE = {
    FailureKind.IK_UNREACHABLE: "place the object closer to the fingers' common workspace",
    FailureKind.VELOCITY: "turn the object more slowly (or raise the joint velocity limits)",
    FailureKind.JOINT_LIMIT: "place the object where the fingers have more joint range",
    FailureKind.FINGER_COLLISION: "use fingers that are further apart, or fewer fingers",
    FailureKind.OBJECT_CLEARANCE: "lower RegraspParams.clearance_m (flights) or "
    "ContactModel.choice_link_clearance_m (new contacts), or use a larger object",
    FailureKind.GRID_UNREACHABLE: "lower RegraspParams.grid_spacing_m or the contact keep-out",
    FailureKind.NO_CANDIDATE: "lower ContactModel.choice_margin_rad or turn more slowly",
    FailureKind.FORCE_CLOSURE: "use more fingers, a higher friction coefficient mu, or soft "
    "fingertips (ContactModel.torsion_m) if the hand has them",
    FailureKind.TOO_LATE: "shorten RegraspParams.duration_s or extend the motion",
    FailureKind.SHORT_HOLD: "turn more slowly or place the object deeper in the fingers' workspace",
    FailureKind.FINGER_BUSY: "turn more slowly so that the fingers can take turns",
    FailureKind.TOO_FEW_FINGERS: "use more fingers, or soft fingertips (ContactModel.torsion_m: "
    "two fingers can then hold), or lower PlannerParams.min_holding",
    FailureKind.BUDGET: "raise the planner's budget (PlannerParams.max_steps, or budget_s if set)",
    FailureKind.INFEASIBLE: "turn less or about another axis, or place the object where that "
    "finger's contacts stay within its limits longer",
}


@dataclass(frozen=True)
class Attempt:
    """One failed attempt of a search, as data (JSON-serializable with :meth:`to_dict`).

    Attributes:
        kind: Why it failed.
        finger: The finger concerned (or None).
        time_s: When the failure happened [s] (or None).
        measured: The measured value (units by kind: m, rad, rad/s, ...), or None.
        required: The value that was required, or None.
        what: What was tried (e.g. ``"Q=(0.01, 0.02, 0.0) start=1.90 m=9"``).
        other: For ``finger-collision``, the finger it came too near, when known.
    """

    kind: FailureKind
    finger: str | None = None
    time_s: float | None = None
    measured: float | None = None
    required: float | None = None
    what: str = ""
    other: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """The attempt as JSON-serializable data (the kind by its value)."""
        d = asdict(self)
        d["kind"] = self.kind.value
        return d


def _where(finger: str | None, time_s: float | None) -> str:
    where = []
    if finger is not None:
        where.append(f"finger {finger!r}")
    if time_s is not None:
        where.append(f"t={time_s:.3f} s")
    return (", ".join(where) + ": ") if where else ""


class _Outcome(RegraspError):
    """An error with a :class:`FailureKind`, a finger, a time and measured numbers."""

    default_kind = FailureKind.BUDGET

    def __init__(
        self,
        reason: str,
        finger: str | None = None,
        time_s: float | None = None,
        *,
        kind: FailureKind | None = None,
        measured: float | None = None,
        required: float | None = None,
        attempts: Iterable[Attempt] = (),
        other: str | None = None,
    ) -> None:
        self.finger = finger
        self.time_s = time_s
        self.reason = reason
        self.kind = FailureKind(self.default_kind if kind is None else kind)
        self.measured = None if measured is None else float(measured)
        self.required = None if required is None else float(required)
        self.attempts = tuple(attempts)
        self.other = other
        super().__init__(_where(finger, time_s) + reason)

    def as_attempt(self, what: str = "") -> Attempt:
        """This failure as an :class:`Attempt` record."""
        return Attempt(
            kind=self.kind,
            finger=self.finger,
            time_s=self.time_s,
            measured=self.measured,
            required=self.required,
            what=what,
            other=self.other,
        )


class ContactError(_Outcome):
    """No feasible contact could be found (initial grasp or new contact Q).

    Attributes:
        finger: The finger concerned (or None for the whole grasp).
        time_s: The time at which it was needed [s] (or None).
        reason: Why no contact could be found.
        kind: A :class:`FailureKind` (default ``NO_CANDIDATE``).
        measured, required: The numbers behind the failure, when there are any.
        attempts: Failed attempts that led here, as data.
        other: For ``finger-collision``, the finger it came too near, when known.
    """

    default_kind = FailureKind.NO_CANDIDATE


class PlanningError(_Outcome):
    """A regrasp or a whole-hand plan could not be found and verified.

    Attributes:
        finger: The finger concerned (or None).
        time_s: When the failure happened [s] (or None).
        reason: What failed, in plain words.
        kind: A :class:`FailureKind`: what the failure was (default ``BUDGET``).
        measured, required: The numbers behind it (units by kind), when there are any.
        attempts: Every failed attempt of the search that led here, as data.
        other: For ``finger-collision``, the finger it came too near, when known.
        partial: Whatever was planned before the failure (e.g. a partial plan), or None.
    """

    def __init__(
        self,
        reason: str,
        finger: str | None = None,
        time_s: float | None = None,
        partial: Any = None,
        **outcome: Any,
    ) -> None:
        super().__init__(reason, finger, time_s, **outcome)
        self.partial = partial


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
