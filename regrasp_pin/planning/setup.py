"""What a plan builds before it searches, whatever its initial grasp.

:func:`~.planner.plan_manipulation` first samples the object's surface, builds the
taking-part fingers' manifolds on the manifold grid and proves where a finger must
hold (:func:`~.feasibility.must_hold_runs`); none of it depends on the initial grasp.
A caller that plans the same hand, object and motion from several grasps (the backups
of :func:`~regrasp_pin.backups.plan_scenario`) builds it once with :func:`plan_setup`
and passes it to each plan (``setup=``): the plans are the same as without it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..exceptions import InputError
from ..grasp.holding import rest_configuration
from ..grasp.manifold import Manifold, build_manifolds
from ..grasp.necessity import MustHold
from ..model.hand import Hand
from ..model.motion import ObjectMotion
from ..model.objects import ConvexObject, SurfaceSample
from ..model.scene import Scene
from .feasibility import must_hold_runs
from .params import PlannerParams

__all__ = ["PlanSetup", "plan_setup"]


@dataclass(frozen=True)
class PlanSetup:
    """The grasp-independent part of a plan (:func:`plan_setup`).

    Attributes:
        hand: The hand it was built for.
        obj: The object.
        motion: The motion.
        base_q: ``(nq,)`` the hand with the idle fingers at rest [rad].
        sample: The surface sample.
        manifolds: The taking-part fingers' manifolds on the manifold grid.
        every: The manifolds of every finger that could hold (idle ones included where
            they may join).
        runs: The runs in which a finger cannot let go.
        stage_s: The time each part took [s] (``"manifolds"``, ``"must hold"``).
        key: What of the planner's parameters it was built with, by name
            (:meth:`check`).
    """

    hand: Hand
    obj: ConvexObject
    motion: ObjectMotion
    base_q: np.ndarray
    sample: SurfaceSample
    manifolds: dict[str, Manifold]
    every: dict[str, Manifold]
    runs: list[MustHold]
    stage_s: dict[str, float]
    key: dict[str, Any]

    @property
    def active(self) -> tuple[str, ...]:
        """The fingers that take part (as built: ``key["fingers"]``)."""
        return self.key["fingers"]

    def check(
        self, hand: Hand, obj: ConvexObject, motion: ObjectMotion, params: PlannerParams
    ) -> None:
        """Raise InputError unless this setup was built for ``hand``, ``obj`` and
        ``motion`` (the same objects) and parameters that build the same (``params``'
        fingers, sampling, manifold grid, contact model, friction, release and proof
        settings, shortest regrasp); the message names what differs."""
        given = {"hand": hand, "obj": obj, "motion": motion}
        built = {"hand": self.hand, "obj": self.obj, "motion": self.motion}
        other = [name for name in given if given[name] is not built[name]]
        if other:
            raise InputError(
                "setup",
                f"was built for another {', '.join(other)}",
                "plan_setup() of the same hand, object and motion objects",
            )
        now = _key(hand, params)
        changed = [
            f"{k} built {self.key[k]!r}, given {now[k]!r}" for k in now if now[k] != self.key[k]
        ]
        if changed:
            raise InputError(
                "setup",
                f"was built with other planner parameters ({'; '.join(changed)})",
                "plan_setup() with these params",
            )


def plan_setup(
    hand: Hand, obj: ConvexObject, motion: ObjectMotion, params: PlannerParams | None = None
) -> PlanSetup:
    """Build the grasp-independent part of a plan (module docstring).

    Args:
        hand: The hand.
        obj: The object.
        motion: The object's motion.
        params: :class:`~.params.PlannerParams` (default ones if None).

    Returns:
        The :class:`PlanSetup`, for ``plan_manipulation(..., setup=...)`` with the same
        hand, object, motion and parameters that build the same.

    Raises:
        InputError: a part of the wrong type, a motion that takes the object more than
            1 m from the palm (as :func:`~.planner.plan_manipulation`).
        UnknownNameError: a finger of ``params.fingers`` that the hand does not have.
    """
    Scene(hand, obj, motion)  # checks types and scale before any work
    params = params or PlannerParams()
    key = _key(hand, params)
    active = key["fingers"]
    for name in active:
        hand.finger(name)  # raises UnknownNameError listing the valid names
    base_q = rest_configuration(
        hand, obj, motion, [n for n in hand.finger_names if n not in active]
    )
    stage: dict[str, float] = {}
    t0 = time.perf_counter()
    sample = obj.sample_surface(params.sample_spacing_m)
    n_m = max(int(round(motion.duration_s / params.manifold_dt_s)), 1) + 1
    m_times = np.linspace(motion.t_start, motion.t_end, n_m)
    manifolds = build_manifolds(
        hand, active, sample, motion, m_times, contact=params.contact, threads=params.threads
    )
    stage["manifolds"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    every, runs = must_hold_runs(hand, obj, motion, sample, m_times, manifolds, params)
    stage["must hold"] = time.perf_counter() - t0
    return PlanSetup(hand, obj, motion, base_q, sample, manifolds, every, runs, stage, key)


def _key(hand: Hand, params: PlannerParams) -> dict[str, Any]:
    """What in ``params`` the setup depends on, by name."""
    return {
        "fingers": tuple(params.fingers) if params.fingers else tuple(hand.finger_names),
        "sample_spacing_m": params.sample_spacing_m,
        "manifold_dt_s": params.manifold_dt_s,
        "contact": params.contact,
        "mu": params.mu,
        "release": params.release,
        "prove_infeasible": params.prove_infeasible,
        "regrasp.duration_s": params.regrasp.duration_s,
    }
