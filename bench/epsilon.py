"""The Ferrari-Canny epsilon of grasps on the suite's objects, against qhull's default
hull, in one run.

Grasps: ``--n`` sets of 3-5 contacts drawn (seeded) from the 2 mm surface samples of
a 40 x 60 x 40 mm box and a hexagonal prism (32 mm circumradius, 40 mm high), point
contacts and soft ones (1 mm torsion), friction 0.8, the torque scale the objects'
radius: what the choice of Q and the initial grasp ask for, in force closure or not.
Prints, best of 3 each:

- the epsilon as the planner computes it
  (:func:`regrasp_pin.grasp.quality.ferrari_canny_epsilon`: the hull without merged
  facets where it passes its check, else the default hull);
- the baseline: the same wrenches' epsilon from ``scipy.spatial.ConvexHull`` with its
  default options (merged facets, ``Qx`` in 6-D), and the ratio;
- how many hulls were taken without merging, and the largest relative difference
  between the two epsilons over the sets in force closure (the decisions compare
  epsilons within ``EPSILON_RTOL``).

Usage: ``python bench/epsilon.py [--n 2000] [--seed 0]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from machine import machine_line
from scipy.spatial import ConvexHull, QhullError

from regrasp_pin.grasp import quality
from regrasp_pin.grasp.quality import EPSILON_RTOL, FORCE_CLOSURE_TOL, contact_wrenches
from regrasp_pin.model.objects import Box, Prism

MU = 0.8


def grasps(n: int, seed: int) -> list[np.ndarray]:
    """``n`` wrench sets ``(M, 6)`` of random contacts on the two objects."""
    rng = np.random.default_rng(seed)
    sets = []
    for obj in (Box((0.04, 0.06, 0.04)), Prism(6, 0.032, 0.04)):
        sample = obj.sample_surface(0.002)
        for _ in range(n // 2):
            idx = rng.choice(len(sample), size=int(rng.integers(3, 6)), replace=False)
            torsion = float(rng.choice([0.0, 0.001]))
            sets.append(
                contact_wrenches(
                    sample.points[idx],
                    sample.normals[idx],
                    MU,
                    torque_scale_m=obj.radius_m,
                    torsion_m=torsion,
                )
            )
    return sets


def merged_epsilon(w: np.ndarray) -> float:
    """The baseline: epsilon from qhull's default hull (0 where it has no 6-D hull)."""
    try:
        hull = ConvexHull(w)
    except QhullError:
        return 0.0
    return max(float(np.min(-hull.equations[:, -1])), 0.0)


def best_of(fn, sets, repeats=3):
    best, out = np.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = [fn(w) for w in sets]
        best = min(best, time.perf_counter() - t0)
    return best, np.array(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=2000, help="wrench sets (default 2000)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    print(machine_line())
    sets = grasps(args.n, args.seed)
    unmerged = sum(quality._simplicial_epsilon(w) is not None for w in sets)
    t_lib, eps = best_of(quality._hull_epsilon, sets)
    t_ref, ref = best_of(merged_epsilon, sets)
    closing = ref > FORCE_CLOSURE_TOL
    rel = np.abs(eps[closing] - ref[closing]) / ref[closing]
    same_fc = np.array_equal(eps > FORCE_CLOSURE_TOL, closing)
    per = 1e3 / len(sets)
    print(f"{len(sets)} wrench sets, {closing.sum()} in force closure, friction {MU}")
    print(f"{'step':44} {'time':>12}")
    print(f"{'epsilon, the planner':44} {t_lib * per:9.3f} ms")
    print(f"{'epsilon, default hull (baseline)':44} {t_ref * per:9.3f} ms")
    print(f"{'speed-up':44} {t_ref / t_lib:9.2f} x")
    print(f"hulls without merged facets: {unmerged}/{len(sets)} passed their check")
    print(
        f"largest relative difference in force closure: {rel.max(initial=0.0):.1e} "
        f"(decisions compare within {EPSILON_RTOL:g}); "
        f"force closure {'the same' if same_fc else 'DIFFERS'} for every set"
    )


if __name__ == "__main__":
    main()
