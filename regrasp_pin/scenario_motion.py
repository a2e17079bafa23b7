"""A scenario for a user's own motion: any hand, any object, the motion as relative poses.

The motion is given relative to the object's start pose, in the object's frame at the
start, ``T_rel(t)`` with ``T_rel(t_start) = I``: a turn about an axis through a point of
the object (:func:`relative_twist`) or timed poses from a CSV file
(:func:`relative_motion_from_csv`). :func:`scenario_for_motion` then finds where to
hold the object (the start pose ``T0`` in the palm frame, unless given) and an initial
force-closure grasp for the motion ``T_palm_object(t) = T0 T_rel(t)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ._validate import as_array, positive
from .exceptions import Attempt, ContactError, FailureKind, InputError, ModelFileError
from .grasp.contact import ContactModel
from .model.hand import Hand
from .model.motion import ObjectMotion
from .model.objects import ConvexObject
from .scenarios import GraspSearch, Scenario, palm_hit, scenario_params, start_poses

__all__ = ["relative_motion_from_csv", "relative_twist", "scenario_for_motion"]

_CSV_COLUMNS = "t, x, y, z, qx, qy, qz, qw"


def relative_twist(
    *,
    axis_object: Sequence[float] = (0.0, 0.0, 1.0),
    point_object: Sequence[float] = (0.0, 0.0, 0.0),
    angle_deg: float = 100.0,
    rate_deg_s: float = 20.0,
    dt_s: float = 0.01,
) -> ObjectMotion:
    """A turn by ``angle_deg`` at ``rate_deg_s`` about the axis ``axis_object`` through
    ``point_object`` [m], both in the object's frame at the start, as poses relative to
    the start (the sign of the angle turns by the right-hand rule about the axis).

    Raises:
        InputError: a zero or non-finite axis or angle, a rate that is not positive.
    """
    axis = as_array(axis_object, "axis_object", (3,))
    if not np.linalg.norm(axis) > 0:
        raise InputError("axis_object", "is zero", "a non-zero direction (object frame)")
    point = as_array(point_object, "point_object", (3,))
    rate = positive(rate_deg_s, "rate_deg_s")
    angle = float(angle_deg)
    if not np.isfinite(angle) or angle == 0:
        raise InputError("angle_deg", f"{angle_deg!r} is not allowed", "a finite non-zero angle")
    return ObjectMotion.constant_twist(
        np.eye(4),
        axis_palm=axis,
        point_palm=point,
        rate_rad_s=float(np.sign(angle) * np.radians(rate)),
        duration_s=abs(angle) / rate,
        dt_s=dt_s,
    )


def relative_motion_from_csv(path: str | Path) -> ObjectMotion:
    """Timed poses relative to the start from a CSV file: rows ``t, x, y, z, qx, qy, qz,
    qw`` (seconds, metres, a unit quaternion; an optional header line), the first at the
    identity (``0, 0, 0, 0, 0, 0, 0, 1``), times increasing.

    Raises:
        ModelFileError: the file does not exist or cannot be read.
        InputError: wrong columns, non-numeric cells, times not increasing, a first pose
            that is not the identity.
    """
    file = Path(path)
    if not file.is_file():
        raise ModelFileError(file, "no such motion file")
    rows = []
    for lineno, line in enumerate(file.read_text().splitlines(), start=1):
        cells = [c.strip() for c in line.replace(";", ",").split(",") if c.strip()]
        if not cells or cells[0].startswith("#"):
            continue
        try:
            rows.append([float(c) for c in cells])
        except ValueError:
            if rows:
                raise InputError(
                    "motion", f"{file.name} line {lineno} is not numeric", _CSV_COLUMNS
                ) from None
            continue  # a header
        if len(rows[-1]) != 8:
            raise InputError(
                "motion", f"{file.name} line {lineno} has {len(rows[-1])} columns", _CSV_COLUMNS
            )
    data = as_array(rows, "motion", (None, 8))
    if data.shape[0] < 2:
        raise InputError("motion", f"{file.name} has {data.shape[0]} pose(s)", "at least 2 rows")
    first = data[0, 1:]
    if not np.allclose(first, [0, 0, 0, 0, 0, 0, 1], atol=1e-9):
        raise InputError(
            "motion",
            f"{file.name}: the first pose is {first.tolist()}",
            "poses relative to the start: the first row at the identity (0,0,0, 0,0,0,1)",
        )
    return ObjectMotion.from_xyzquat(data[:, 0], data[:, 1:])


def scenario_for_motion(
    hand: Hand,
    obj: ConvexObject,
    relative: ObjectMotion,
    *,
    fingers: Sequence[str] | None = None,
    pose: np.ndarray | None = None,
    seed: int = 0,
    attempts: int = 6,
    contact: ContactModel | None = None,
    grasp_dt_s: float = 0.1,
    what: str | None = None,
) -> Scenario:
    """A scenario of ``hand`` moving ``obj`` by the relative motion ``relative``.

    The start pose is ``pose`` or, by default, searched in the fingers' common workspace
    (:func:`~regrasp_pin.placing.candidate_placements`, best first, at most
    ``attempts``); the first pose with an initial force-closure grasp for the whole
    motion (:func:`~regrasp_pin.scenarios.grasp_for_motion`) at which the object stays
    clear of the palm is the scenario's.

    Args:
        hand: Any hand.
        obj: The object (its frame: the one ``relative`` is expressed in).
        relative: The motion relative to the start pose (:func:`relative_twist`,
            :func:`relative_motion_from_csv`); its first pose must be the identity.
        fingers: The fingers that grasp; default all of the hand's.
        pose: The object's start pose ``(4, 4)`` in the palm frame; default searched.
        seed: Seed of the placement and grasp searches.
        attempts: Most start poses tried.
        contact: The contact model; default :class:`~regrasp_pin.grasp.contact.ContactModel`.
        grasp_dt_s: Time step of the grasp search's manifolds [s].
        what: How the description names the motion; default "its own motion".

    Raises:
        InputError: a first relative pose that is not the identity, a bad pose.
        UnknownNameError: an unknown finger.
        ContactError: no start pose with a grasp (``attempts`` lists each pose tried).
    """
    names = tuple(fingers) if fingers is not None else hand.finger_names
    for n in names:
        hand.finger(n)
    rel = relative.T_palm_object
    if not np.allclose(rel[0], np.eye(4), atol=1e-9):
        raise InputError(
            "relative", "does not start at the identity", "poses relative to the start"
        )
    contact = contact or ContactModel()
    poses = start_poses(
        hand, obj, names, contact, pose=pose, attempts=attempts, pivot=None, seed=seed
    )
    failed: list[Attempt] = []
    for i, T0 in enumerate(poses):
        where = f"pose {i} (object at {np.round(T0[:3, 3] * 1e3, 1).tolist()} mm)"
        motion = ObjectMotion.from_poses(relative.times_s, T0 @ rel)
        search = GraspSearch(motion, names, contact, grasp_dt_s=grasp_dt_s, seed=seed)
        try:
            grasp = search.choose(hand, obj)
        except ContactError as exc:
            failed.append(exc.as_attempt(where))
            continue
        hit = palm_hit(hand, obj, motion, f"{where}: the object hits the palm during the motion")
        if hit is not None:
            failed.append(hit)
            continue
        idle = [n for n in hand.finger_names if n not in names]
        text = (
            f"{hand.name} hand moves a {obj.kind} by {what or 'its own motion'} over "
            f"{motion.duration_s:.2f} s; fingers {', '.join(names)}"
            + (f" (idle: {', '.join(idle)})" if idle else "")
        )
        return Scenario(
            name=f"{hand.name}-{obj.kind}",
            hand=hand,
            obj=obj,
            motion=motion,
            grasp=grasp,
            params=scenario_params(names, contact),
            description=text,
            grasp_search=search,
        )
    raise ContactError(
        f"no start pose of the {obj.kind} lets the {hand.name} hand grasp it through the "
        f"motion ({len(poses)} tried)",
        kind=FailureKind.NO_CANDIDATE,
        attempts=failed,
    )
