"""Independent re-check of a plan file with Pinocchio and Coal only.

:func:`recheck_plan` reads nothing but the plan file's content -- the hand's URDF
and load options, the object's mesh vertices, the samples ``t``, ``q`` and
``T_palm_object`` and the phases -- and checks it with Pinocchio (kinematics) and Coal
(distances). It shares only the URDF loader with the planner
(:meth:`~regrasp_pin.plan.Plan.load_hand`: palm frame, couplings, convex meshes; its
tests compare it with Pinocchio on the unreduced URDF) and uses none of regrasp_pin's
own kinematics, IK or verification, so it catches what a bug there would hide. What
it checks (the motion between two samples is linear interpolation of ``q`` and of the
object position, slerp of its rotation, as ``docs/plan_format.md`` says):

* every regrasp and every release, re-sampled so that no joint moves more than
  ``max_step_rad`` between two samples: the moving finger's collision geometries
  against the object (the worst penetration must stay within ``penetration_tol_m``)
  and the geometries of every pair of different fingers (they must not touch);
* at every sample of the plan (not densified), the geometries of every pair of
  different fingers apart (fingers that hold can also collide), and the object out of
  the hand's fixed geometry (the palm, a locked wrist: the geometry no joint moves)
  within ``penetration_tol_m``;
* at every sample of the plan, every finger's geometries (a holding finger's other
  links too, and its fingertip link) out of the object within ``penetration_tol_m``;
* every sample inside the joint limits (linear interpolation between samples inside
  a box stays inside it, so the samples suffice);
* every one-dof joint with a positive, finite velocity limit in the hand's model (the
  URDF's; a coupled group's driver carries the tightest of its group's limits) within
  it between every two samples (the interpolated motion's speed is constant between
  them, so the samples are exact);
* the fewest fingers holding a contact at any instant (exact: the count is constant
  between phase boundaries), and, with the friction coefficient the plan records (or
  the ``mu`` given), that the contacts held at once are in force closure
  (:mod:`._closure`, its own wrench model);
* during every contact phase, the fingertip centre at ``p + r n`` of its contact (in
  the object frame, moved by the object's pose) within ``contact_tol_m``;
* every finger's phases follow each other without gap or overlap over the plan.

Exact minima at little cost. Every (sample, pair) entry gets a lower bound on its
signed distance, penetration included (:mod:`._bounds`: spheres around each geometry's
capsule for all entries; for the entries below the first exact distance, the capsules'
signed distance, the shapes' gap along the capsules' nearest points, and the object's
face planes). The candidates are visited in increasing order of their bound and Coal
is called until the next bound is not below the smallest exact distance found, so the
minimum reported is Coal's exact minimum over all densified samples and pairs.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from .._validate import positive, positive_int
from ..exceptions import InputError
from ..plan import ContactPhase, Plan
from ._bounds import Shapes, hull_planes, object_bound, pair_bound, sphere_bound
from ._closure import CLOSURE_TOL, weakest_hold

if TYPE_CHECKING:
    from ..plan import IdlePhase, JoinPhase, RegraspPhase, ReleasePhase

__all__ = [
    "JointLimitViolation",
    "JointSpeedViolation",
    "PlanCheck",
    "RegraspCheck",
    "phase_gaps",
    "recheck_plan",
]

_TIME_TOL_S = 1e-9  # a sample within this of a phase's ends belongs to the phase
_JOINT_TOL_RAD = 1e-9  # accepted excess over a joint limit
_SPEED_TOL = 1e-6  # accepted relative excess over a joint velocity limit
_GAP_TOL_S = 1e-6  # accepted gap or overlap between consecutive phases of a finger
_REFINE_CHUNK = 32768  # entries per call of a tighter bound (a few kB of arrays each)


@dataclass(frozen=True)
class RegraspCheck:
    """The dense re-check of one regrasp phase.

    Attributes:
        finger: The moving finger.
        t_start: Lift-off time [s].
        t_end: Landing time [s].
        n_samples: Densified samples checked.
        min_object_distance_m: Smallest signed distance between the moving finger's
            collision geometries and the object [m] (negative: penetration).
        t_min_object_s: When it occurs [s].
        min_finger_distance_m: Smallest signed distance between collision geometries of
            two different fingers (any fingers, the palm excluded) [m].
        t_min_finger_s: When it occurs [s].
        finger_pair: The two fingers of that smallest distance.
    """

    finger: str
    t_start: float
    t_end: float
    n_samples: int
    min_object_distance_m: float
    t_min_object_s: float
    min_finger_distance_m: float
    t_min_finger_s: float
    finger_pair: tuple[str, str]

    @property
    def penetration_m(self) -> float:
        """Worst penetration of the moving finger into the object [m] (0 if none)."""
        return max(0.0, -self.min_object_distance_m)


@dataclass(frozen=True)
class JointLimitViolation:
    """The worst excess of one joint over its limits in the plan.

    Attributes:
        joint: Joint name (URDF).
        t_s: When the excess is largest [s].
        q_rad: The joint value there [rad].
        lower_rad: Lower limit [rad].
        upper_rad: Upper limit [rad].
    """

    joint: str
    t_s: float
    q_rad: float
    lower_rad: float
    upper_rad: float

    @property
    def excess_rad(self) -> float:
        """How far outside ``[lower_rad, upper_rad]`` the value is [rad]."""
        return max(self.lower_rad - self.q_rad, self.q_rad - self.upper_rad, 0.0)


@dataclass(frozen=True)
class JointSpeedViolation:
    """The fastest move of one joint over its velocity limit in the plan.

    Attributes:
        joint: Joint name (URDF).
        finger: The finger that moves it (None: no finger's).
        t_s: When that move starts (the first of its two samples) [s].
        speed_rad_s: Its speed between the two samples [rad/s].
        limit_rad_s: The joint's velocity limit [rad/s].
    """

    joint: str
    finger: str | None
    t_s: float
    speed_rad_s: float
    limit_rad_s: float


@dataclass(frozen=True)
class PlanCheck:
    """What :func:`recheck_plan` found.

    Attributes:
        ok: True when no problem was found.
        regrasps: One :class:`RegraspCheck` per regrasp phase (time order), then one per
            release phase, then one per join phase.
        idles: One :class:`RegraspCheck` per idle phase: the resting finger against the
            object and the other fingers.
        joint_limit_violations: The joints that leave their limits (worst sample each).
        joint_speed_violations: The joints that move faster than their velocity
            limits between two samples (the fastest move each).
        min_holding: Fewest fingers holding a contact at any instant of the plan.
        t_min_holding_s: A time when that happens [s].
        min_finger_distance_samples_m: Smallest signed distance between geometries of
            two different fingers at the plan's samples (every phase) [m].
        t_min_finger_samples_s: When it occurs [s].
        finger_pair_samples: The two fingers of that smallest distance.
        max_contact_error_m: Largest distance between a holding fingertip's centre and
            where its contact puts it, over the samples of every contact phase [m].
        contact_error_finger: The finger of that largest error (None without contacts).
        t_max_contact_error_s: When it occurs [s] (None without contacts).
        min_palm_distance_m: Smallest signed distance between the object, at the plan's
            samples, and the hand's fixed geometry (the geometry no joint moves: the
            palm, a locked wrist) [m]; inf when the hand has none.
        palm_geometry: The fixed geometry of that distance ("" without one).
        t_min_palm_s: When it occurs [s].
        min_object_distance_samples_m: Smallest signed distance between the fingers'
            geometries (holding, idle or moving) and the object at the plan's samples
            [m]; a holding fingertip touches it (about 0); inf without finger geometry.
        object_geometry_samples: The finger geometry of that distance ("" without one).
        t_min_object_samples_s: When it occurs [s].
        problems: Every problem found, in plain words.
        min_closure_epsilon: With a friction coefficient (the plan's or the one
            given to :func:`recheck_plan`), the smallest Ferrari-Canny epsilon of the
            contacts held at once over the plan (inf without contacts); None without.
        t_min_closure_s: When it occurs [s] (None without a friction coefficient).
        closure_fingers: The fingers holding then.
    """

    ok: bool
    regrasps: tuple[RegraspCheck, ...]
    idles: tuple[RegraspCheck, ...]
    joint_limit_violations: tuple[JointLimitViolation, ...]
    joint_speed_violations: tuple[JointSpeedViolation, ...]
    min_holding: int
    t_min_holding_s: float
    min_finger_distance_samples_m: float
    t_min_finger_samples_s: float
    finger_pair_samples: tuple[str, str]
    max_contact_error_m: float
    contact_error_finger: str | None
    t_max_contact_error_s: float | None
    min_palm_distance_m: float
    palm_geometry: str
    t_min_palm_s: float
    min_object_distance_samples_m: float
    object_geometry_samples: str
    t_min_object_samples_s: float
    problems: tuple[str, ...]
    min_closure_epsilon: float | None = None
    t_min_closure_s: float | None = None
    closure_fingers: tuple[str, ...] = ()

    @property
    def worst_penetration_m(self) -> float:
        """Worst penetration of a moving finger into the object over all regrasps [m]."""
        return max((r.penetration_m for r in self.regrasps), default=0.0)

    @property
    def min_finger_distance_m(self) -> float:
        """Smallest finger-finger distance over all regrasps [m] (inf without regrasps)."""
        return min((r.min_finger_distance_m for r in self.regrasps), default=math.inf)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able summary (infinite distances become None)."""
        d = asdict(self)
        for k in (
            "max_contact_error_m",
            "min_finger_distance_samples_m",
            "min_palm_distance_m",
            "min_closure_epsilon",
        ):
            if d[k] is not None and not math.isfinite(d[k]):
                d[k] = None
        d["closure_fingers"] = list(d["closure_fingers"])
        d["finger_pair_samples"] = list(d["finger_pair_samples"])
        for r in d["regrasps"]:
            for k in ("min_object_distance_m", "min_finger_distance_m"):
                if not math.isfinite(r[k]):
                    r[k] = None
            r["finger_pair"] = list(r["finger_pair"])
        d["problems"] = list(self.problems)
        return d


def recheck_plan(
    plan: Plan,
    *,
    max_step_rad: float = 1e-3,
    penetration_tol_m: float = 1e-4,
    contact_tol_m: float = 1e-4,
    min_holding: int | None = None,
    mu: float | None = None,
    torsion_m: float | None = None,
) -> PlanCheck:
    """Re-check a plan file with Pinocchio and Coal only (see the module docstring).

    Args:
        plan: The plan (e.g. from :meth:`~regrasp_pin.plan.Plan.load`).
        max_step_rad: Largest joint step between two densified samples of a regrasp [rad].
        penetration_tol_m: Largest accepted penetration of a moving finger into the
            object [m].
        contact_tol_m: Largest accepted fingertip-to-contact error while holding [m].
        min_holding: Fewest fingers that must hold at every instant; None: 3 for
            point contacts, 2 with torsional friction (a pinch can hold).
        mu: The friction coefficient to check force closure with: the contacts held
            at once must be in force closure at every instant (their Ferrari-Canny
            epsilon above 1e-9, computed here apart from the planner's). None: the
            plan's own ``mu`` (what it was made for); not checked for a plan that
            records none.
        torsion_m: The soft-finger torsional friction to check force closure with [m]
            (0: point contacts); None: the plan's own ``torsion_m``.

    Returns:
        A :class:`PlanCheck`; ``ok`` is False when any check fails, with one line per
        failure in ``problems``.

    Raises:
        InputError: ``plan`` not a :class:`~regrasp_pin.plan.Plan` (a path: load it
            first), non-positive tolerances, or a plan whose fingers, joints or frames
            are not in its URDF, or whose ``q`` does not fit the URDF.
        ModelFileError: the plan's URDF cannot be loaded.
    """
    if not isinstance(plan, Plan):
        raise InputError(
            "plan", f"is a {type(plan).__name__}", "a Plan, e.g. Plan.load('out/plan.json')"
        )
    max_step = positive(max_step_rad, "max_step_rad")
    pen_tol = positive(penetration_tol_m, "penetration_tol_m", allow_zero=True)
    tip_tol = positive(contact_tol_m, "contact_tol_m", allow_zero=True)
    torsion = (
        plan.torsion_m if torsion_m is None else positive(torsion_m, "torsion_m", allow_zero=True)
    )
    need = (
        (2 if torsion > 0.0 else 3)
        if min_holding is None
        else positive_int(min_holding, "min_holding", minimum=0)
    )
    scene = _Scene(plan)
    problems: list[str] = []

    problems += phase_gaps(plan)
    violations = _joint_limits(scene)
    for v in violations:
        problems.append(
            f"joint {v.joint} at t={v.t_s:.3f} s is {v.q_rad:.4f} rad, outside "
            f"[{v.lower_rad:.4f}, {v.upper_rad:.4f}] rad"
        )
    too_fast = _joint_speeds(scene)
    for w in too_fast:
        problems.append(
            f"joint {w.joint}{'' if w.finger is None else f' ({w.finger})'} moves at "
            f"{w.speed_rad_s:.3f} rad/s from t={w.t_s:.3f} s, over its velocity limit "
            f"{w.limit_rad_s:.3f} rad/s"
        )

    n_hold, t_hold = _min_holding(plan)
    if n_hold < need:
        problems.append(f"only {n_hold} fingers hold at t={t_hold:.3f} s (need {need})")
    closure = _closure(plan, plan.mu if mu is None else mu, torsion, problems)

    R_geom, x_geom = scene.kinematics(plan.q)
    err, err_finger, err_t = _contact_error(scene, scene.tips(plan.q))
    if err_finger is not None and err > tip_tol:
        problems.append(
            f"{err_finger} at t={err_t:.3f} s is {err * 1e3:.3f} mm from its contact "
            f"(tolerance {tip_tol * 1e3:.3f} mm)"
        )

    d_ff, k_ff, pair_ff = _min_finger_distance(scene, R_geom, x_geom)
    if d_ff <= 0.0:
        problems.append(
            f"{pair_ff[0]} and {pair_ff[1]} touch at t={plan.t[k_ff]:.3f} s "
            f"(distance {d_ff * 1e3:.3f} mm)"
        )

    d_palm, k_palm, palm_geom = _min_palm_distance(scene)
    if d_palm < -pen_tol:
        problems.append(
            f"the object enters the hand's fixed geometry {palm_geom!r} at "
            f"t={plan.t[k_palm]:.3f} s by {-d_palm * 1e3:.3f} mm "
            f"(tolerance {pen_tol * 1e3:.3f} mm)"
        )

    # every finger at every sample (a holding finger's other links too; the moves are
    # checked densely below)
    d_obj, k_obj, obj_geom = _min_finger_object_distance(scene, R_geom, x_geom)
    if d_obj < -pen_tol:
        problems.append(
            f"the finger geometry {obj_geom!r} enters the object at t={plan.t[k_obj]:.3f} s "
            f"by {-d_obj * 1e3:.3f} mm (tolerance {pen_tol * 1e3:.3f} mm)"
        )

    checks: list[RegraspCheck] = []
    idle_checks: list[RegraspCheck] = []
    moves: list[RegraspPhase | ReleasePhase | JoinPhase | IdlePhase] = [
        *plan.regrasps(),
        *plan.releases(),
        *plan.joins(),
        *plan.idles(),
    ]
    for phase in moves:
        rc = _check_regrasp(scene, phase, max_step)
        (idle_checks if phase.kind == "idle" else checks).append(rc)
        if rc.min_object_distance_m < -pen_tol:
            problems.append(
                f"{rc.finger} ({phase.kind} at {rc.t_start:.3f} s) penetrates the object by "
                f"{rc.penetration_m * 1e3:.3f} mm at t={rc.t_min_object_s:.3f} s "
                f"(tolerance {pen_tol * 1e3:.3f} mm)"
            )
        if rc.min_finger_distance_m <= 0.0:
            a, b = rc.finger_pair
            problems.append(
                f"{a} and {b} touch during the {phase.kind} of {rc.finger} at {rc.t_start:.3f} s "
                f"(distance {rc.min_finger_distance_m * 1e3:.3f} mm at "
                f"t={rc.t_min_finger_s:.3f} s)"
            )
    return PlanCheck(
        ok=not problems,
        regrasps=tuple(checks),
        idles=tuple(idle_checks),
        joint_limit_violations=tuple(violations),
        joint_speed_violations=tuple(too_fast),
        min_holding=n_hold,
        t_min_holding_s=t_hold,
        min_finger_distance_samples_m=d_ff,
        t_min_finger_samples_s=float(plan.t[k_ff]),
        finger_pair_samples=pair_ff,
        max_contact_error_m=err,
        contact_error_finger=err_finger,
        t_max_contact_error_s=err_t,
        min_palm_distance_m=d_palm,
        palm_geometry=palm_geom,
        t_min_palm_s=float(plan.t[k_palm]),
        min_object_distance_samples_m=d_obj,
        object_geometry_samples=obj_geom,
        t_min_object_samples_s=float(plan.t[k_obj]),
        problems=tuple(problems),
        min_closure_epsilon=closure[0],
        t_min_closure_s=closure[1],
        closure_fingers=closure[2],
    )


# ---------------------------------------------------------------------- the scene
class _Scene:
    """The hand (Pinocchio model and collision geometries) and the object (Coal) of a plan."""

    def __init__(self, plan: Plan) -> None:
        import coal
        import pinocchio as pin

        self.plan = plan
        urdf = str(plan.urdf_path)
        # the models only (Pinocchio and Coal); none of the planner's own kinematics
        hand = plan.load_hand()
        self.model, self.geom = hand.model, hand.collision_model
        if plan.q.shape[1] != self.model.nq:
            raise InputError(
                "plan.q",
                f"has {plan.q.shape[1]} columns but the hand's model has nq={self.model.nq}",
                "q in the order of the model of Plan.load_hand()",
            )
        self.data = self.model.createData()
        self.gdata = pin.GeometryData(self.geom)
        pts = coal.StdVec_Vec3s()
        pts.extend([np.asarray(v, float) for v in plan.object["vertices"]])
        self.obj = coal.Convex.convexHull(pts, False, None)
        verts = np.asarray(plan.object["vertices"], float)
        lo, hi = verts.min(axis=0), verts.max(axis=0)
        self.obj_center = 0.5 * (lo + hi)
        self.obj_radius = float(np.max(np.linalg.norm(verts - self.obj_center, axis=1)))
        self.obj_planes = hull_planes(verts)

        # which finger moves each geometry: the finger whose joints are its ancestors
        joint_finger: dict[int, str] = {}
        fingers = plan.hand["fingers"]
        for name, f in fingers.items():
            for j in f["joints"]:
                if not self.model.existJointName(j):
                    raise InputError("plan.hand", f"finger {name!r}: joint {j!r} is not in {urdf}")
                joint_finger[self.model.getJointId(j)] = name
        self.joint_finger = joint_finger  # joint id -> the finger that moves it
        self.geom_finger: list[str | None] = []
        for g in self.geom.geometryObjects:
            j, owner = int(g.parentJoint), None
            while j > 0 and owner is None:
                owner = joint_finger.get(j)
                j = int(self.model.parents[j])
            self.geom_finger.append(owner)
        # every geometry's capsule and support function: the lower bounds of _exact_min
        self.geom_shapes = Shapes.of([g.geometry for g in self.geom.geometryObjects])
        self.tip_frames: dict[str, int] = {}
        for name, f in fingers.items():
            if not self.model.existFrame(f["tip_frame"]):
                raise InputError(
                    "plan.hand", f"finger {name!r}: frame {f['tip_frame']!r} is not in {urdf}"
                )
            self.tip_frames[name] = self.model.getFrameId(f["tip_frame"])
        self.finger_geoms = [g for g, f in enumerate(self.geom_finger) if f is not None]
        ids = self.finger_geoms
        self.finger_shapes = self.geom_shapes[ids]
        self.ff_pairs = np.array(
            [
                (a, b)
                for a in range(len(ids))
                for b in range(a + 1, len(ids))
                if self.geom_finger[ids[a]] != self.geom_finger[ids[b]]
            ],
            dtype=np.int64,
        ).reshape(-1, 2)
        for name in plan.phases:
            if name not in fingers:
                raise InputError("plan.phases", f"finger {name!r} is not in plan.hand.fingers")
        self.slerp = Slerp(plan.t, Rotation.from_quat(plan.T_palm_object[:, 3:]))
        # the object's rotations and positions at the plan's samples, read by three checks
        self.sample_poses = self.object_poses(plan.t)

    def object_poses(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Object rotations ``(K, 3, 3)`` and positions ``(K, 3)`` [m] at ``times`` [s]."""
        p = self.plan
        x = np.stack([np.interp(times, p.t, p.T_palm_object[:, j]) for j in range(3)], axis=1)
        return self.slerp(times).as_matrix(), x

    def kinematics(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The finger geometries' placements (palm frame), Pinocchio's.

        Args:
            q: Configurations ``(K, nq)`` [rad].

        Returns:
            Rotations ``(K, G, 3, 3)`` and translations ``(K, G, 3)`` [m] of the
            geometries :attr:`finger_geoms`.
        """
        import pinocchio as pin

        m, d, oMg, ids = self.model, self.data, self.gdata.oMg, self.finger_geoms
        M = np.empty((q.shape[0], len(ids), 4, 4))  # homogeneous placements
        if ids:
            for k in range(q.shape[0]):
                pin.forwardKinematics(m, d, q[k])
                pin.updateGeometryPlacements(m, d, self.geom, self.gdata)
                # one read per geometry: reading the placements costs more than computing
                placed = oMg.tolist()
                M[k] = [placed[g].homogeneous for g in ids]
        return np.ascontiguousarray(M[..., :3, :3]), np.ascontiguousarray(M[..., :3, 3])

    def tips(self, q: np.ndarray) -> np.ndarray:
        """Fingertip frame origins ``(K, F, 3)`` [m] (palm frame; fingers in
        ``tip_frames`` order) at the configurations ``q`` ``(K, nq)`` [rad]."""
        import pinocchio as pin

        m, d, frames = self.model, self.data, list(self.tip_frames.values())
        tips = np.empty((q.shape[0], len(frames), 3))
        if frames:
            for k in range(q.shape[0]):
                pin.forwardKinematics(m, d, q[k])
                tips[k] = [pin.updateFramePlacement(m, d, f).translation for f in frames]
        return tips


# ---------------------------------------------------------------------- the checks
def phase_gaps(plan: Plan) -> list[str]:
    """Gaps, overlaps or uncovered ends in each finger's phases: each finger's phases
    must follow one another without gaps or overlaps and span the plan's samples, from
    ``plan.t[0]`` to ``plan.t[-1]`` (1 us tolerance). One line per problem; empty if
    none."""
    out = []
    t0, t1 = float(plan.t[0]), float(plan.t[-1])
    for name, phases in plan.phases.items():
        if not phases:
            out.append(f"{name} has no phase")
            continue
        ps = sorted(phases, key=lambda p: p.t_start)
        if abs(ps[0].t_start - t0) > _GAP_TOL_S:
            out.append(f"{name}'s first phase starts at {ps[0].t_start:.3f} s, not {t0:.3f} s")
        if abs(ps[-1].t_end - t1) > _GAP_TOL_S:
            out.append(f"{name}'s last phase ends at {ps[-1].t_end:.3f} s, not {t1:.3f} s")
        for a, b in zip(ps[:-1], ps[1:], strict=True):
            if abs(b.t_start - a.t_end) > _GAP_TOL_S:
                out.append(
                    f"{name}: {a.kind} phase ends at {a.t_end:.3f} s but the next "
                    f"({b.kind}) starts at {b.t_start:.3f} s"
                )
        for p in ps:
            if p.t_end < p.t_start:
                out.append(f"{name}: {p.kind} phase ends before it starts ({p.t_start:.3f} s)")
    return out


def _joint_limits(scene: _Scene) -> list[JointLimitViolation]:
    """The worst sample of every joint that leaves its limits."""
    m, plan = scene.model, scene.plan
    lo, hi = np.asarray(m.lowerPositionLimit), np.asarray(m.upperPositionLimit)
    excess = np.maximum(lo - plan.q, plan.q - hi)  # (S, nq)
    out = []
    for iq in np.flatnonzero(np.max(excess, axis=0) > _JOINT_TOL_RAD):
        k = int(np.argmax(excess[:, iq]))
        out.append(
            JointLimitViolation(
                joint=_joint_name_of_q(m, int(iq)),
                t_s=float(plan.t[k]),
                q_rad=float(plan.q[k, iq]),
                lower_rad=float(lo[iq]),
                upper_rad=float(hi[iq]),
            )
        )
    return out


def _joint_speeds(scene: _Scene) -> list[JointSpeedViolation]:
    """The fastest move of every joint over its velocity limit (one-dof joints with a
    positive, finite limit in the hand's model; the plan moves linearly between
    samples)."""
    m, plan = scene.model, scene.plan
    dt = np.diff(plan.t)
    out = []
    for j in range(1, m.njoints):
        jm = m.joints[j]
        limit = float(m.velocityLimit[jm.idx_v]) if jm.nv == 1 else math.inf
        if jm.nq != 1 or not 0.0 < limit < math.inf or dt.size == 0:
            continue
        speed = np.abs(np.diff(plan.q[:, jm.idx_q])) / dt  # Plan: t strictly increasing
        k = int(np.argmax(speed))
        if speed[k] > limit * (1.0 + _SPEED_TOL):
            out.append(
                JointSpeedViolation(
                    joint=str(m.names[j]),
                    finger=scene.joint_finger.get(j),
                    t_s=float(plan.t[k]),
                    speed_rad_s=float(speed[k]),
                    limit_rad_s=limit,
                )
            )
    return out


def _joint_name_of_q(model: Any, iq: int) -> str:
    for j in range(1, model.njoints):
        jm = model.joints[j]
        if jm.idx_q <= iq < jm.idx_q + jm.nq:
            return str(model.names[j])
    return f"q[{iq}]"


def _closure(
    plan: Plan, mu: float | None, torsion_m: float, problems: list[str]
) -> tuple[float | None, float | None, tuple[str, ...]]:
    """With ``mu``, the weakest hold of the plan (:func:`._closure.weakest_hold`, with
    torsional friction ``torsion_m`` [m]), and a problem appended when it is not in
    force closure; ``(None, None, ())`` without."""
    if mu is None:
        return None, None, ()
    eps, t_eps, holders = weakest_hold(plan, positive(mu, "mu", allow_zero=True), torsion_m)
    if eps <= CLOSURE_TOL:
        soft = f", torsion {torsion_m * 1e3:g} mm" if torsion_m > 0.0 else ""
        problems.append(
            f"the contacts held at t={t_eps:.3f} s ({', '.join(holders)}) are not in "
            f"force closure (epsilon {eps:.3g}, mu={mu}{soft})"
        )
    return eps, t_eps, holders


def _min_holding(plan: Plan) -> tuple[int, float]:
    """Fewest fingers in a contact phase at any instant, and the first time it happens.

    The count only changes at phase ends, so it is evaluated exactly at every phase end
    and midway between consecutive ends (phases are closed intervals).
    """
    contacts = [
        (p.t_start, p.t_end)
        for phases in plan.phases.values()
        for p in phases
        if p.kind == "contact"
    ]
    owner = [name for name, phases in plan.phases.items() for p in phases if p.kind == "contact"]
    t0, t1 = float(plan.t[0]), float(plan.t[-1])
    ends = np.unique(np.clip([t0, t1, *[t for c in contacts for t in c]], t0, t1))
    probe = np.sort(np.concatenate([ends, 0.5 * (ends[:-1] + ends[1:])]))
    if not contacts:
        return 0, t0
    c = np.array(contacts)
    inside = (c[:, None, 0] - _TIME_TOL_S <= probe) & (probe <= c[:, None, 1] + _TIME_TOL_S)
    names = sorted(set(owner))
    per_finger = np.zeros((len(names), probe.size), bool)
    for i, name in enumerate(owner):
        per_finger[names.index(name)] |= inside[i]
    count = per_finger.sum(axis=0)
    k = int(np.argmin(count))
    return int(count[k]), float(probe[k])


def _contact_error(scene: _Scene, tips: np.ndarray) -> tuple[float, str | None, float | None]:
    """Largest fingertip-to-contact error over the samples of every contact phase.

    ``tips`` are the fingertip frame origins at the plan's samples ``(S, F, 3)`` [m].
    """
    plan = scene.plan
    R, x = scene.sample_poses
    order = list(scene.tip_frames)
    worst: tuple[float, str | None, float | None] = (0.0, None, None)
    for name, phases in plan.phases.items():
        r = float(plan.hand["fingers"][name]["tip_radius"])
        i_f = order.index(name)
        for ph in phases:
            if not isinstance(ph, ContactPhase):
                continue
            sel = np.flatnonzero(
                (plan.t >= ph.t_start - _TIME_TOL_S) & (plan.t <= ph.t_end + _TIME_TOL_S)
            )
            if sel.size == 0:
                continue
            centre_object = np.asarray(ph.p_object, float) + r * np.asarray(ph.n_object, float)
            want = np.einsum("kij,j->ki", R[sel], centre_object) + x[sel]
            err = np.linalg.norm(tips[sel, i_f] - want, axis=1)
            k = int(np.argmax(err))
            if worst[1] is None or err[k] > worst[0]:
                worst = (float(err[k]), name, float(plan.t[sel[k]]))
    return worst


def _densify(plan: Plan, sel: np.ndarray, max_step: float) -> tuple[np.ndarray, np.ndarray]:
    """Times ``(K,)`` and configurations ``(K, nq)`` between the samples ``sel`` so that no
    joint moves more than ``max_step`` between two consecutive ones (ends included)."""
    t, q = plan.t[sel], plan.q[sel]
    if sel.size == 1:
        return t, q
    steps = np.ceil(np.max(np.abs(np.diff(q, axis=0)), axis=1) / max_step).astype(int)
    steps = np.maximum(steps, 1)
    seg = np.repeat(np.arange(steps.size), steps)
    frac = np.concatenate([np.arange(n) / n for n in steps])
    times = np.append(t[seg] + frac * (t[seg + 1] - t[seg]), t[-1])
    qs = np.vstack([q[seg] + frac[:, None] * (q[seg + 1] - q[seg]), q[-1:]])
    return times, qs


def _check_regrasp(
    scene: _Scene, phase: RegraspPhase | ReleasePhase | JoinPhase | IdlePhase, max_step: float
) -> RegraspCheck:
    """Densify one regrasp; the moving finger against the object, all fingers pairwise."""
    plan = scene.plan
    sel = np.flatnonzero(
        (plan.t >= phase.t_start - _TIME_TOL_S) & (plan.t <= phase.t_end + _TIME_TOL_S)
    )
    if sel.size == 0:  # a regrasp between two samples: check the segment around it
        k = int(np.clip(np.searchsorted(plan.t, phase.t_start), 1, plan.t.size - 1))
        sel = np.array([k - 1, k])
    times, q = _densify(plan, sel, max_step)
    R_obj, x_obj = scene.object_poses(times)
    R, x = scene.kinematics(q)
    # the moving finger's geometries against the object
    moving = [i for i, g in enumerate(scene.finger_geoms) if scene.geom_finger[g] == phase.finger]
    d_obj, k_obj, _ = _min_object_distance(scene, R, x, R_obj, x_obj, moving)
    d_ff, k_ff, pair = _min_finger_distance(scene, R, x)
    return RegraspCheck(
        finger=phase.finger,
        t_start=float(phase.t_start),
        t_end=float(phase.t_end),
        n_samples=int(times.size),
        min_object_distance_m=float(d_obj),
        t_min_object_s=float(times[k_obj]),
        min_finger_distance_m=float(d_ff),
        t_min_finger_s=float(times[k_ff]),
        finger_pair=pair,
    )


def _min_finger_distance(
    scene: _Scene, R: np.ndarray, x: np.ndarray
) -> tuple[float, int, tuple[str, str]]:
    """Smallest signed distance between geometries of two different fingers.

    Args:
        scene: The scene.
        R, x: Placements of :attr:`_Scene.finger_geoms`, ``(K, G, 3, 3)`` and ``(K, G, 3)``.

    Returns:
        ``(distance [m], sample index, (finger, finger))``; ``inf`` without pairs.
    """
    import coal

    pairs, ids = scene.ff_pairs, scene.finger_geoms
    if pairs.size == 0:
        return math.inf, 0, ("", "")
    bodies = scene.finger_shapes.placed(R, x)  # (K, G)
    c, rho = bodies.c, bodies.rho
    lower = sphere_bound(
        c[:, pairs[:, 0]], rho[:, pairs[:, 0]], c[:, pairs[:, 1]], rho[:, pairs[:, 1]]
    )

    def refine(idx: np.ndarray) -> np.ndarray:
        k, j = np.divmod(idx, len(pairs))
        return pair_bound(bodies.take(k, pairs[j, 0]), bodies.take(k, pairs[j, 1]))

    shapes = [scene.geom.geometryObjects[g].geometry for g in ids]
    ends = pairs.tolist()
    place, req, res = _Transforms(R, x), coal.DistanceRequest(), coal.DistanceResult()

    def d_pair(k: int, j: int) -> float:
        a, b = ends[j]
        res.clear()
        return coal.distance(shapes[a], place(k, a), shapes[b], place(k, b), req, res)

    d, (k, j) = _exact_min(lower, d_pair, refine)
    a, b = pairs[j]
    return d, k, (str(scene.geom_finger[ids[a]]), str(scene.geom_finger[ids[b]]))


def _min_palm_distance(scene: _Scene) -> tuple[float, int, str]:
    """Smallest signed distance [m] between the object at the plan's samples and the
    hand's fixed geometry (parent joint 0), its sample index and the geometry's name;
    ``(inf, 0, "")`` without fixed geometry."""
    import coal

    objs = scene.geom.geometryObjects
    fixed = [g for g, o in enumerate(objs) if int(o.parentJoint) == 0]
    if not fixed:
        return math.inf, 0, ""
    R_obj, x_obj = scene.sample_poses
    place = [objs[g].placement for g in fixed]
    bodies = scene.geom_shapes[fixed].placed(
        np.array([M.rotation for M in place]), np.array([M.translation for M in place])
    )  # (F,)
    c_obj = x_obj + R_obj @ scene.obj_center
    lower = sphere_bound(c_obj[:, None], scene.obj_radius, bodies.c[None], bodies.rho[None])

    def refine(idx: np.ndarray) -> np.ndarray:
        k, j = np.divmod(idx, len(fixed))
        return object_bound(bodies[j], R_obj[k], x_obj[k], scene.obj_planes)

    shapes = [objs[g].geometry for g in fixed]
    fixed_at = [coal.Transform3s(M.rotation, M.translation) for M in place]
    obj_at = _Transforms(R_obj[:, None], x_obj[:, None])
    req, res = coal.DistanceRequest(), coal.DistanceResult()

    def d_fixed(k: int, j: int) -> float:
        res.clear()
        return coal.distance(shapes[j], fixed_at[j], scene.obj, obj_at(k, 0), req, res)

    d, (k, j) = _exact_min(lower, d_fixed, refine)
    return d, k, str(objs[fixed[j]].name)


def _min_object_distance(
    scene: _Scene,
    R: np.ndarray,
    x: np.ndarray,
    R_obj: np.ndarray,
    x_obj: np.ndarray,
    columns: list[int],
) -> tuple[float, int, int]:
    """Smallest signed distance [m] between the object and the finger geometries
    ``columns`` (indices into :attr:`_Scene.finger_geoms`), placed by ``R, x``
    ``(K, G, 3, 3), (K, G, 3)`` with the object at ``R_obj, x_obj``; its sample index and
    column (``(inf, 0, 0)`` without columns)."""
    import coal

    if not columns:
        return math.inf, 0, 0
    ids, objs = scene.finger_geoms, scene.geom.geometryObjects
    bodies = scene.finger_shapes[columns].placed(R[:, columns], x[:, columns])  # (K, C)
    c_obj = np.einsum("kij,j->ki", R_obj, scene.obj_center) + x_obj  # (K, 3)
    lower = sphere_bound(bodies.c, bodies.rho, c_obj[:, None], scene.obj_radius)

    def refine(idx: np.ndarray) -> np.ndarray:
        k, j = np.divmod(idx, len(columns))
        return object_bound(bodies.take(k, j), R_obj[k], x_obj[k], scene.obj_planes)

    shapes = [objs[ids[i]].geometry for i in columns]
    place, obj_at = _Transforms(R, x), _Transforms(R_obj[:, None], x_obj[:, None])
    req, res = coal.DistanceRequest(), coal.DistanceResult()

    def d_object(k: int, j: int) -> float:
        res.clear()
        return coal.distance(shapes[j], place(k, columns[j]), scene.obj, obj_at(k, 0), req, res)

    d, (k, j) = _exact_min(lower, d_object, refine)
    return d, k, columns[j]


def _min_finger_object_distance(
    scene: _Scene, R_geom: np.ndarray, x_geom: np.ndarray
) -> tuple[float, int, str]:
    """Smallest signed distance [m] between the fingers' geometries (holding, idle or
    moving) and the object at the plan's samples, its sample index and the geometry's
    name; ``(inf, 0, "")`` without finger geometry."""
    ids = scene.finger_geoms
    if not ids:
        return math.inf, 0, ""
    R_obj, x_obj = scene.sample_poses
    d, k, i = _min_object_distance(scene, R_geom, x_geom, R_obj, x_obj, list(range(len(ids))))
    return d, k, str(scene.geom.geometryObjects[ids[i]].name)


class _Transforms:
    """Coal transforms of placements ``R`` ``(K, G, 3, 3)``, ``x`` ``(K, G, 3)`` [m], each
    built when first asked for and kept (a body's placement at a sample is read by
    every pair it is in)."""

    def __init__(self, R: np.ndarray, x: np.ndarray) -> None:
        import coal

        self._make = coal.Transform3s
        self._n = R.shape[1]
        self._R, self._x = R.reshape(-1, 3, 3), x.reshape(-1, 3)  # row k * G + g
        self._known: list[Any] = [None] * self._x.shape[0]

    def __call__(self, k: int, g: int) -> Any:
        """The transform of body ``g`` at sample ``k``."""
        i = k * self._n + g
        tf = self._known[i]
        if tf is None:
            tf = self._known[i] = self._make(self._R[i], self._x[i])
        return tf


def _exact_min(lower: np.ndarray, exact: Any, refine: Any = None) -> tuple[float, tuple[int, int]]:
    """The exact minimum of ``exact(k, j)`` over all entries of ``lower`` (K, J).

    ``lower[k, j]`` must be a lower bound of ``exact(k, j)``, and so must ``refine(idx)``
    of the entries at the flat indices ``idx`` (a tighter, costlier bound; optional).
    The entry of the smallest bound is evaluated first; the entries whose bound is
    below its value get the tighter bound (the others cannot be below it). They are
    evaluated in increasing order of that bound until the next bound is not below the
    best exact value: every entry left has a value at least its bound, hence at least
    the best.
    """
    flat, n = lower.ravel(), lower.shape[1]
    if flat.size == 0:
        return math.inf, (0, 0)
    seed = int(np.argmin(flat))
    d = float(exact(*divmod(seed, n)))
    best, arg = (d if d < math.inf else math.inf), seed
    todo = np.flatnonzero(~(flat >= best))  # NaN bounds too: no bound
    bound = flat[todo]
    if refine is not None and todo.size:
        chunks = [refine(todo[i : i + _REFINE_CHUNK]) for i in range(0, todo.size, _REFINE_CHUNK)]
        bound = np.maximum(bound, np.concatenate(chunks))
        keep = ~(bound >= best)
        todo, bound = todo[keep], bound[keep]
    order = np.argsort(bound, kind="stable")
    for idx, b in zip(todo[order].tolist(), bound[order].tolist(), strict=True):
        if b >= best:
            break
        if idx == seed:
            continue
        d = float(exact(*divmod(idx, n)))
        if d < best:
            best, arg = d, idx
    return best, divmod(arg, n)
