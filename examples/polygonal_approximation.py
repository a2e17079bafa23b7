"""Polygonal approximation with the competitive Hopfield network (Eqs. 5-10, Fig. 8).

Approximates a noisy closed curve and an open path by m of their points, with the
paper's network and with the exact dynamic-programming optimum beside it, and saves
a Fig. 8 style plot to ``out/examples/polygon.png``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from regrasp_pin import approximate_polygon


def main(out: Path = Path("out/examples")) -> list[tuple[float, float]]:
    """Print and return the (Hopfield, exact) energies of each curve and deviation."""
    rng = np.random.default_rng(0)
    s = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    circle = np.c_[np.cos(s), 0.6 * np.sin(s)] + rng.normal(0, 0.01, (200, 2))
    path = np.c_[np.linspace(0, 1, 150), 0.2 * np.sin(np.linspace(0, 3 * np.pi, 150))]
    energies = []
    for name, pts, closed in (("closed curve", circle, True), ("open path", path, False)):
        for deviation in ("max", "ise"):
            net = approximate_polygon(pts, 10, closed=closed, deviation=deviation)
            best = approximate_polygon(pts, 10, closed=closed, deviation=deviation, method="exact")
            print(
                f"{name:12} {deviation:3}: Hopfield {net.energy:.5f} ({net.sweeps} sweeps), "
                f"exact {best.energy:.5f}, ratio {net.energy / best.energy:.3f}"
            )
            energies.append((net.energy, best.energy))
    try:
        from regrasp_pin.plotting.polygon import plot_polygon
    except ImportError:  # matplotlib missing: pip install regrasp-pin[viz]
        return energies
    out.mkdir(parents=True, exist_ok=True)
    fig = plot_polygon(path, approximate_polygon(path, 7, deviation="ise"))
    fig.savefig(out / "polygon.png", dpi=100)
    print(f"figure: {out / 'polygon.png'}")
    return energies


if __name__ == "__main__":
    main()
