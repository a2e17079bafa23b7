"""Hand models: a Pinocchio model, its collision model, and one :class:`Finger` per finger.

Frames: every position is in the palm frame, the root frame of the URDF (the
``universe`` frame of the Pinocchio model). Units: metres and radians.

Bundled hands:

- :meth:`Hand.five_finger` loads ``urdf/five_finger_hand.urdf``, an anthropomorphic
  right hand with four 3-joint fingers (abduction, MCP, PIP, DIP coupled to PIP by a
  ``<mimic>`` joint) and a 3-joint thumb (opposition, MCP, IP).
- :meth:`Hand.allegro` loads the Allegro right hand from ``example-robot-data``
  (offline, from the installed package), four 4-joint fingers.
"""

from __future__ import annotations

import importlib.metadata
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from .._validate import as_array, as_batch, positive
from ..exceptions import InputError, ModelFileError, UnknownNameError
from .ik import IKResult, solve_position_ik
from .kinematics import FingerChain
from .tip_reach import TipReach, tip_reach
from .urdf import HandModels, load_hand_models

__all__ = ["Finger", "Hand", "allegro_urdf_path", "five_finger_urdf_path", "speed_shares"]

#: Optional keys of a hand file (:meth:`Hand.from_file`).
_HAND_FILE_OPTIONAL = ("name", "pad_axes", "palm_frame", "locked", "couplings", "package_dirs")

#: The pad cone of a finger whose fingertip link carries the tip sphere itself [deg]:
#: the sphere's whole front hemisphere is the finger's surface (the pad and the
#: fingertip's end; the back, the nail, never touches).
PAD_CONE_SPHERE_DEG = 90.0
#: The pad cone of a finger whose tip sphere stands in for a pad of another shape (a
#: mesh, or a sphere of another radius) [deg]: trusted near the pad only (the Shadow
#: Hand's distal mesh reaches 5.0-6.0 mm from its 7.5 mm sphere's centre 30-90 deg
#: towards the fingertip's end, 8.5-9 mm sideways).
PAD_CONE_STAND_IN_DEG = 60.0

#: Tip frames of the bundled five-finger hand.
FIVE_FINGER_TIPS = {
    "thumb": "thumb_tip",
    "index": "index_tip",
    "middle": "middle_tip",
    "ring": "ring_tip",
    "little": "little_tip",
}
FIVE_FINGER_TIP_RADIUS = 0.008

#: Allegro right hand: fingertip links and the radius of their collision spheres.
ALLEGRO_TIPS = {
    "thumb": "link_15.0_tip",
    "index": "link_3.0_tip",
    "middle": "link_7.0_tip",
    "ring": "link_11.0_tip",
}
ALLEGRO_TIP_RADIUS = 0.012


def five_finger_urdf_path() -> Path:
    """Path of the bundled ``five_finger_hand.urdf``."""
    return Path(str(resources.files("regrasp_pin") / "urdf" / "five_finger_hand.urdf"))


def allegro_urdf_path() -> Path:
    """Path of the Allegro right hand URDF installed by ``example-robot-data``.

    Raises:
        ModelFileError: if example-robot-data is not installed or lacks the file.
    """
    rel = "share/example-robot-data/robots/allegro_hand_description/urdf/allegro_right_hand.urdf"
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        raise ModelFileError(
            "allegro_right_hand.urdf", "example-robot-data is not installed (pip install it)"
        ) from None
    for prefix in ("cmeel.prefix/", ""):
        path = Path(str(dist.locate_file(prefix + rel)))
        if path.is_file():
            return path
    raise ModelFileError(rel, "not found in the installed example-robot-data")


def speed_shares(dq: np.ndarray, dt_s: np.ndarray, velocity_limit: np.ndarray) -> np.ndarray:
    """``(S, k)``: joint steps ``dq`` ``(S, k)`` [rad] taken over ``dt_s`` ``(S,)`` [s],
    each as a share of its joint's velocity limit ``(k,)`` [rad/s] (above 1: too fast).
    0 for joints without a positive limit (not counted, as
    :func:`~regrasp_pin.verify.plan_check.recheck_plan` does not count them) and for
    steps that take no time."""
    limit = np.asarray(velocity_limit, float)
    dt = np.asarray(dt_s, float)[:, None]
    speed = np.zeros(np.shape(dq))
    np.divide(np.abs(dq), dt, out=speed, where=dt > 0.0)  # [rad/s]
    out = np.zeros(speed.shape)
    np.divide(speed, limit, out=out, where=limit > 0.0)
    return out


@dataclass(frozen=True, eq=False)
class Finger:
    """One finger: its independent joints, limits, tip frame and batched kinematics.

    Attributes:
        name: Finger name (e.g. ``"index"``).
        tip_frame: Name of the frame at the centre of the fingertip sphere.
        tip_radius: Fingertip sphere radius [m].
        joint_names: Names of the independent joints, shape ``(k,)``; mimic joints
            driven by them are not listed (they follow).
        q_indices: Indices of those joints in the full configuration, ``(k,)``.
        lower: Lower joint limits ``(k,)`` [rad].
        upper: Upper joint limits ``(k,)`` [rad].
        velocity_limit: Joint velocity limits ``(k,)`` [rad/s].
        pad_axis_tip: Unit vector in the tip frame pointing out of the finger pad (the
            palmar side), ``(3,)``.
        chain: The batched kinematics kernel.
        geometry_ids: Indices in the hand's collision model of the geometries carried
            by this finger's links.
        tip_geometry_ids: Those of them that touch the object at a contact (the
            fingertip sphere and the distal link it sits on).
        tip_reach: How far those reach past the plane the tip sphere rests on, by the
            plane's direction (:class:`~regrasp_pin.model.tip_reach.TipReach`); None
            without collision geometry.
        pad_cone_deg: Largest angle between the pad axis and the inward surface normal
            at which the fingertip can hold [deg] (the contact model's cone unless
            :attr:`~regrasp_pin.grasp.contact.ContactModel.cone_deg` overrides it):
            :data:`PAD_CONE_SPHERE_DEG` where the fingertip link carries the tip sphere
            itself (``tip_reach.has_tip_sphere()``), else :data:`PAD_CONE_STAND_IN_DEG`.
    """

    name: str
    tip_frame: str
    tip_radius: float
    joint_names: tuple[str, ...]
    q_indices: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    velocity_limit: np.ndarray
    pad_axis_tip: np.ndarray
    chain: FingerChain = field(repr=False)
    geometry_ids: tuple[int, ...] = ()
    tip_geometry_ids: tuple[int, ...] = ()
    tip_reach: TipReach | None = field(default=None, repr=False)

    @property
    def pad_cone_deg(self) -> float:
        """See the class's attributes: from :attr:`tip_reach`."""
        sphere = self.tip_reach is not None and self.tip_reach.has_tip_sphere()
        return PAD_CONE_SPHERE_DEG if sphere else PAD_CONE_STAND_IN_DEG

    @property
    def k(self) -> int:
        """Number of independent joints (dimension of the finger's joint space)."""
        return len(self.joint_names)

    @property
    def q_mid(self) -> np.ndarray:
        """Middle of the joint box ``(k,)`` [rad]."""
        return 0.5 * (self.lower + self.upper)

    # -------------------------------------------------------------- kinematics
    def _q_batch(self, q: object, argument: str = "q") -> tuple[np.ndarray, bool]:
        return as_batch(q, argument, self.k)

    def fk(self, q: object) -> np.ndarray:
        """Tip-centre positions in the palm frame.

        Args:
            q: ``(k,)`` or ``(N, k)`` finger configurations [rad].

        Returns:
            ``(3,)`` or ``(N, 3)`` positions [m].

        Raises:
            InputError: wrong shape or NaN/inf.
        """
        qb, single = self._q_batch(q)
        p = self.chain.positions(qb)
        return p[0] if single else p

    def jacobian(self, q: object) -> tuple[np.ndarray, np.ndarray]:
        """Tip positions and position Jacobians in the palm frame.

        Args:
            q: ``(k,)`` or ``(N, k)`` configurations [rad].

        Returns:
            ``p`` ``(N, 3)`` [m] and ``J`` ``(N, 3, k)`` [m/rad] (without the N axis for
            a single configuration).
        """
        qb, single = self._q_batch(q)
        p, J = self.chain.positions_jacobians(qb)
        return (p[0], J[0]) if single else (p, J)

    def tip_poses(self, q: object) -> tuple[np.ndarray, np.ndarray]:
        """Tip frame rotations ``(N, 3, 3)`` and positions ``(N, 3)`` in the palm frame."""
        qb, single = self._q_batch(q)
        R, p = self.chain.poses(qb)
        return (R[0], p[0]) if single else (R, p)

    def pad_normals(self, q: object) -> np.ndarray:
        """Unit pad directions (out of the finger pad) in the palm frame, ``(N, 3)``."""
        R, _ = self.tip_poses(q)
        return R @ self.pad_axis_tip

    def ik(
        self,
        targets_palm: object,
        q_init: object | None = None,
        *,
        tol_m: float = 1e-5,
        max_iter: int = 40,
        restarts: bool = True,
    ) -> IKResult:
        """Batched damped-least-squares position IK of the tip centre.

        Args:
            targets_palm: ``(3,)`` or ``(N, 3)`` tip-centre targets in the palm frame [m].
            q_init: Initial guess, ``(k,)`` (shared) or ``(N, k)`` (warm start per target)
                [rad]; default the middle of the joint box.
            tol_m: Position tolerance [m].
            max_iter: Iteration cap per pass.
            restarts: Retry unconverged targets from fixed seeds over the joint box.

        Returns:
            :class:`~regrasp_pin.model.ik.IKResult` with ``q`` ``(N, k)`` inside the limits,
            ``success`` ``(N,)`` and ``error_m`` ``(N,)``. An unreachable target gets
            ``success=False`` and its residual; it is not an error.

        Raises:
            InputError: wrong shapes, NaN/inf, non-positive tolerance.
        """
        targets, _ = as_batch(targets_palm, "targets_palm", 3)
        n = targets.shape[0]
        if q_init is None:
            q0 = np.broadcast_to(self.q_mid, (n, self.k))
        else:
            q0, single = as_batch(q_init, "q_init", self.k)
            if single:
                q0 = np.broadcast_to(q0[0], (n, self.k))
            elif q0.shape[0] != n:
                raise InputError(
                    "q_init",
                    f"has {q0.shape[0]} rows for {n} targets",
                    f"shape ({self.k},) or ({n}, {self.k})",
                )
        tol = positive(tol_m, "tol_m")
        if (
            isinstance(max_iter, bool)
            or not isinstance(max_iter, (int, np.integer))
            or max_iter < 1
        ):
            raise InputError("max_iter", f"{max_iter!r} is not allowed", "an integer >= 1")
        return solve_position_ik(
            self.chain,
            self.lower,
            self.upper,
            targets,
            q0,
            tol_m=tol,
            max_iter=int(max_iter),
            restarts=restarts,
        )

    def within_limits(self, q: object, tol: float = 0.0) -> np.ndarray:
        """``(N,)`` True where every joint is within ``[lower - tol, upper + tol]``."""
        qb, _ = self._q_batch(q)
        return np.all((qb >= self.lower - tol) & (qb <= self.upper + tol), axis=1)

    def limit_margin(self, q: object) -> np.ndarray:
        """Distance to the nearest boundary plane of the joint box, ``(N,)`` [rad].

        Negative outside the box.
        """
        qb, _ = self._q_batch(q)
        return np.minimum(qb - self.lower, self.upper - qb).min(axis=1)


class FingerMap(dict):
    """``Hand.fingers``: a dict whose missing names raise an UnknownNameError that lists
    the hand's fingers (a KeyError too, so ``except KeyError`` still works)."""

    def __missing__(self, key: object) -> Finger:
        raise UnknownNameError("fingers", key, list(self))


class Hand:
    """A hand: Pinocchio model, collision and visual models, and its fingers.

    Use :meth:`five_finger`, :meth:`allegro` or :meth:`from_urdf` to build one.

    Attributes:
        model: The Pinocchio model (mimic joints loaded as mimic joints).
        collision_model: Pinocchio ``GeometryModel`` of the collision geometry.
        visual_model: Pinocchio ``GeometryModel`` of the visual geometry.
        urdf_path: Path of the URDF the hand was loaded from.
        fingers: Mapping finger name -> :class:`Finger`, in the given order.
        name: Short name (``"five_finger"``, ``"allegro"`` or the URDF stem).
        load_options: ``palm_frame``, ``locked`` (every joint locked and its value, those
            locked by default above the palm included) and ``couplings`` (as given) of
            :meth:`from_urdf`, as JSON values; empty when none applies.
    """

    def __init__(
        self,
        model: pin.Model,
        collision_model: pin.GeometryModel,
        visual_model: pin.GeometryModel,
        urdf_path: Path,
        fingers: dict[str, Finger],
        name: str,
    ) -> None:
        self.model = model
        self.collision_model = collision_model
        self.visual_model = visual_model
        self.urdf_path = urdf_path
        self.fingers: dict[str, Finger] = FingerMap(fingers)
        self.name = name
        #: How the URDF was loaded (``palm_frame``, ``locked``, ``couplings``), as JSON
        #: values: with the URDF, what rebuilds the same models.
        self.load_options: dict[str, Any] = {}
        #: The URDF's text as it was loaded.
        self.urdf_text: str = ""
        #: Folders given for its meshes (besides the URDF's own folder).
        self.package_dirs: tuple[Path, ...] = ()

    def __repr__(self) -> str:
        return f"Hand({self.name!r}, fingers={self.finger_names}, nq={self.model.nq})"

    # ------------------------------------------------------------ construction
    @classmethod
    def five_finger(cls) -> Hand:
        """The bundled anthropomorphic five-finger right hand."""
        return cls.from_urdf(
            five_finger_urdf_path(),
            FIVE_FINGER_TIPS,
            tip_radius=FIVE_FINGER_TIP_RADIUS,
            name="five_finger",
        )

    @classmethod
    def allegro(cls) -> Hand:
        """The Allegro right hand from example-robot-data (loaded offline)."""
        return cls.from_urdf(
            allegro_urdf_path(), ALLEGRO_TIPS, tip_radius=ALLEGRO_TIP_RADIUS, name="allegro"
        )

    @classmethod
    def from_urdf(
        cls,
        path: str | Path,
        fingers: Mapping[str, str],
        *,
        tip_radius: float | Mapping[str, float],
        pad_axes: Mapping[str, object] | None = None,
        name: str | None = None,
        palm_frame: str | None = None,
        locked: Mapping[str, float] | None = None,
        couplings: Mapping[str, tuple[str, float, float]] | None = None,
        package_dirs: Sequence[str | Path] | None = None,
        urdf_text: str | None = None,
    ) -> Hand:
        """Load any hand URDF.

        Args:
            path: URDF file. Meshes referenced by ``package://`` or by a relative path
                are looked up in the URDF's folder and its ancestors.
            fingers: Mapping finger name -> tip frame name (the frame at the centre of
                the fingertip sphere).
            tip_radius: Fingertip sphere radius [m], one for all or one per finger.
            pad_axes: Optional mapping finger -> unit pad direction in its tip frame.
                By default it is the direction in which the tip centre moves when the
                last joint of the finger flexes (with its limits' sign), which points
                out of the pad for a flexion joint.
            name: Short name; default the URDF file stem.
            palm_frame: The frame that is the palm: the joints between the URDF's root
                and it (a wrist, an arm) are locked and every position is expressed in
                this frame. None: the URDF's root frame is the palm frame.
            locked: Values [rad] of the locked joints by name (default each joint's
                neutral value); any other joint named here is locked too.
            couplings: ``{joint: (leader, multiplier, offset)}``: ``joint = multiplier *
                leader + offset`` [rad], as a URDF ``<mimic>`` tag would say (for
                example the Shadow Hand's ``{"FFJ1": ("FFJ2", 1.0, 0.0)}``). The URDF's
                own mimic tags are applied the same way, in any joint order.
            package_dirs: Folders searched first for meshes (``package://`` and relative
                paths).
            urdf_text: The URDF's text, when ``path`` no longer holds it (a plan opened
                on another machine); ``path`` then only names it.

        See :mod:`regrasp_pin.model.urdf` for how the models are built (collision
        meshes become their convex hulls).

        Raises:
            ModelFileError: the file does not exist or cannot be parsed.
            UnknownNameError: a tip frame, the palm frame or a joint is not in the model
                (lists the valid names).
            InputError: bad radius or pad axis, a finger chain that is not revolute, a
                joint on two fingers' chains (name a ``palm_frame`` beyond it), a bad
                locked value or coupling.
        """
        urdf = Path(path)
        if urdf_text is None:
            if not urdf.is_file():
                raise ModelFileError(urdf, "no such URDF file")
            try:
                urdf_text = urdf.read_text()
            except (OSError, UnicodeDecodeError) as exc:
                raise ModelFileError(urdf, f"cannot be read ({exc})") from None
        if not isinstance(fingers, Mapping) or not fingers:
            raise InputError("fingers", "is empty or not a mapping", "{finger name: tip frame}")
        models = load_hand_models(
            urdf,
            urdf_text,
            palm_frame=palm_frame,
            locked=locked,
            couplings=couplings,
            package_dirs=package_dirs,
        )
        model, collision, visual = models.model, models.collision_model, models.visual_model

        frame_names = [f.name for f in model.frames]
        built: dict[str, Finger] = {}
        for finger_name, tip in fingers.items():
            if tip not in frame_names:
                raise UnknownNameError(f"fingers[{finger_name!r}]", tip, frame_names)
            if isinstance(tip_radius, Mapping):
                if finger_name not in tip_radius:
                    raise UnknownNameError("tip_radius", finger_name, list(tip_radius))
                radius = positive(tip_radius[finger_name], f"tip_radius[{finger_name!r}]")
            else:
                radius = positive(tip_radius, "tip_radius")
            chain = FingerChain(model, tip)
            if chain.k == 0:
                raise InputError(
                    f"fingers[{finger_name!r}]",
                    f"frame {tip!r} is not moved by any joint",
                    "a tip frame on a finger chain",
                )
            qi = chain.q_indices
            lower = model.lowerPositionLimit[qi].copy()
            upper = model.upperPositionLimit[qi].copy()
            if pad_axes is not None and finger_name in pad_axes:
                pad = as_array(pad_axes[finger_name], f"pad_axes[{finger_name!r}]", (3,))
                if np.linalg.norm(pad) < 1e-9:
                    raise InputError(f"pad_axes[{finger_name!r}]", "is zero", "a unit vector")
                pad = pad / np.linalg.norm(pad)
            else:
                pad = _default_pad_axis(model, chain, lower, upper)
            geom_ids, tip_ids = _finger_geometries(model, collision, chain, tip)
            built[finger_name] = Finger(
                name=finger_name,
                tip_frame=tip,
                tip_radius=radius,
                joint_names=tuple(model.names[int(j)] for j in chain.joint_ids),
                q_indices=qi,
                lower=lower,
                upper=upper,
                velocity_limit=model.velocityLimit[
                    [model.joints[int(j)].idx_v for j in chain.joint_ids]
                ].copy(),
                pad_axis_tip=pad,
                chain=chain,
                geometry_ids=geom_ids,
                tip_geometry_ids=tip_ids,
                tip_reach=tip_reach(model, collision, tip, radius, tip_ids),
            )
        _check_disjoint(model, built)
        hand = cls(model, collision, visual, urdf, built, name or urdf.stem)
        hand.load_options = _load_options(palm_frame, models, couplings)
        hand.urdf_text = urdf_text
        hand.package_dirs = tuple(Path(d) for d in package_dirs or ())
        return hand

    @classmethod
    def from_file(cls, path: str | Path) -> Hand:
        """Load a hand described by a JSON hand file.

        The file holds :meth:`from_urdf`'s arguments: ``urdf`` (a path relative to the
        hand file, or absolute), ``fingers``, ``tip_radius`` and optionally ``name``,
        ``pad_axes``, ``palm_frame``, ``locked``, ``couplings`` (``{joint: [leader,
        multiplier, offset]}``) and ``package_dirs`` (relative to the hand file). A
        ``scenario`` entry is for :mod:`regrasp_pin.scenarios` (which fingers grasp in
        the ready-made scenarios, how their objects are scaled) and is not read here.
        See ``examples/hands/shadow_hand.json``.

        Raises:
            ModelFileError: the file cannot be read or is not JSON.
            InputError: a missing key, a ``urdf`` that is not a string, ``package_dirs``
                that is not a list of strings, and whatever :meth:`from_urdf` raises.
            UnknownNameError: an unknown key (lists the accepted ones).
        """
        spec_path = Path(path)
        try:
            spec = json.loads(spec_path.read_text())
        except (OSError, UnicodeDecodeError) as exc:
            raise ModelFileError(spec_path, f"cannot be read ({exc})") from None
        except json.JSONDecodeError as exc:
            raise ModelFileError(spec_path, f"is not JSON ({exc})") from None
        accepted = ("urdf", "fingers", "tip_radius", "scenario", *_HAND_FILE_OPTIONAL)
        if not isinstance(spec, dict):
            raise InputError(str(spec_path), "is not a JSON object", f"an object with {accepted}")
        for key in spec:
            if key not in accepted:
                raise UnknownNameError(f"{spec_path.name} key", key, accepted)
        for key in ("urdf", "fingers", "tip_radius"):
            if key not in spec:
                raise InputError(str(spec_path), f"has no {key!r}", f"the keys {accepted}")
        if not isinstance(spec["urdf"], str):
            raise InputError(f"{spec_path.name}: urdf", f"is {spec['urdf']!r}", "a path string")
        base = spec_path.resolve().parent
        options = {k: spec[k] for k in _HAND_FILE_OPTIONAL if k in spec}
        if "package_dirs" in options:
            dirs = options["package_dirs"]
            if not isinstance(dirs, list) or not all(isinstance(d, str) for d in dirs):
                raise InputError(
                    f"{spec_path.name}: package_dirs", f"is {dirs!r}", "a list of paths"
                )
            options["package_dirs"] = [base / d for d in dirs]
        return cls.from_urdf(
            base / spec["urdf"], spec["fingers"], tip_radius=spec["tip_radius"], **options
        )

    # ------------------------------------------------------------------ access
    @property
    def finger_names(self) -> tuple[str, ...]:
        """Finger names in the order they were given."""
        return tuple(self.fingers)

    def finger(self, name: str) -> Finger:
        """The finger called ``name``.

        Raises:
            UnknownNameError: lists the valid finger names.
        """
        try:
            return self.fingers[name]
        except KeyError:
            raise UnknownNameError("finger", name, self.finger_names) from None

    def neutral(self) -> np.ndarray:
        """A full configuration ``(nq,)`` with every finger at the middle of its limits."""
        q = pin.neutral(self.model)
        for f in self.fingers.values():
            q[f.q_indices] = f.q_mid
        return q

    def to_full(self, finger: str, q_finger: object, q_full: object | None = None) -> np.ndarray:
        """Put a finger's configuration into full configurations.

        Args:
            finger: Finger name.
            q_finger: ``(k,)`` or ``(N, k)`` [rad].
            q_full: Base full configuration(s) ``(nq,)`` or ``(N, nq)``; default
                :meth:`neutral`.

        Returns:
            ``(nq,)`` or ``(N, nq)`` full configurations.
        """
        f = self.finger(finger)
        qf, single = as_batch(q_finger, "q_finger", f.k)
        nq = self.model.nq
        if q_full is None:
            base = np.broadcast_to(self.neutral(), (qf.shape[0], nq)).copy()
        else:
            base, base_single = as_batch(q_full, "q_full", nq)
            base = np.broadcast_to(base, (qf.shape[0], nq)).copy() if base_single else base.copy()
            if base.shape[0] != qf.shape[0]:
                raise InputError("q_full", f"has {base.shape[0]} rows", f"{qf.shape[0]} rows")
        base[:, f.q_indices] = qf
        return base[0] if single else base

    def from_full(self, finger: str, q_full: object) -> np.ndarray:
        """Take a finger's ``(k,)`` / ``(N, k)`` configuration out of full configurations."""
        f = self.finger(finger)
        qb, single = as_batch(q_full, "q_full", self.model.nq)
        out = qb[:, f.q_indices]
        return out[0] if single else out


def _default_pad_axis(
    model: pin.Model, chain: FingerChain, lower: np.ndarray, upper: np.ndarray
) -> np.ndarray:
    """Direction (tip frame) in which the tip centre moves when the last joint of the
    chain turns positively, at the middle of the joint box."""
    q = pin.neutral(model)
    q[chain.q_indices] = 0.5 * (lower + upper)
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    pin.updateFramePlacements(model, data)
    jid, axis_local = chain.path_axes[-1]
    oMi = data.oMi[jid]
    oMf = data.oMf[model.getFrameId(chain.tip_frame)]
    v = np.cross(oMi.rotation @ axis_local, oMf.translation - oMi.translation)
    if np.linalg.norm(v) < 1e-9:
        return np.array([0.0, 0.0, 1.0])
    v = oMf.rotation.T @ v
    return v / np.linalg.norm(v)


def _finger_geometries(
    model: pin.Model, collision: pin.GeometryModel, chain: FingerChain, tip: str
) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """Collision geometry ids on the finger's moving links, and those on the tip link."""
    frame = model.frames[model.getFrameId(tip)]
    tip_joint = int(frame.parentJoint)
    # joints whose motion is caused by the finger's independent joints
    finger_joints = set()
    for jid in range(1, model.njoints):
        j = jid
        while j > 0:
            if j in {int(x) for x in chain.joint_ids} or _mimics(model, j, chain.joint_ids):
                finger_joints.add(jid)
                break
            j = int(model.parents[j])
    ids = []
    tip_ids = []
    for gid, geom in enumerate(collision.geometryObjects):
        if int(geom.parentJoint) in finger_joints:
            ids.append(gid)
            if int(geom.parentJoint) == tip_joint:
                tip_ids.append(gid)
    return tuple(ids), tuple(tip_ids)


def _check_disjoint(model: pin.Model, fingers: Mapping[str, Finger]) -> None:
    """InputError naming a joint that two fingers' chains share."""
    owner: dict[int, str] = {}
    for f in fingers.values():
        for jid in f.chain.joint_ids:
            other = owner.setdefault(int(jid), f.name)
            if other != f.name:
                joint = model.names[int(jid)]
                raise InputError(
                    "fingers",
                    f"joint {joint!r} is on the chains of both {other!r} and {f.name!r}",
                    f"fingers with joints of their own: pass palm_frame= a frame beyond "
                    f"{joint!r} (its joints are then locked)",
                )


def _load_options(
    palm_frame: str | None,
    models: HandModels,
    couplings: Mapping[str, tuple[str, float, float]] | None,
) -> dict[str, Any]:
    out: dict[str, Any] = {}
    if palm_frame is not None:
        out["palm_frame"] = palm_frame
    if models.locked:
        out["locked"] = dict(models.locked)
    if couplings:
        out["couplings"] = {k: [v[0], float(v[1]), float(v[2])] for k, v in couplings.items()}
    return out


def _mimics(model: pin.Model, jid: int, drivers: np.ndarray) -> bool:
    for a, b in zip(model.mimicking_joints, model.mimicked_joints, strict=True):
        if int(a) == jid and int(b) in {int(x) for x in drivers}:
            return True
    return False
