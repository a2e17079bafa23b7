"""Building a scenario from its spec, and the suite's scenarios that have an initial grasp."""

from __future__ import annotations

import dataclasses
import functools
import logging
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from .._validate import positive_int
from ..exceptions import Attempt, ContactError
from ..grasp.contact import ContactModel
from ..grasp.holding import rest_configuration
from ..model.clearance import FingerClearance
from ..model.hand import Hand
from ..model.motion import ObjectMotion
from ..model.objects import ConvexObject
from ..planning.params import with_time_law
from ..scenarios import (
    GraspSearch,
    Scenario,
    describe,
    hand_model,
    is_hand_file,
    scenario_for_hand,
    scenario_params,
    setup_fingers,
    setup_pose,
    setup_time_law,
    turn_about_thumb_contact,
)
from .specs import MAX_DRAWS_PER_SCENARIO, ScenarioSpec, generate_specs

__all__ = ["MAX_DRAWS_PER_SCENARIO", "build_scenario", "suite_hand", "suite_scenarios"]

log = logging.getLogger(__name__)


@functools.cache
def suite_hand(name: str) -> Hand:
    """The hand of a spec (:func:`~regrasp_pin.scenarios.hand_model`), built once per
    name and process: its fingers' caches (workspace covers, pad directions) then serve
    every scenario of the process (and of the processes forked from it, see
    :mod:`.warm`)."""
    return hand_model(name)


def finger_clearance(
    hand: Hand, obj: ConvexObject, motion: ObjectMotion, fingers: tuple[str, ...], margin: float
) -> Any:
    """``q_fingers -> smallest finger-finger distance - margin`` [m] for initial_grasp."""
    idle = [n for n in hand.finger_names if n not in fingers]
    base = rest_configuration(hand, obj, motion, idle)
    checks = [FingerClearance(hand, n) for n in fingers]

    def clearance(q_fingers: dict[str, np.ndarray]) -> float:
        q = base.copy()
        for n, qn in q_fingers.items():
            q[hand.fingers[n].q_indices] = qn
        return min(c(q) for c in checks) - margin

    return clearance


def build_scenario(spec: ScenarioSpec, contact: ContactModel | None = None) -> Scenario:
    """Build the scenario of a spec.

    The object starts at the hand's canonical pose (:func:`~regrasp_pin.scenarios.setup_pose`)
    moved by the spec's offsets. The initial grasp is chosen by
    :func:`~regrasp_pin.grasp.initial.initial_grasp` for a turn about an axis through the
    object's centre: the motion itself for ``"object-axis"`` and
    ``"rotate-translate"``, the turn about the object's z axis for ``"contact-axis"``,
    whose motion is then placed about the thumb's contact (as
    :func:`~regrasp_pin.scenarios.make_scenario`; a neighbour spec builds the same scenario).
    A hand file's ``"contact-axis"`` spec is built by
    :func:`~regrasp_pin.scenarios.scenario_for_hand` at the spec's pose.

    Args:
        spec: The spec.
        contact: The contact model of the grasp search and the planner (default
            ``ContactModel()``: each finger's own pad cone).

    Returns:
        The :class:`~regrasp_pin.scenarios.Scenario` (planner settings as make_scenario's,
        the regrasps by the hand's time law: :func:`~regrasp_pin.scenarios.setup_time_law`).

    Raises:
        ContactError: no initial force-closure grasp.
    """
    scen = _build(spec, contact)
    return dataclasses.replace(scen, params=with_time_law(scen.params, setup_time_law(spec.hand)))


def _build(spec: ScenarioSpec, contact: ContactModel | None) -> Scenario:
    """:func:`build_scenario`'s scenario before the hand's time law is set."""
    h = suite_hand(spec.hand)
    o = spec.object.build()
    m = spec.motion
    T0 = setup_pose(spec.hand) if spec.base_pose is None else np.reshape(spec.base_pose, (4, 4))
    T0[:3, :3] = Rotation.from_rotvec(spec.rotation_offset_rotvec).as_matrix() @ T0[:3, :3]
    T0[:3, 3] = T0[:3, 3] + np.asarray(spec.position_offset_m)
    fingers = setup_fingers(spec.hand)
    contact = contact or ContactModel()
    if is_hand_file(spec.hand) and m.kind == "contact-axis" and spec.grasp_clearance_m is None:
        # any hand: as scenario_for_hand builds it (the pivot's contact kept, the other
        # fingers' chosen again for the turn about it)
        scen = scenario_for_hand(
            h,
            o,
            fingers=fingers,
            angle_deg=m.angle_deg,
            rate_deg_s=m.rate_deg_s,
            pose=T0,
            dt_s=m.dt_s,
            seed=spec.seed,
            contact=contact,
        )
        return dataclasses.replace(scen, name=spec.name)
    rate_rad = np.sign(m.angle_deg) * np.radians(m.rate_deg_s)
    duration = m.duration_s
    if m.kind == "contact-axis":
        axis = T0[:3, :3] @ np.array([0.0, 0.0, 1.0])
        velocity = np.zeros(3)
        what_axis = "the axis through the thumb's contact"
    else:
        axis = T0[:3, :3] @ np.asarray(m.axis_object)
        velocity = np.asarray(m.translation_m) / duration
        what_axis = "an axis through its centre" + (
            f", drifting {np.linalg.norm(m.translation_m) * 1e3:.1f} mm"
            if m.kind == "rotate-translate"
            else ""
        )
    turn = ObjectMotion.constant_twist(
        T0,
        axis_palm=axis,
        point_palm=T0[:3, 3],
        rate_rad_s=rate_rad,
        velocity_palm_m_s=velocity,
        duration_s=duration,
        dt_s=m.dt_s,
    )
    clearance = (
        None
        if spec.grasp_clearance_m is None
        else finger_clearance(h, o, turn, fingers, spec.grasp_clearance_m)
    )
    search = GraspSearch(
        turn,
        fingers,
        contact,
        grasp_dt_s=spec.grasp_dt_s,
        horizon_s=spec.grasp_horizon_s,
        seed=spec.seed,
        finger_clearance=clearance,
        must_hold_check=m.kind != "contact-axis",  # the grasp's turn is the motion
        pivot="thumb" if m.kind == "contact-axis" else None,
    )
    grasp = search.choose(h, o)
    motion = (
        turn_about_thumb_contact(T0, grasp, axis, rate_rad, duration, m.dt_s)
        if m.kind == "contact-axis"
        else turn
    )
    return Scenario(
        name=spec.name,
        hand=h,
        obj=o,
        motion=motion,
        grasp=grasp,
        params=scenario_params(fingers, contact),
        description=describe(
            h,
            o,
            fingers,
            float(m.angle_deg),
            float(m.rate_deg_s),
            f"{o.kind} ({spec.object.label})",
            what_axis,
        ),
        grasp_search=search,
    )


def suite_scenarios(n: int, seed: int = 0) -> list[tuple[ScenarioSpec, Scenario]]:
    """The first ``n`` specs of the suite ``seed`` that have an initial grasp, built.

    Specs whose build raises :class:`~regrasp_pin.exceptions.ContactError` are skipped (the same
    ones on every run); at most ``4 n`` specs are drawn.

    Raises:
        InputError: negative ``n`` or ``seed``.
        ContactError: fewer than ``n`` of the ``4 n`` specs have an initial grasp; its
            ``attempts`` list every skipped spec (``what`` is the spec's name).
    """
    n = positive_int(n, "n", minimum=0)
    out: list[tuple[ScenarioSpec, Scenario]] = []
    skipped: list[Attempt] = []
    draws = MAX_DRAWS_PER_SCENARIO * n
    for spec in generate_specs(draws, seed):
        if len(out) == n:
            break
        try:
            out.append((spec, build_scenario(spec)))
        except ContactError as exc:
            log.info("suite: %s skipped, no initial grasp: %s", spec.name, exc)
            skipped.append(exc.as_attempt(what=spec.name))
    if len(out) < n:
        raise ContactError(
            f"only {len(out)} of {draws} specs of suite seed {seed} have an initial grasp "
            f"(need {n})",
            measured=len(out),
            required=n,
            attempts=skipped,
        )
    return out
