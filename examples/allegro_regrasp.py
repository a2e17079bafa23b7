"""The same pipeline on the four-finger Allegro hand from example-robot-data.

Loads the Allegro right hand offline, builds its scenario (a prism turned about the
thumb's contact), plans every regrasp with Coal verification and prints a summary.
"""

from __future__ import annotations

from pathlib import Path

from regrasp_pin import make_scenario, plan_manipulation


def main(out: Path = Path("out/examples")) -> None:
    scen = make_scenario("allegro", "hexagon")
    print(scen.description)
    result = plan_manipulation(
        scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=scen.params
    )
    for r in result.regrasps:
        print(
            f"{r.finger:7} lift-off {r.t_start:5.2f} s, landing {r.t_end:5.2f} s, "
            f"min clearance {1e3 * r.min_clearance_m:5.2f} mm, {r.planning_ms:5.0f} ms"
        )
    print(f"{len(result.regrasps)} regrasps; plan: {result.plan.save(out / 'allegro_plan.json')}")


if __name__ == "__main__":
    main()
