"""Failures as data: kinds, attempts, the dominant cause."""

from __future__ import annotations

import json

from regrasp_pin.exceptions import ADVICE, Attempt, ContactError, FailureKind, PlanningError
from regrasp_pin.planning.outcomes import dominant_kind, failure_summary

K = FailureKind


def test_every_kind_has_advice():
    assert set(ADVICE) == set(FailureKind)


def test_dominant_kind_is_the_most_frequent_with_ties_in_enum_order():
    a = [Attempt(K.VELOCITY), Attempt(K.FINGER_COLLISION), Attempt(K.FINGER_COLLISION)]
    assert dominant_kind(a, K.BUDGET) == K.FINGER_COLLISION
    tie = [Attempt(K.FINGER_COLLISION), Attempt(K.VELOCITY)]
    assert dominant_kind(tie, K.BUDGET) == K.VELOCITY  # VELOCITY precedes in FailureKind
    assert dominant_kind(list(reversed(tie)), K.BUDGET) == K.VELOCITY  # order-independent
    assert dominant_kind([], K.NO_CANDIDATE) == K.NO_CANDIDATE


def test_failure_summary_counts_and_advises():
    a = [Attempt(K.IK_UNREACHABLE)] * 2 + [Attempt(K.GRID_UNREACHABLE)]
    text = failure_summary(a, K.BUDGET)
    assert "3 attempts failed" in text and "2 ik-unreachable" in text
    assert ADVICE[K.IK_UNREACHABLE] in text


def test_errors_carry_kind_numbers_and_json_attempts():
    att = Attempt(K.VELOCITY, "index", 1.25, measured=5.0, required=4.0, what="start 1.2 s")
    err = PlanningError(
        "too fast",
        finger="index",
        time_s=1.25,
        kind=K.VELOCITY,
        measured=5.0,
        required=4.0,
        attempts=[att],
    )
    assert err.kind is K.VELOCITY and err.measured == 5.0 and err.required == 4.0
    assert str(err) == "finger 'index', t=1.250 s: too fast"
    d = json.loads(json.dumps([a.to_dict() for a in err.attempts]))
    assert d == [
        {
            "kind": "velocity",
            "finger": "index",
            "time_s": 1.25,
            "measured": 5.0,
            "required": 4.0,
            "what": "start 1.2 s",
        }
    ]
    assert err.as_attempt("x").kind is K.VELOCITY
    assert ContactError("none").kind is K.NO_CANDIDATE
