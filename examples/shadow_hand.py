"""A whole-hand regrasping plan with a real hand: the Shadow Dexterous Hand.

The hand comes from third-party models outside this package (``../shared/hands``, the
Shadow Hand E of dexsuite/dex-urdf) through the hand file
``examples/hands/shadow_hand.json``: the palm frame ``palm`` locks the two wrist joints
away, each finger's distal joint J1 follows its J2 (a coupling the URDF does not
declare), and the collision meshes (in millimetres, scale 0.001) become convex hulls.

No setup is hand-written for it: :func:`regrasp_pin.scenarios.scenario_for_hand`
places an octagonal prism where the thumb and three fingers can grasp it
(:mod:`regrasp_pin.placing`) and turns it about the thumb's contact. The planner keeps
the prism in force closure while the fingers regrasp (:func:`regrasp_pin.plan_scenario`:
from another initial grasp if a finger fails on the contact it started on); the plan
is saved, reloaded and re-checked with Pinocchio and Coal alone.

Run it from the repository with the models at ``../shared/hands``:
``python examples/shadow_hand.py``.
"""

from __future__ import annotations

from pathlib import Path

from regrasp_pin import Hand, Plan, Prism, plan_scenario
from regrasp_pin.planning.params import with_time_law
from regrasp_pin.scenarios import scenario_for_hand, setup_time_law
from regrasp_pin.verify.plan_check import recheck_plan

HAND_FILE = Path(__file__).resolve().parent / "hands" / "shadow_hand.json"
#: The thumb pins the prism; of the others, the little finger reaches farthest (its
#: extra metacarpal joint LFJ5), so it takes the ring finger's place.
FINGERS = ("thumb", "index", "middle", "little")
ANGLE_DEG = -100.0
RATE_DEG_S = 20.0


def main(out: Path = Path("out/examples")) -> Path:
    """Plan, save and re-check the Shadow Hand's manipulation; return the plan's path."""
    hand = Hand.from_file(HAND_FILE)
    prism = Prism(8, 0.040, 0.050)  # octagonal: circumradius 40 mm, 50 mm long
    scen = scenario_for_hand(
        hand, prism, fingers=FINGERS, angle_deg=ANGLE_DEG, rate_deg_s=RATE_DEG_S
    )
    print(scen.description)
    # the hand file's time law (cruise: its 2 rad/s finger joints bind the regrasps)
    params = with_time_law(scen.params, setup_time_law(str(HAND_FILE)))
    # from another start if a finger fails on its first contact
    plan = plan_scenario(scen, params=params)
    for r in plan.regrasps:
        print(
            f"  {r.finger:7} regrasps at t={r.t_start:.2f}-{r.t_end:.2f} s, "
            f"{1e3 * r.path_length_m:.1f} mm, min clearance {1e3 * r.min_clearance_m:.2f} mm"
        )
    path = plan.plan.save(out / "shadow_hand_plan.json")
    check = recheck_plan(Plan.load(path), mu=scen.params.mu)
    print(
        f"{len(plan.regrasps)} regrasps; saved {path}; independent re-check: "
        f"{'passed' if check.ok else check.problems}"
    )
    return path


if __name__ == "__main__":
    main()
