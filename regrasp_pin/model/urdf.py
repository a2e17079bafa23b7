"""Loading a hand URDF into the models a :class:`~regrasp_pin.model.hand.Hand` needs.

A real hand's URDF rarely starts at the palm, declares every coupling, or uses only
primitives. :func:`load_hand_models` turns one into a Pinocchio model, a collision
model and a visual model such that:

- **the palm is the root.** With ``palm_frame``, every joint between the URDF's root and
  that frame (an arm's or a wrist's) is locked at a fixed value
  (``pin.buildReducedModel``) and the models are re-expressed in the palm frame: the
  Pinocchio ``universe`` frame is the palm frame. Other joints may be locked too.
- **couplings are joints that follow joints.** ``couplings={"FFJ1": ("FFJ2", 1.0,
  0.0)}`` makes ``FFJ1 = 1.0 * FFJ2 + 0.0`` (a mimic joint, ``pin.transformJointIntoMimic``).
  URDF ``<mimic>`` tags are read here and applied the same way, also when the mimicked
  joint comes later in the tree (which Pinocchio's parser refuses): each group of
  coupled joints is driven by its first joint in the tree, the others follow it, and
  its limits are narrowed so that every joint of the group stays inside its own.
- **collision meshes are convex.** Each mesh is replaced by its convex hull, on which
  Coal's signed distance is exact also when the shapes overlap (a triangle soup only
  knows whether it is touched); the hull contains the mesh, so every check stays
  conservative. Mesh scale factors are honoured by Pinocchio's loader.

Lengths in metres, angles in radians.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from ..exceptions import InputError, ModelFileError, UnknownNameError

__all__ = ["Coupling", "HandModels", "load_hand_models", "read_couplings"]


@dataclass(frozen=True)
class Coupling:
    """Joint ``follower = multiplier * leader + offset`` [rad]."""

    follower: str
    leader: str
    multiplier: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True, eq=False)
class HandModels:
    """The three models of a hand, rooted at its palm.

    Attributes:
        model: Pinocchio model; couplings are mimic joints.
        collision_model: Collision geometry (meshes as convex hulls).
        visual_model: Visual geometry.
        locked: The joints locked away and their values [rad].
        couplings: The couplings applied (URDF mimic tags and the given ones), each
            as it was declared.
    """

    model: pin.Model
    collision_model: pin.GeometryModel
    visual_model: pin.GeometryModel
    locked: dict[str, float]
    couplings: tuple[Coupling, ...]


def read_couplings(urdf_text: str, source: str | Path = "urdf") -> tuple[str, tuple[Coupling, ...]]:
    """The URDF without its ``<mimic>`` tags, and the couplings they declared
    (``source`` names the URDF in errors).

    Raises:
        ModelFileError: the text is not XML or a mimic tag is malformed.
    """
    try:
        root = ET.fromstring(urdf_text)
    except ET.ParseError as exc:
        raise ModelFileError(source, f"is not valid XML ({exc})") from None
    found = []
    for joint in root.iter("joint"):
        for tag in joint.findall("mimic"):
            leader = tag.get("joint")
            if not leader:
                raise ModelFileError(
                    source, f"joint {joint.get('name')!r}: a <mimic> tag without a joint"
                )
            try:
                mult = float(tag.get("multiplier", 1.0))
                off = float(tag.get("offset", 0.0))
            except ValueError:
                raise ModelFileError(
                    source, f"joint {joint.get('name')!r}: <mimic> multiplier/offset not numbers"
                ) from None
            found.append(Coupling(str(joint.get("name")), leader, mult, off))
            joint.remove(tag)
    return ET.tostring(root, encoding="unicode"), tuple(found)


def load_hand_models(
    urdf: Path,
    text: str,
    *,
    palm_frame: str | None = None,
    locked: Mapping[str, float] | None = None,
    couplings: Mapping[str, tuple[str, float, float]] | None = None,
    package_dirs: Sequence[str | Path] | None = None,
) -> HandModels:
    """Models of the hand in ``urdf``, rooted at ``palm_frame`` (see the module docstring).

    Args:
        urdf: The URDF file's path (relative mesh paths start from its folder).
        text: The URDF's text.
        palm_frame: Frame that becomes the root (the palm frame); the joints between the
            URDF's root and it are locked. None: the URDF's root is the palm frame.
        locked: Values [rad] of locked joints, by name; a joint named here is locked even
            when it is not between the root and the palm. Default: each joint's neutral
            value (0 for a revolute joint).
        couplings: ``{follower: (leader, multiplier, offset)}``, joint follows joint;
            given on top of the URDF's mimic tags (a follower named in both takes the
            one given here).
        package_dirs: Folders in which ``package://`` and relative mesh paths are looked
            up first; then the URDF's folder and every ancestor of it (and Pinocchio
            adds those of ``ROS_PACKAGE_PATH``).

    Raises:
        ModelFileError: the text cannot be parsed or a mesh is not found.
        UnknownNameError: an unknown frame or joint name (lists the valid ones).
        InputError: a locked value outside the joint's limits, a coupling between joints
            that are not revolute, a locked joint in a coupling, a coupling loop, or a
            multiplier that is zero or not finite.
    """
    plain, declared = read_couplings(text, urdf)
    here = urdf.resolve()
    dirs = [str(d) for d in package_dirs or []] + [str(here.parent)]
    dirs += [str(p) for p in here.parent.parents]
    try:
        model = pin.buildModelFromXML(plain)
        collision = pin.buildGeomFromUrdfString(model, plain, pin.COLLISION, package_dirs=dirs)
        visual = pin.buildGeomFromUrdfString(model, plain, pin.VISUAL, package_dirs=dirs)
    except (RuntimeError, ValueError) as exc:
        raise ModelFileError(
            urdf, f"cannot be loaded by Pinocchio (meshes searched in {dirs[:3]}...): {exc}"
        ) from None
    given = _given_couplings(couplings)
    lock = _joints_to_lock(model, palm_frame, locked)
    if lock:
        q_ref = pin.neutral(model)
        for name, value in lock.items():
            if value is not None:
                q_ref[model.joints[model.getJointId(name)].idx_q] = value
        ids = [model.getJointId(n) for n in lock]
        model, (collision, visual) = pin.buildReducedModel(model, [collision, visual], ids, q_ref)
    if palm_frame is not None:
        _reroot(model, [collision, visual], palm_frame)
    applied = _applicable(declared, given, set(lock))
    model = _couple(model, applied, set(lock))
    _convex_meshes(collision)
    values = {n: v for n, v in lock.items() if v is not None}
    return HandModels(model, collision, visual, values, tuple(applied))


# ------------------------------------------------------------------ locking the palm
def _joints_to_lock(
    model: pin.Model, palm_frame: str | None, locked: Mapping[str, float] | None
) -> dict[str, float | None]:
    """Joint name -> value [rad] for every joint to lock (validated); None for a joint
    of more than one variable above the palm, locked at its neutral configuration."""
    names = [model.names[j] for j in range(1, model.njoints)]
    out: dict[str, float | None] = {}
    if palm_frame is not None:
        out.update(dict.fromkeys(_above(model, palm_frame), math.nan))
    if locked is not None:
        if not isinstance(locked, Mapping):
            raise InputError("locked", f"is a {type(locked).__name__}", "{joint name: value [rad]}")
        for name in locked:
            if name not in names:
                raise UnknownNameError("locked", name, names)
            out[name] = math.nan
    given = locked or {}
    for name in out:
        jm = model.joints[model.getJointId(name)]
        if jm.nq != 1 and name not in given:
            out[name] = None  # a free-flyer, planar or continuous joint: at neutral
            continue
        if jm.nq != 1:
            raise InputError(f"locked[{name!r}]", f"joint has nq={jm.nq}", "one-dof joints")
        lo = float(model.lowerPositionLimit[jm.idx_q])
        hi = float(model.upperPositionLimit[jm.idx_q])
        value = float(pin.neutral(model)[jm.idx_q])
        if name in given:
            value = _finite(given[name], f"locked[{name!r}]")
        if not lo - 1e-12 <= value <= hi + 1e-12:
            raise InputError(f"locked[{name!r}]", f"{value:g} rad", f"within [{lo:g}, {hi:g}] rad")
        out[name] = value
    return out


def _above(model: pin.Model, palm_frame: str) -> list[str]:
    """The joints between the model's root and ``palm_frame`` (UnknownNameError if no
    such frame)."""
    frames = [f.name for f in model.frames]
    if not isinstance(palm_frame, str) or palm_frame not in frames:
        raise UnknownNameError("palm_frame", palm_frame, frames)
    out = []
    j = int(model.frames[model.getFrameId(palm_frame)].parentJoint)
    while j > 0:
        out.append(model.names[j])
        j = int(model.parents[j])
    return out


def _reroot(model: pin.Model, geometries: list[pin.GeometryModel], palm_frame: str) -> None:
    """Re-express ``model`` (whose ``palm_frame`` is now fixed to the universe) and its
    geometry in the palm frame, in place."""
    fid = model.getFrameId(palm_frame)
    data = model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    palm_inv = data.oMf[fid].inverse()
    for j in range(1, model.njoints):
        if int(model.parents[j]) == 0:
            model.jointPlacements[j] = palm_inv * model.jointPlacements[j]
    for frame in model.frames:
        if int(frame.parentJoint) == 0 and frame.name != "universe":
            frame.placement = palm_inv * frame.placement
    for geometry in geometries:
        for gobj in geometry.geometryObjects:
            if int(gobj.parentJoint) == 0:
                gobj.placement = palm_inv * gobj.placement


# ------------------------------------------------------------------ couplings
def _applicable(
    declared: tuple[Coupling, ...], given: list[Coupling], locked: set[str]
) -> list[Coupling]:
    """The given couplings over the URDF's mimic tags (a follower named in both takes
    the given one). A mimic tag between two locked joints (an arm's, above the palm) is
    dropped; one between a locked and a free joint is an error that names it."""
    mine = {c.follower for c in given}
    out = []
    for c in declared:
        if c.follower in mine:
            continue
        ends = {c.follower, c.leader} & locked
        if len(ends) == 2:
            continue
        if ends:
            raise InputError(
                f"URDF <mimic> of {c.follower!r}",
                f"couples it to {c.leader!r} across the palm frame (one of them is locked)",
                "a palm_frame above both joints or below both",
            )
        out.append(c)
    return out + given


def _given_couplings(couplings: Mapping[str, tuple[str, float, float]] | None) -> list[Coupling]:
    if couplings is None:
        return []
    if not isinstance(couplings, Mapping):
        raise InputError(
            "couplings", f"is a {type(couplings).__name__}", "{follower: (leader, mult, offset)}"
        )
    out = []
    for follower, spec in couplings.items():
        arg = f"couplings[{follower!r}]"
        if not isinstance(spec, (tuple, list)) or len(spec) != 3 or not isinstance(spec[0], str):
            raise InputError(arg, f"is {spec!r}", "(leader joint name, multiplier, offset [rad])")
        out.append(Coupling(str(follower), spec[0], _finite(spec[1], arg), _finite(spec[2], arg)))
    return out


def _finite(value: Any, argument: str) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise InputError(argument, f"{value!r} is not a number", "a finite number") from None
    if not math.isfinite(out):
        raise InputError(argument, f"{value!r} is not finite", "a finite number")
    return out


def _couple(model: pin.Model, couplings: list[Coupling], locked: set[str]) -> pin.Model:
    """``model`` with every coupled group driven by its first joint (a new model)."""
    if not couplings:
        return model
    names = [model.names[j] for j in range(1, model.njoints)]
    # affine map of each joint to its group's root: theta_j = a_j * theta_root + b_j
    parent: dict[str, Coupling] = {}
    for c in couplings:
        arg = f"couplings[{c.follower!r}]"
        for name in (c.follower, c.leader):
            if name in locked:
                raise InputError(arg, f"joint {name!r} is locked", "joints that stay free")
            if name not in names:
                raise UnknownNameError(arg, name, names)
            if model.joints[model.getJointId(name)].nq != 1:
                raise InputError(arg, f"joint {name!r} is not one-dof", "revolute joints")
        if c.multiplier == 0.0 or not math.isfinite(c.multiplier):
            raise InputError(arg, f"multiplier {c.multiplier!r}", "a finite non-zero number")
        if c.follower == c.leader:
            raise InputError(arg, "a joint follows itself", "another joint")
        parent[c.follower] = c
    groups: dict[str, dict[str, tuple[float, float]]] = {}
    for name in parent:
        root, a, b = _to_root(name, parent)
        groups.setdefault(root, {root: (1.0, 0.0)})[name] = (a, b)
    for _root, members in sorted(groups.items(), key=lambda kv: model.getJointId(kv[0])):
        model = _drive_group(model, members)
    return model


def _to_root(name: str, parent: dict[str, Coupling]) -> tuple[str, float, float]:
    """The group root of ``name`` and ``(a, b)`` with ``theta = a * theta_root + b``."""
    a, b, seen = 1.0, 0.0, [name]
    while name in parent:
        c = parent[name]
        # theta_name = a * theta_x + b and theta_x = m * theta_leader + o
        a, b = a * c.multiplier, a * c.offset + b
        name = c.leader
        if name in seen:
            raise InputError(
                f"couplings[{seen[0]!r}]", f"joints follow in a loop: {seen + [name]}", "a tree"
            )
        seen.append(name)
    return name, a, b


def _drive_group(model: pin.Model, members: dict[str, tuple[float, float]]) -> pin.Model:
    """Make the group's first joint (in the tree) drive the others; narrow its limits."""
    driver = min(members, key=model.getJointId)
    a_d, b_d = members[driver]
    lo, hi = -np.inf, np.inf
    vel = np.inf
    for name, (a, b) in members.items():
        # theta_name = (a / a_d) * theta_driver + (b - a * b_d / a_d)
        m, o = a / a_d, b - a * b_d / a_d
        jm = model.joints[model.getJointId(name)]
        lims = sorted(
            (
                (model.lowerPositionLimit[jm.idx_q] - o) / m,
                (model.upperPositionLimit[jm.idx_q] - o) / m,
            )
        )
        lo, hi = max(lo, lims[0]), min(hi, lims[1])
        vel = min(vel, float(model.velocityLimit[jm.idx_v]) / abs(m))
        members[name] = (m, o)
    if not lo <= hi:
        raise InputError(
            "couplings",
            f"the joints coupled to {driver!r} have no common range inside their limits",
            "couplings that keep every joint inside its limits somewhere",
        )
    jd = model.joints[model.getJointId(driver)]
    model.lowerPositionLimit[jd.idx_q] = lo
    model.upperPositionLimit[jd.idx_q] = hi
    model.velocityLimit[jd.idx_v] = vel
    for name in sorted(members, key=model.getJointId):
        if name == driver:
            continue
        m, o = members[name]
        model = pin.transformJointIntoMimic(
            model, model.getJointId(driver), model.getJointId(name), m, o
        )
    return model


# ------------------------------------------------------------------ geometry
def _convex_meshes(collision: pin.GeometryModel) -> None:
    """Replace each mesh of the collision model by its convex hull, in place.

    The hull is computed (qhull, through Coal's ``buildConvexHull``): Coal's
    ``buildConvexRepresentation`` would keep the mesh's own vertices and triangles, and
    on a mesh that is not convex GJK's support search can stop at a local maximum and
    miss a penetration (the Shadow Hand's distal link: 92 of 3000 boxes that held one
    of its vertices up to 4.2 mm deep were reported apart).
    """
    for gobj in collision.geometryObjects:
        shape = gobj.geometry
        if isinstance(shape, coal.BVHModelBase):
            # (the return value says whether the mesh was convex already, not success)
            shape.buildConvexHull(True, "Qt")
            gobj.geometry = shape.convex
