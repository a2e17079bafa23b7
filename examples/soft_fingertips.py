"""Soft fingertips: two fingers that hold while the others take turns.

The Allegro hand turns its box 140 deg at 30 deg/s about the thumb's contact. With
point contacts (the default contact model) three fingers must hold while one is in
the air, and the Allegro has four: its index, middle and ring crowd the face the box
turns under them, and the plan fails with a typed error. Rubber fingertips resist a
little torque about the contact normal (``ContactModel.torsion_m``, here 1 mm: a
contact patch of about 2 mm radius); with it the thumb and one finger opposing it
hold the box while another finger moves, and the turn plans. The plan file records
the torsion, and the independent re-check reads it from there.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from regrasp_pin import ContactModel, Plan, PlanningError, make_scenario, plan_scenario
from regrasp_pin.plan import ContactPhase
from regrasp_pin.verify.plan_check import recheck_plan


def holding(plan: Plan) -> list[tuple[float, float, tuple[str, ...]]]:
    """``(from [s], to [s], fingers)``: who holds the object, between two phase ends."""
    contacts = [c for ps in plan.phases.values() for c in ps if isinstance(c, ContactPhase)]
    ends = np.unique([t for c in contacts for t in (c.t_start, c.t_end)])
    out = []
    for a, b in zip(ends[:-1], ends[1:], strict=True):
        mid = 0.5 * (a + b)
        held = tuple(sorted(c.finger for c in contacts if c.t_start <= mid <= c.t_end))
        out.append((float(a), float(b), held))
    return out


def main(out: Path = Path("out/examples")) -> Path:
    """Fail with point contacts, plan with soft ones, re-check; return the plan file."""
    try:
        plan_scenario(make_scenario("allegro", "box", angle_deg=140, rate_deg_s=30))
        print("point contacts: planned")
    except PlanningError as exc:
        print(f"point contacts: {exc.kind.value} of the {exc.finger} at {exc.time_s:.2f} s")
    soft = ContactModel(torsion_m=0.001)
    result = plan_scenario(
        make_scenario("allegro", "box", angle_deg=140, rate_deg_s=30, contact=soft)
    )
    path = result.plan.save(out / "soft_fingertips.json")
    print(f"soft fingertips (torsion 1 mm): {len(result.plan.regrasps())} regrasps")
    for a, b, held in holding(result.plan):
        if len(held) == 2:
            print(f"  {a:.2f}-{b:.2f} s: {' and '.join(held)} hold the box alone")
    check = recheck_plan(Plan.load(path))  # the torsion read from the file
    eps, t_eps = check.min_closure_epsilon, check.t_min_closure_s
    print(f"re-check: {'ok' if check.ok else check.problems}, at least {check.min_holding} hold,")
    print(f"  the weakest hold's epsilon {eps:.3g} at {t_eps:.2f} s")
    return path


if __name__ == "__main__":
    main()
