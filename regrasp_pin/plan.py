"""The plan file: a whole-hand manipulation plan as JSON (format ``regrasp_pin.plan/1``).

A plan stores, at strictly increasing times ``t`` [s], the full hand configuration
``q`` (in the order of the hand's Pinocchio model, :meth:`Plan.load_hand`) and the object pose
``T_palm_object`` as ``[x, y, z, qx, qy, qz, qw]`` (palm frame). Linear interpolation of
``q`` and slerp of the pose between consecutive samples *is* the motion that was
verified. ``phases`` says, per finger, when it held which contact and when it
regrasped or let go. See ``docs/plan_format.md`` for every field.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ._validate import as_array, positive
from .exceptions import InputError, ModelFileError
from .model.objects import OBJECT_KINDS

if TYPE_CHECKING:  # imported lazily at run time
    from .model.hand import Hand
    from .model.objects import ConvexObject

__all__ = [
    "PLAN_FORMAT",
    "ContactPhase",
    "IdlePhase",
    "JoinPhase",
    "Plan",
    "RegraspPhase",
    "ReleasePhase",
    "hand_record",
    "repo_root",
]

PLAN_FORMAT = "regrasp_pin.plan/1"


def repo_root() -> Path:
    """The folder that holds ``urdf/`` for the bundled hands (the repository root)."""
    return Path(__file__).resolve().parent.parent


def hand_record(hand: Hand) -> dict[str, Any]:
    """The plan file's ``hand`` entry: what rebuilds the hand, here or elsewhere.

    The URDF's absolute path and its text, the folder it was in (meshes are looked up
    there), how it was loaded (``palm_frame``, ``locked``, ``couplings``) and the fingers.
    """
    urdf = hand.urdf_path.resolve()
    record: dict[str, Any] = {
        "name": hand.name,
        "urdf": str(urdf),
        "urdf_text": hand.urdf_text,
        "package_dirs": [str(d) for d in hand.package_dirs] + [str(urdf.parent)],
        "fingers": {
            n: {"tip_frame": f.tip_frame, "tip_radius": f.tip_radius, "joints": list(f.joint_names)}
            for n, f in hand.fingers.items()
        },
    }
    if hand.load_options:
        record["load_options"] = hand.load_options
    return record


@dataclass(frozen=True)
class ContactPhase:
    """A finger holds a contact fixed in the object frame from ``t_start`` to ``t_end`` [s].

    Attributes:
        finger: Finger name.
        t_start: Start time [s].
        t_end: End time [s].
        p_object: Contact point on the surface, object frame ``(3,)`` [m].
        n_object: Outward surface normal at the contact, object frame ``(3,)``.
    """

    finger: str
    t_start: float
    t_end: float
    p_object: np.ndarray
    n_object: np.ndarray
    kind: str = field(default="contact", init=False)

    def to_dict(self) -> dict[str, Any]:
        """The phase as plan-file data (JSON types)."""
        return {
            "finger": self.finger,
            "kind": self.kind,
            "t_start": self.t_start,
            "t_end": self.t_end,
            "p_object": np.asarray(self.p_object).tolist(),
            "n_object": np.asarray(self.n_object).tolist(),
        }


@dataclass(frozen=True)
class RegraspPhase:
    """A finger moves from contact P to contact Q from ``t_start`` to ``t_end`` [s].

    Attributes:
        finger: Finger name.
        t_start: Lift-off time [s].
        t_end: Landing time [s].
        P_object: Old contact, object frame ``(3,)`` [m].
        Q_object: New contact, object frame ``(3,)`` [m].
        waypoints_object: Hopfield waypoints of the fingertip centre, object frame
            ``(m, 3)`` [m].
        min_clearance_m: Smallest clearance margin found by the Coal verification [m].
        planning_ms: Time spent planning and verifying this regrasp [ms].
        reason: Why the finger regrasped when it did.
        extra: Further JSON-able data (grid path, tip path, stage times, ...).
    """

    finger: str
    t_start: float
    t_end: float
    P_object: np.ndarray
    Q_object: np.ndarray
    waypoints_object: np.ndarray
    min_clearance_m: float
    planning_ms: float
    reason: str = ""
    extra: dict[str, Any] = field(default_factory=dict)
    kind: str = field(default="regrasp", init=False)

    def to_dict(self) -> dict[str, Any]:
        """The phase as plan-file data (JSON types)."""
        d = {
            "finger": self.finger,
            "kind": self.kind,
            "t_start": self.t_start,
            "t_end": self.t_end,
            "P_object": np.asarray(self.P_object).tolist(),
            "Q_object": np.asarray(self.Q_object).tolist(),
            "waypoints_object": np.asarray(self.waypoints_object).tolist(),
            "min_clearance_m": self.min_clearance_m,
            "planning_ms": self.planning_ms,
            "reason": self.reason,
        }
        d.update(self.extra)
        return d


@dataclass(frozen=True)
class ReleasePhase:
    """A finger lets go of contact P at ``t_start`` and stays off to ``t_end`` [s]: the
    end of the plan, or the start of its ``join`` if it joins again.

    Its fingertip backs off along the contact normal and the finger then stays still
    (:mod:`~regrasp_pin.planning.release`); the other fingers hold the object.

    Attributes:
        finger: Finger name.
        t_start: Release time [s].
        t_end: End of the plan, or when the finger starts to join again [s].
        P_object: The contact let go, object frame ``(3,)`` [m].
        min_clearance_m: Smallest finger-object distance after the back-off [m].
        reason: Why the finger let go.
    """

    finger: str
    t_start: float
    t_end: float
    P_object: np.ndarray
    min_clearance_m: float
    reason: str = ""
    kind: str = field(default="release", init=False)

    def to_dict(self) -> dict[str, Any]:
        """The phase as plan-file data (JSON types)."""
        return {
            "finger": self.finger,
            "kind": self.kind,
            "t_start": self.t_start,
            "t_end": self.t_end,
            "P_object": np.asarray(self.P_object).tolist(),
            "min_clearance_m": self.min_clearance_m,
            "reason": self.reason,
        }


@dataclass(frozen=True)
class JoinPhase:
    """A finger that does not hold (it took no part so far, or let go earlier) moves
    onto contact Q, from ``t_start`` to ``t_end`` [s]
    (:mod:`~regrasp_pin.planning.join`); it holds Q from ``t_end``.

    Attributes:
        finger: Finger name.
        t_start: When it starts to move [s].
        t_end: When its pad touches Q [s].
        Q_object: The new contact, object frame ``(3,)`` [m].
        min_clearance_m: Smallest finger-object distance before the approach [m].
        reason: Why it joins.
    """

    finger: str
    t_start: float
    t_end: float
    Q_object: np.ndarray
    min_clearance_m: float
    reason: str = ""
    kind: str = field(default="join", init=False)

    def to_dict(self) -> dict[str, Any]:
        """The phase as plan-file data (JSON types)."""
        return {
            "finger": self.finger,
            "kind": self.kind,
            "t_start": self.t_start,
            "t_end": self.t_end,
            "Q_object": np.asarray(self.Q_object).tolist(),
            "min_clearance_m": self.min_clearance_m,
            "reason": self.reason,
        }


@dataclass(frozen=True)
class IdlePhase:
    """A finger that takes no part rests, clear of the object and of the other fingers,
    from ``t_start`` to ``t_end`` [s]: a finger outside ``PlannerParams.fingers`` for
    the whole plan, or one that joins later (until its ``join`` phase).

    Attributes:
        finger: Finger name.
        t_start: Start [s].
        t_end: End [s].
    """

    finger: str
    t_start: float
    t_end: float
    kind: str = field(default="idle", init=False)

    def to_dict(self) -> dict[str, Any]:
        """The phase as plan-file data (JSON types)."""
        return {
            "finger": self.finger,
            "kind": self.kind,
            "t_start": self.t_start,
            "t_end": self.t_end,
        }


Phase = ContactPhase | RegraspPhase | ReleasePhase | JoinPhase | IdlePhase


def _phase_from_dict(d: dict[str, Any]) -> Phase:
    if d.get("kind") == "contact":
        return ContactPhase(
            finger=d["finger"],
            t_start=float(d["t_start"]),
            t_end=float(d["t_end"]),
            p_object=np.asarray(d["p_object"], float),
            n_object=np.asarray(d["n_object"], float),
        )
    if d.get("kind") == "regrasp":
        known = {
            "finger",
            "kind",
            "t_start",
            "t_end",
            "P_object",
            "Q_object",
            "waypoints_object",
            "min_clearance_m",
            "planning_ms",
            "reason",
        }
        return RegraspPhase(
            finger=d["finger"],
            t_start=float(d["t_start"]),
            t_end=float(d["t_end"]),
            P_object=np.asarray(d["P_object"], float),
            Q_object=np.asarray(d["Q_object"], float),
            waypoints_object=np.asarray(d["waypoints_object"], float),
            min_clearance_m=float(d["min_clearance_m"]),
            planning_ms=float(d["planning_ms"]),
            reason=str(d.get("reason", "")),
            extra={k: v for k, v in d.items() if k not in known},
        )
    if d.get("kind") == "release":
        return ReleasePhase(
            finger=d["finger"],
            t_start=float(d["t_start"]),
            t_end=float(d["t_end"]),
            P_object=np.asarray(d["P_object"], float),
            min_clearance_m=float(d["min_clearance_m"]),
            reason=str(d.get("reason", "")),
        )
    if d.get("kind") == "idle":
        return IdlePhase(finger=d["finger"], t_start=float(d["t_start"]), t_end=float(d["t_end"]))
    if d.get("kind") == "join":
        return JoinPhase(
            finger=d["finger"],
            t_start=float(d["t_start"]),
            t_end=float(d["t_end"]),
            Q_object=np.asarray(d["Q_object"], float),
            min_clearance_m=float(d["min_clearance_m"]),
            reason=str(d.get("reason", "")),
        )
    raise InputError(
        "phases",
        f"unknown phase kind {d.get('kind')!r}",
        "'contact', 'regrasp', 'release' or 'join'",
    )


@dataclass
class Plan:
    """A whole-hand plan (see the module docstring).

    Attributes:
        hand: ``{"name", "urdf", "urdf_text", "package_dirs", "load_options", "fingers":
            {name: {"tip_frame", "tip_radius", "joints"}}}`` (:func:`hand_record`).
        object: ``{"kind", "params", "vertices", "faces"}`` (mesh in the object frame).
        t: Sample times ``(S,)`` [s], strictly increasing.
        q: Full hand configurations ``(S, nq)`` [rad].
        T_palm_object: Object poses ``(S, 7)`` as ``[x, y, z, qx, qy, qz, qw]``.
        phases: Per finger, its phases in time order.
        summary: Free-form summary (totals, timings).
        mu: The friction coefficient the plan was made for (None: not recorded, as in
            older plans); the re-check verifies force closure with it.
        torsion_m: The soft-finger torsional friction the plan was made for [m]
            (:attr:`~regrasp_pin.grasp.contact.ContactModel.torsion_m`; 0: point
            contacts, also for plans that do not record it); the re-check verifies
            force closure with it.
    """

    hand: dict[str, Any]
    object: dict[str, Any]
    t: np.ndarray
    q: np.ndarray
    T_palm_object: np.ndarray
    phases: dict[str, list[Phase]]
    summary: dict[str, Any] = field(default_factory=dict)
    mu: float | None = None
    torsion_m: float = 0.0

    def __repr__(self) -> str:
        phases = {f: len(ps) for f, ps in self.phases.items()}
        return (
            f"Plan(hand={self.hand.get('name')!r}, object={self.object.get('kind')!r}, "
            f"{self.t.size} samples over [{self.t[0]:g}, {self.t[-1]:g}] s, phases={phases})"
        )

    def __post_init__(self) -> None:
        self.t = as_array(self.t, "t", (None,))
        if self.t.size < 2 or np.any(np.diff(self.t) <= 0):
            raise InputError("t", "is not strictly increasing with >= 2 samples", "times [s]")
        self.q = as_array(self.q, "q", (self.t.size, None))
        self.T_palm_object = as_array(self.T_palm_object, "T_palm_object", (self.t.size, 7))
        if self.mu is not None:
            self.mu = positive(self.mu, "mu", allow_zero=True)
        self.torsion_m = positive(self.torsion_m, "torsion_m", allow_zero=True)

    # ------------------------------------------------------------------ I/O
    def to_dict(self) -> dict[str, Any]:
        """The JSON document as a dict."""
        return {
            "format": PLAN_FORMAT,
            "hand": self.hand,
            "object": self.object,
            "t": self.t.tolist(),
            "q": self.q.tolist(),
            "T_palm_object": self.T_palm_object.tolist(),
            "phases": {f: [p.to_dict() for p in ps] for f, ps in self.phases.items()},
            "summary": self.summary,
            **({} if self.mu is None else {"mu": self.mu}),
            **({"torsion_m": self.torsion_m} if self.torsion_m > 0.0 else {}),
        }

    def save(self, path: str | Path) -> Path:
        """Write the plan as JSON; returns the path."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.to_dict()))
        return path

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Plan:
        """Build a plan from its JSON document.

        Raises:
            InputError: wrong ``format`` or malformed fields.
        """
        if not isinstance(d, dict):
            raise InputError(
                "plan", f"is a JSON {type(d).__name__}", "a JSON object (regrasp_pin.plan/1)"
            )
        if d.get("format") != PLAN_FORMAT:
            raise InputError("format", f"is {d.get('format')!r}", repr(PLAN_FORMAT))
        obj = d.get("object")
        kind = obj.get("kind") if isinstance(obj, dict) else None
        if kind not in OBJECT_KINDS:
            raise InputError("object.kind", f"is {kind!r}", f"one of {OBJECT_KINDS}")
        try:
            phases = {f: [_phase_from_dict(p) for p in ps] for f, ps in d["phases"].items()}
            return cls(
                hand=d["hand"],
                object=d["object"],
                t=np.asarray(d["t"], float),
                q=np.asarray(d["q"], float),
                T_palm_object=np.asarray(d["T_palm_object"], float),
                phases=phases,
                summary=d.get("summary", {}),
                mu=d.get("mu"),
                torsion_m=d.get("torsion_m", 0.0),
            )
        except KeyError as exc:
            raise InputError(
                "plan", f"missing field {exc}", "a regrasp_pin.plan/1 document"
            ) from None

    @classmethod
    def load(cls, path: str | Path) -> Plan:
        """Read a plan file.

        Raises:
            ModelFileError: the file does not exist or is not JSON.
            InputError: the document is not a ``regrasp_pin.plan/1`` plan.
        """
        path = Path(path)
        if not path.is_file():
            raise ModelFileError(path, "no such plan file")
        try:
            d = json.loads(path.read_text())
        except json.JSONDecodeError as exc:
            raise ModelFileError(path, f"not JSON: {exc}") from None
        return cls.from_dict(d)

    # ------------------------------------------------------------- accessors
    @property
    def urdf_path(self) -> Path:
        """Path of the hand's URDF where the plan was made (older plans stored bundled
        hands relative to the repository)."""
        p = Path(self.hand["urdf"])
        return p if p.is_absolute() else repo_root() / p

    def load_hand(self, package_dirs: list[str | Path] | None = None) -> Hand:
        """Rebuild the :class:`~regrasp_pin.model.hand.Hand` the plan was made with.

        The URDF is the text stored in the plan (the model the plan was made with, even
        if the file at :attr:`urdf_path` changed since), or that file for plans that
        store no text; meshes are looked up in ``package_dirs``, then in the folders the
        plan stored, then where ``ROS_PACKAGE_PATH`` says (see docs/plan_format.md).

        Raises:
            ModelFileError: the URDF is neither at its path nor stored, or Pinocchio
                cannot load it (a mesh that is not found names the folders searched).
        """
        from .model.hand import Hand

        h = self.hand
        fingers = {n: f["tip_frame"] for n, f in h["fingers"].items()}
        radii = {n: float(f["tip_radius"]) for n, f in h["fingers"].items()}
        options = dict(h.get("load_options", {}))
        if "couplings" in options:
            options["couplings"] = {k: tuple(v) for k, v in options["couplings"].items()}
        return Hand.from_urdf(
            self.urdf_path,
            fingers,
            tip_radius=radii,
            name=h.get("name"),
            urdf_text=self._urdf_text(),
            package_dirs=self._package_dirs(package_dirs),
            **options,
        )

    def _urdf_text(self) -> str | None:
        text = self.hand.get("urdf_text")
        if isinstance(text, str):
            return text
        if not self.urdf_path.is_file():
            raise ModelFileError(self.urdf_path, "no such URDF file, and the plan stores no text")
        return None

    def _package_dirs(self, given: list[str | Path] | None) -> list[str] | None:
        stored = [str(d) for d in self.hand.get("package_dirs", [])]
        dirs = [str(d) for d in (given or [])] + stored
        return dirs or None

    def load_object(self) -> ConvexObject:
        """Rebuild the object from its kind and parameters."""
        from .model.objects import object_from_params

        return object_from_params(self.object["kind"], self.object["params"])

    def poses(self) -> np.ndarray:
        """Object poses ``(S, 4, 4)`` in the palm frame."""
        from scipy.spatial.transform import Rotation

        T = np.zeros((self.t.size, 4, 4))
        T[:, :3, :3] = Rotation.from_quat(self.T_palm_object[:, 3:]).as_matrix()
        T[:, :3, 3] = self.T_palm_object[:, :3]
        T[:, 3, 3] = 1.0
        return T

    def regrasps(self) -> list[RegraspPhase]:
        """All regrasp phases, in time order."""
        out = [p for ps in self.phases.values() for p in ps if isinstance(p, RegraspPhase)]
        return sorted(out, key=lambda p: p.t_start)

    def releases(self) -> list[ReleasePhase]:
        """All release phases, in time order."""
        out = [p for ps in self.phases.values() for p in ps if isinstance(p, ReleasePhase)]
        return sorted(out, key=lambda p: p.t_start)

    def joins(self) -> list[JoinPhase]:
        """All join phases, in time order."""
        out = [p for ps in self.phases.values() for p in ps if isinstance(p, JoinPhase)]
        return sorted(out, key=lambda p: p.t_start)

    def idles(self) -> list[IdlePhase]:
        """All idle phases, in time order."""
        out = [p for ps in self.phases.values() for p in ps if isinstance(p, IdlePhase)]
        return sorted(out, key=lambda p: (p.t_start, p.finger))
