"""A deterministic suite of manipulation scenarios: specs, builds, runs and a summary.

The canonical scenario (:func:`~regrasp_pin.scenarios.make_scenario`) is one point in a space of
problems; the suite samples that space so that a planner change can be measured on
many problems at once, the same ones on every machine.

* :class:`ScenarioSpec` (:mod:`.specs`) holds everything needed to rebuild a scenario
  (hand, object, pose offsets, motion, seeds) as plain JSON values.
* :func:`generate_specs` draws specs deterministically: spec ``i`` depends only on
  ``(seed, i)`` (``numpy.random.default_rng([seed, i])``), so a longer suite starts
  with the shorter one. Hands alternate (``i % len(hands)``; the bundled two by
  default, or any JSON hand files, :meth:`~regrasp_pin.model.hand.Hand.from_file`),
  object kinds cycle (``i % 3``) and motion kinds cycle shifted by ``i // 6``, so
  every prefix is balanced over each and, with two hands, every 18 consecutive specs
  hold each hand x object x motion combination once. :func:`neighbour_specs` are the
  canonical demo and its neighbours, 15 per hand. A hand file's canonical pose is
  found by :func:`~regrasp_pin.scenarios.setup_pose` (a placement search, once per
  process) and its canonical objects are the five-finger hand's, scaled by the file's
  ``scenario.object_scale``.
* :func:`build_scenario` (:mod:`.build`) builds a spec the way
  :func:`~regrasp_pin.scenarios.make_scenario` does: the object at the hand's
  canonical pose composed with the spec's offsets, an initial grasp chosen by
  :func:`~regrasp_pin.grasp.initial.initial_grasp` over the manifolds of a turn about
  an axis through the object's centre, then the motion placed.
  :func:`suite_scenarios` skips the specs without an initial grasp.
* :func:`run_scenario` (:mod:`.run`) builds and plans one spec and records the outcome
  as a :class:`ScenarioResult`: failure kind, numbers, attempts, timings, and for a
  full plan the independent re-check of the saved plan file
  (:func:`~regrasp_pin.verify.plan_check.recheck_plan`).
* :func:`summarize` (:mod:`.report`) turns results into a plain-text report, and
  :func:`time_spent` says where a suite's time went.

Object sizes are centred on the canonical objects of each hand
(:func:`~regrasp_pin.scenarios.setup_objects`) and vary by +-10 %; motions turn by
60-270 deg either way at 10-45 deg/s; the object starts up to 3 mm and 6 deg away from
the canonical pose. The grasp search of a
generated spec samples the turn every ~2 deg (0.05-0.2 s) over its first 120 deg.
"""

from .build import build_scenario, suite_scenarios
from .report import summarize, time_spent
from .run import ScenarioResult, load_results, run_scenario
from .specs import (
    MAX_DRAWS_PER_SCENARIO,
    MOTION_KINDS,
    OBJECT_KINDS,
    MotionSpec,
    ObjectSpec,
    ScenarioSpec,
    generate_specs,
    neighbour_specs,
    select_specs,
)

__all__ = [
    "MAX_DRAWS_PER_SCENARIO",
    "MOTION_KINDS",
    "OBJECT_KINDS",
    "MotionSpec",
    "ObjectSpec",
    "ScenarioResult",
    "ScenarioSpec",
    "build_scenario",
    "generate_specs",
    "load_results",
    "neighbour_specs",
    "run_scenario",
    "select_specs",
    "suite_scenarios",
    "summarize",
    "time_spent",
]
