"""Summaries of failed attempts: the dominant cause and what to change."""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence

from ..exceptions import ADVICE, Attempt, FailureKind

__all__ = [
    "CROSSES",
    "DISTANCE_KINDS",
    "INSIDE",
    "OTHERS_THERE",
    "SINKS_IN",
    "dominant_kind",
    "failure_summary",
    "nearest_miss",
]

_ORDER = {k: i for i, k in enumerate(FailureKind)}
#: kinds whose measured and required numbers are distances [m], failed below
DISTANCE_KINDS = (FailureKind.OBJECT_CLEARANCE, FailureKind.FINGER_COLLISION)
# what to change for an object-clearance failure by what was missed: a penetration
# allowed (a negative requirement: the fingertip link pressing into a face), or a
# clearance with the finger inside the object (which no clearance setting meets)
SINKS_IN = (
    "the fingertip link sinks into the face the tip rests on: raise "
    "ContactModel.tip_penetration_m (to {depth_mm:.2f} mm) if the fingertip is that soft, "
    "or place the object where the finger meets its faces squarely"
)
INSIDE = (
    "every contact or path tried puts a link of the finger into the object: place the "
    "object where the finger reaches it from outside, or turn it less"
)
# a finger-collision failure whose nearest attempt still has the finger inside another
# (a negative distance): the fingers cross, which no clearance setting mends
CROSSES = (
    "every contact or path tried puts the finger into another finger (they cross, not "
    "just come near): start from a grasp whose fingers stand further apart (the grasp "
    "search's finger_clearance), or plan with fewer fingers"
)

# a no-candidate failure of a regrasp's choice of Q (choose_new_contact) whose finger
# has contacts inside its joint limits with the choice margin (a positive count
# measured): the choice's other tests left none
OTHERS_THERE = (
    "the finger has contacts inside its joint limits at arrival ({count:.0f} at the "
    "last attempt), but they lie where the other fingers hold, near its own contact or "
    "near contacts that failed before: use fingers that are further apart, or fewer "
    "fingers, or turn more slowly"
)


def dominant_kind(attempts: Sequence[Attempt], default: FailureKind) -> FailureKind:
    """The most frequent kind among ``attempts`` (ties: the first in :class:`FailureKind`)."""
    if not attempts:
        return default
    counts = Counter(a.kind for a in attempts)
    return min(counts, key=lambda k: (-counts[k], _ORDER[k]))


def nearest_miss(attempts: Sequence[Attempt], kind: FailureKind) -> Attempt | None:
    """Of the ``kind`` attempts whose numbers are distances (object clearance, finger
    collision: failed when ``measured < required`` [m]), the one nearest to passing
    (the largest ``measured - required``; the first of equals); None for other kinds
    or when none has both numbers."""
    if kind not in DISTANCE_KINDS:
        return None
    margins = [
        (a.measured - a.required, a)
        for a in attempts
        if a.kind == kind and a.measured is not None and a.required is not None
    ]
    known = [(m, a) for m, a in margins if math.isfinite(m)]
    return max(known, key=lambda ma: ma[0])[1] if known else None  # the first of equals


def failure_summary(attempts: Sequence[Attempt], default: FailureKind) -> str:
    """One sentence: how many attempts failed, the dominant cause (for distances, with
    the attempt nearest to passing) and what to change."""
    kind = dominant_kind(attempts, default)
    counts = Counter(a.kind for a in attempts)
    parts = ", ".join(
        f"{n} {k.value}" for k, n in sorted(counts.items(), key=lambda kv: _ORDER[kv[0]])
    )
    head = f"{len(attempts)} attempts failed ({parts}); " if attempts else ""
    near = nearest_miss(attempts, kind)
    others = Counter(a.other for a in attempts if a.kind == kind and a.other is not None)
    mostly = f"{head}mostly {kind.value}{_others(others)}"
    if near is None:
        return f"{mostly}: {_advice_without_distance(attempts, kind)}"
    return f"{mostly}{_numbers(near, len(others) > 1)}: {_advice(near)}"


def _others(counts: Counter[str]) -> str:
    """The fingers that attempts came too near (finger collisions) and how often:
    most often first, then by name; "" when none is named."""
    if not counts:
        return ""
    ranked = sorted(counts.items(), key=lambda kv: (-kv[1], kv[0]))
    return " near " + ", ".join(f"{name} ({n})" for name, n in ranked)


def _advice_without_distance(attempts: Sequence[Attempt], kind: FailureKind) -> str:
    """What to change for a failure whose numbers are not distances: for
    ``no-candidate``, by the last such attempt's count of contacts inside the joint
    limits with the choice margin (none: the limits; some: the choice's other tests)."""
    if kind == FailureKind.NO_CANDIDATE:
        last = next((a for a in reversed(attempts) if a.kind == kind), None)
        if last is not None and last.measured is not None and last.measured > 0:
            return OTHERS_THERE.format(count=last.measured)
    return ADVICE[kind]


def _numbers(near: Attempt, name_other: bool = False) -> str:
    """The nearest miss's numbers [mm], and with ``name_other`` the finger it came
    too near."""
    assert near.measured is not None and near.required is not None
    other = "" if near.other is None or not name_other else f" from {near.other}"
    return f" (the nearest {near.measured * 1e3:.2f} mm{other}, need {near.required * 1e3:.2f} mm)"


def _advice(near: Attempt) -> str:
    """What to change, by the numbers of the attempt nearest to passing."""
    assert near.measured is not None and near.required is not None
    if near.kind == FailureKind.OBJECT_CLEARANCE and near.required < 0.0:
        return SINKS_IN.format(depth_mm=-near.measured * 1e3)
    if near.kind == FailureKind.OBJECT_CLEARANCE and near.measured < 0.0:
        return INSIDE
    if near.kind == FailureKind.FINGER_COLLISION and near.measured < 0.0:
        return CROSSES
    return ADVICE[near.kind]
