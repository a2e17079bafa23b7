"""A finger's joint-space manifold moving with the object (the paper's Fig. 2).

Maps a box's sampled surface into the index finger's 3-D joint space while the box
turns, prints how the feasible region shrinks and moves, and saves the Fig. 2 view to
``out/examples/manifold.png``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from regrasp_pin import Box, Hand, Manifold, ObjectMotion, SurfaceSample, build_manifold


def main(out: Path = Path("out/examples")) -> tuple[Manifold, SurfaceSample]:
    """Print how much of the box the index finger can touch over time; return its
    manifold and the surface sample it was built on."""
    hand = Hand.five_finger()
    box = Box((0.04, 0.06, 0.04))
    T0 = np.eye(4)
    T0[:3, 3] = [0.065, 0.0, 0.06]
    motion = ObjectMotion.constant_twist(
        T0, axis_palm=[0, 1, 0], point_palm=T0[:3, 3], rate_rad_s=np.radians(30), duration_s=3.0
    )
    sample = box.sample_surface(0.003)
    times = np.linspace(0.0, 3.0, 31)
    man = build_manifold(hand.fingers["index"], sample, motion, times)
    for k in range(0, times.size, 6):
        print(
            f"t={times[k]:.1f} s: {int(man.reachable[k].sum()):4d} reachable, "
            f"{int(man.inside[k].sum()):4d} inside the limits, "
            f"{int(man.feasible[k].sum()):4d} feasible"
        )
    try:
        from regrasp_pin.plotting.manifold import plot_manifold
    except ImportError:  # matplotlib missing: pip install regrasp-pin[viz]
        return man, sample
    out.mkdir(parents=True, exist_ok=True)
    fig = plot_manifold(man, times_idx=[0, 10, 20, 30])
    fig.savefig(out / "manifold.png", dpi=100)
    print(f"figure: {out / 'manifold.png'}")
    return man, sample


if __name__ == "__main__":
    main()
