"""Failures as data: kinds, attempts, the dominant cause."""

from __future__ import annotations

import json

from regrasp_pin.exceptions import (
    ADVICE,
    Attempt,
    ContactError,
    FailureKind,
    PlanningError,
)
from regrasp_pin.planning.outcomes import (
    CROSSES,
    INSIDE,
    OTHERS_THERE,
    SINKS_IN,
    dominant_kind,
    failure_summary,
    nearest_miss,
)

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


def test_no_candidate_advice_tells_the_limits_from_the_other_tests():
    """A choice that found no contact inside the limits with the choice margin (a count
    of 0) is told to lower that margin or turn more slowly; one that found some (the
    last attempt's count) is told that the other fingers and the exclusions took them."""
    none_inside = [Attempt(K.NO_CANDIDATE, measured=3.0), Attempt(K.NO_CANDIDATE, measured=0.0)]
    assert failure_summary(none_inside, K.BUDGET).endswith(ADVICE[K.NO_CANDIDATE])
    taken = list(reversed(none_inside))
    text = failure_summary(taken, K.BUDGET)
    assert text.endswith(OTHERS_THERE.format(count=3.0)) and "(3 at the last attempt)" in text
    no_numbers = [Attempt(K.NO_CANDIDATE)]
    assert failure_summary(no_numbers, K.BUDGET).endswith(ADVICE[K.NO_CANDIDATE])


def test_failure_summary_gives_the_nearest_miss_and_advice_by_its_sign():
    """Distances: the attempt nearest to passing (largest measured - required) is
    quoted; a fingertip link sinking in (a negative requirement) is told the penetration
    setting, a link inside the object (negative, with a clearance required) that no
    setting helps, one short of the clearance the clearance settings."""
    short = [
        Attempt(K.OBJECT_CLEARANCE, measured=0.0010, required=0.003),
        Attempt(K.OBJECT_CLEARANCE, measured=0.0025, required=0.003),
        Attempt(K.VELOCITY, measured=9.0, required=7.0),
    ]
    assert nearest_miss(short, K.OBJECT_CLEARANCE) is short[1]
    assert nearest_miss(short, K.VELOCITY) is None  # not a distance
    text = failure_summary(short, K.BUDGET)
    assert "the nearest 2.50 mm, need 3.00 mm" in text and ADVICE[K.OBJECT_CLEARANCE] in text
    inside = [
        Attempt(K.OBJECT_CLEARANCE, measured=-0.0133, required=0.003),
        Attempt(K.OBJECT_CLEARANCE),  # no numbers: ignored
    ]
    text = failure_summary(inside, K.BUDGET)
    assert "the nearest -13.30 mm, need 3.00 mm" in text and text.endswith(INSIDE)
    sinks = [*inside, Attempt(K.OBJECT_CLEARANCE, measured=-0.0008, required=-5e-5)]
    text = failure_summary(sinks, K.BUDGET)
    assert "the nearest -0.80 mm, need -0.05 mm" in text
    # the penetration the fingertip would have to allow, the depth the nearest one sank
    assert "tip_penetration_m (to 0.80 mm)" in text
    assert text.endswith(SINKS_IN.format(depth_mm=0.8))
    assert failure_summary([Attempt(K.OBJECT_CLEARANCE)], K.BUDGET).endswith(
        ADVICE[K.OBJECT_CLEARANCE]
    )


def test_finger_collision_advice_tells_crossing_fingers_from_near_misses():
    """A finger-collision failure whose nearest attempt has the finger inside another
    (a negative distance) is told that the fingers cross; one that only came too near
    keeps the clearance advice."""
    crossing = [
        Attempt(K.FINGER_COLLISION, measured=-0.0046, required=0.001),
        Attempt(K.FINGER_COLLISION, measured=-0.0009, required=0.001),
    ]
    text = failure_summary(crossing, K.BUDGET)
    assert "the nearest -0.90 mm, need 1.00 mm" in text and text.endswith(CROSSES)
    near = [*crossing, Attempt(K.FINGER_COLLISION, measured=0.0006, required=0.001)]
    text = failure_summary(near, K.BUDGET)
    assert "the nearest 0.60 mm, need 1.00 mm" in text
    assert text.endswith(ADVICE[K.FINGER_COLLISION])


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
            "other": None,
        }
    ]
    assert err.as_attempt("x").kind is K.VELOCITY
    assert ContactError("none").kind is K.NO_CANDIDATE


def test_finger_collision_summary_names_the_fingers_come_near():
    """A finger-collision summary names the fingers its attempts came too near, most
    often first (ties by name), and the nearest miss's where they differ; attempts of
    other kinds and attempts that do not know the finger are not counted."""
    attempts = [
        Attempt(K.FINGER_COLLISION, measured=-0.002, required=0.001, other="ring"),
        Attempt(K.FINGER_COLLISION, measured=0.0004, required=0.001, other="middle"),
        Attempt(K.FINGER_COLLISION, measured=-0.001, required=0.001, other="ring"),
        Attempt(K.FINGER_COLLISION, measured=-0.003, required=0.001),
        Attempt(K.FINGER_COLLISION, measured=-0.003, required=0.001, other="index"),
        Attempt(K.OBJECT_CLEARANCE, measured=0.001, required=0.003, other="thumb"),
    ]
    text = failure_summary(attempts, K.BUDGET)
    assert "mostly finger-collision near ring (2), index (1), middle (1) (" in text
    assert "the nearest 0.40 mm from middle, need 1.00 mm" in text
    assert "thumb" not in text
    # one finger named: the nearest miss's is that one, not named twice
    one = failure_summary(attempts[:3], K.BUDGET)
    assert "mostly finger-collision near ring (2), middle (1) (the nearest 0.40 mm from" in one
    alone = failure_summary(attempts[:1], K.BUDGET)
    assert "mostly finger-collision near ring (1) (the nearest -2.00 mm, need" in alone
    assert "mostly finger-collision (the nearest" in failure_summary(attempts[3:4], K.BUDGET)
