"""Polygonal approximation: deviation matrix H, competitive Hopfield network and exact DP.

Generates noisy circles, spirals, sine paths, grid paths (4-connected lattice walks, as on
the object's surface grid) and digital curves (rasterized blobs with repeated pixels), with
n = 100, 200, 500 points, and reduces them to m = 7, 10, 20 vertices. Prints:

1. the headline case (n = 500, m = 20, ``"max"``, 2-D): time for H (the band the network
   uses), for the network (plain run + restarts), H + network, for the exact solver (its
   own pruned H + DP), and the energy ratio network / exact, per curve, open and closed;
2. the same times (median over curves, open and closed) and mean ratio for every n and m;
3. quality: energy ratio network / exact (mean and worst) and that of the plain network
   of the paper, by deviation, open/closed, 2-D/3-D, over all curves, n and m (cases whose
   optimum is 0, e.g. a lattice path cut at its corners, are counted apart);
4. the baseline: a naive numpy O(n^3) H (one chord start at a time, every end and arc
   point broadcast) against the full exact H and the network's band, n = 500;
5. closed digital curves as the polygonal-approximation literature uses them (8-connected
   outlines of 53-112 points with sharp corners, one-pixel-wide parts, repeated pixels, a
   spiral; :mod:`digital_curves`), m = 8 to 30, for every deviation: energy / exact
   optimum of the network and of the plain network of the paper, and the network's time.

Times are the best of ``--repeat`` runs [ms]. Usage:
``python bench/polygon.py [--repeat K] [--quick] [--digital]`` (``--quick``: n <= 200 in
part 3; ``--digital``: part 5 only).
"""

from __future__ import annotations

import argparse
import time
from collections import defaultdict
from collections.abc import Callable

import numpy as np
from digital_curves import benchmark_curves
from machine import machine_line

from regrasp_pin.polygon.approximate import approximate_polygon, network_band
from regrasp_pin.polygon.deviation import DEVIATIONS, deviation_matrix
from regrasp_pin.polygon.hopfield import initial_state

CURVES = ("circle", "spiral", "sine", "grid", "digital")
SIZES = (100, 200, 500)
VERTICES = (7, 10, 20)


def make_curve(kind: str, n: int, d: int = 2, seed: int = 0) -> np.ndarray:
    """A test curve of ``n`` points, shape ``(n, d)``."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, n)
    if kind == "circle":
        a = 2 * np.pi * np.arange(n) / n
        P = np.c_[np.cos(a), np.sin(a)] + 0.01 * rng.standard_normal((n, 2))
    elif kind == "spiral":
        a = 5 * np.pi * t
        P = np.c_[(0.2 + 0.8 * t) * np.cos(a), (0.2 + 0.8 * t) * np.sin(a)]
    elif kind == "sine":
        P = np.c_[4 * t, np.sin(3 * np.pi * t)] + 0.005 * rng.standard_normal((n, 2))
    elif kind == "grid":
        steps = np.array([[1, 0], [0, 1], [-1, 0], [0, -1]])
        heading, moves = 0, []
        for _ in range(n - 1):
            if rng.random() < 0.15:
                heading = (heading + rng.choice([1, 3])) % 4
            moves.append(steps[heading])
        P = np.vstack([[0, 0], np.cumsum(moves, axis=0)]).astype(float)
    elif kind == "digital":
        a = 2 * np.pi * np.arange(n) / n
        r = 1 + 0.3 * np.sin(3 * a) + 0.15 * np.cos(5 * a)
        P = np.round(np.c_[r * np.cos(a), r * np.sin(a)] * n / 9)
    else:
        raise ValueError(kind)
    if d == 3:
        scale = float(np.ptp(P, axis=0).max())
        P = np.c_[P, 0.2 * scale * np.sin(4 * np.pi * t)]
    return P


def best_of(repeat: int, fn: Callable[[], object]) -> tuple[float, object]:
    """Best wall time of ``repeat`` calls [ms] and the last result."""
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best * 1e3, out


def ratio(a: float, b: float) -> float:
    """a / b; 1 when both are 0 (a straight stretch per chord), inf when only b is."""
    if b <= 0.0:
        return 1.0 if a <= 0.0 else np.inf
    return a / b


def zero_level(P: np.ndarray, deviation: str) -> float:
    """Energies below this are rounding noise of an exactly zero energy."""
    size = float(np.ptp(P, axis=0).max())
    return 1e-9 * (size**2 * len(P) if deviation == "ise" else size * len(P))


def clean(e: float, level: float) -> float:
    return 0.0 if e <= level else e


def run_case(P, m, closed, deviation, repeat):
    """(H ms, network ms, exact ms, network energy, exact energy, plain energy).

    Times are the best of ``repeat`` runs; energies below :func:`zero_level` read 0.
    """
    hop_times, exact_times = [], []
    for _ in range(repeat):
        hop = approximate_polygon(P, m, closed=closed, deviation=deviation)
        hop_times.append((hop.timings_ms["H"], hop.timings_ms["network"]))
        ex = approximate_polygon(P, m, closed=closed, deviation=deviation, method="exact")
        exact_times.append(ex.timings_ms["exact"])
    t_h = min(t[0] for t in hop_times)
    t_net = min(t[1] for t in hop_times)
    z = zero_level(P, deviation)
    energies = (clean(hop.energy, z), clean(ex.energy, z), clean(hop.plain_energy, z))
    return (t_h, t_net, min(exact_times), *energies)


def naive_max_h(P: np.ndarray) -> np.ndarray:
    """Baseline: per chord start, all ends and arc points broadcast (O(n^3) work)."""
    n = P.shape[0]
    H = np.full((n, n), np.inf)
    for x in range(n - 1):
        w = P[x + 1 :] - P[x]  # chords to every end y > x
        v = P[x + 1 :] - P[x]  # arc points z > x
        cross = w[:, None, 0] * v[None, :, 1] - w[:, None, 1] * v[None, :, 0]
        dist = np.abs(cross) / np.maximum(np.linalg.norm(w, axis=1), 1e-300)[:, None]
        k = w.shape[0]
        dist[np.arange(k)[None, :] >= np.arange(k)[:, None]] = 0.0  # only z < y
        H[x, x + 1 :] = dist.max(axis=1)
    return H


def headline(repeat: int) -> None:
    print("1) n = 500, m = 20, deviation max, 2-D  [ms]")
    print(
        f"{'curve':8} {'closed':>6} {'H':>6} {'network':>8} {'H+net':>7} {'exact':>7} "
        f"{'net/exact':>9} {'plain/exact':>11}"
    )
    for kind in CURVES:
        P = make_curve(kind, 500)
        for closed in (False, True):
            t_h, t_net, t_ex, e_h, e_x, e_p = run_case(P, 20, closed, "max", repeat)
            print(
                f"{kind:8} {closed!s:>6} {t_h:6.1f} {t_net:8.1f} {t_h + t_net:7.1f} "
                f"{t_ex:7.1f} {ratio(e_h, e_x):9.4f} {ratio(e_p, e_x):11.4f}"
            )


def grid_of_sizes(repeat: int) -> None:
    print("\n2) deviation max, 2-D, median over curves and open/closed  [ms]")
    print(f"{'n':>4} {'m':>3} {'H':>6} {'network':>8} {'H+net':>7} {'exact':>7} {'net/exact':>9}")
    for n in SIZES:
        for m in VERTICES:
            rows = []
            for kind in CURVES:
                P = make_curve(kind, n)
                for closed in (False, True):
                    rows.append(run_case(P, m, closed, "max", repeat))
            a = np.array([r[:3] for r in rows])
            q = np.mean([ratio(r[3], r[4]) for r in rows])
            med = np.median(a, axis=0)
            print(
                f"{n:4d} {m:3d} {med[0]:6.1f} {med[1]:8.1f} {np.median(a[:, 0] + a[:, 1]):7.1f} "
                f"{med[2]:7.1f} {q:9.4f}"
            )


def quality(quick: bool) -> None:
    sizes = SIZES[:2] if quick else SIZES
    print(
        f"\n3) quality over {len(CURVES)} curves x n in {sizes} x m in {VERTICES}: "
        "energy / exact optimum"
    )
    groups: dict[tuple, list[tuple[float, float]]] = defaultdict(list)
    for deviation in DEVIATIONS:
        for closed in (False, True):
            for d in (2, 3):
                for kind in CURVES:
                    for n in sizes:
                        P = make_curve(kind, n, d)
                        for m in VERTICES:
                            hop = approximate_polygon(P, m, closed=closed, deviation=deviation)
                            ex = approximate_polygon(
                                P, m, closed=closed, deviation=deviation, method="exact"
                            )
                            z = zero_level(P, deviation)
                            e_x = clean(ex.energy, z)
                            groups[(deviation, closed, d)].append(
                                (
                                    ratio(clean(hop.energy, z), e_x),
                                    ratio(clean(hop.plain_energy, z), e_x),
                                    float(e_x == 0.0),
                                )
                            )
    print(
        f"{'deviation':9} {'closed':>6} {'dim':>3} {'cases':>5} {'E*=0':>5} {'mean':>7} "
        f"{'worst':>7} {'plain mean':>10} {'plain worst':>11}"
    )

    def line(label: tuple[str, str, str], a: np.ndarray) -> None:
        nz = a[a[:, 2] == 0.0]  # ratios need a nonzero optimum
        zero = a[a[:, 2] == 1.0]
        bad = int((zero[:, 0] != 1.0).sum())
        print(
            f"{label[0]:9} {label[1]:>6} {label[2]:>3} {len(a):5d} "
            f"{len(zero):5d} {nz[:, 0].mean():7.4f} {nz[:, 0].max():7.4f} "
            f"{nz[:, 1].mean():10.4f} {nz[:, 1].max():11.4f}"
            + (f"  ({bad} with E*=0 missed)" if bad else "")
        )

    per_dev: dict[str, list] = defaultdict(list)
    for (deviation, closed, d), vals in groups.items():
        a = np.array(vals)
        per_dev[deviation].append(a)
        line((deviation, str(closed), str(d)), a)
    everything = []
    for deviation, arrs in per_dev.items():
        a = np.vstack(arrs)
        everything.append(a)
        line((deviation, "all", "all"), a)
    line(("all", "all", "all"), np.vstack(everything))
    print(
        "E*=0: cases whose optimum is 0 (every chord straight); they are left out of the "
        "ratios, and the network finds 0 on all of them unless stated."
    )


def baseline(repeat: int) -> None:
    print("\n4) H for deviation max, n = 500, open noisy circle  [ms]")
    P = make_curve("circle", 500)
    band = network_band(initial_state(P, 20), 500, False)
    t_naive, Hn = best_of(1, lambda: naive_max_h(P))
    t_full, Hf = best_of(repeat, lambda: deviation_matrix(P, "max"))
    t_band, _ = best_of(repeat, lambda: deviation_matrix(P, "max", max_span=band))
    t_ise, _ = best_of(repeat, lambda: deviation_matrix(P, "ise"))
    fin = np.isfinite(Hf)
    err = float(np.abs(Hn[fin] - Hf[fin]).max())
    print(f"naive numpy O(n^3) H       {t_naive:8.1f}")
    print(f"full exact H (deviation)   {t_full:8.1f}   (max |difference| to naive {err:.1e})")
    print(f"network band, span <= {band:3d} {t_band:8.1f}   (m = 20)")
    print(f"ise H, O(n^2) prefix sums  {t_ise:8.1f}")


DIGITAL_M = (8, 12, 16, 20, 25, 30)


def digital() -> None:
    curves = benchmark_curves()
    sizes = sorted(len(P) for _, P in curves)
    print(
        f"\n5) closed digital curves: {len(curves)} outlines, n = {sizes[0]}-{sizes[-1]}, "
        f"m in {DIGITAL_M}: energy / exact optimum"
    )
    print(
        f"{'deviation':9} {'cases':>5} {'E*=0':>5} {'mean':>7} {'worst':>7} {'plain mean':>10} "
        f"{'plain worst':>11} {'>plain':>6} {'missed0':>7} {'net ms':>7}"
    )
    worst_case: dict[str, tuple[float, str, int]] = {}
    for deviation in DEVIATIONS:
        rows, times = [], []
        for label, P in curves:
            for m in DIGITAL_M:
                hop = approximate_polygon(P, m, closed=True, deviation=deviation)
                ex = approximate_polygon(P, m, closed=True, deviation=deviation, method="exact")
                z = zero_level(P, deviation)
                e_x = clean(ex.energy, z)
                e_h, e_p = clean(hop.energy, z), clean(hop.plain_energy, z)
                rows.append((ratio(e_h, e_x), ratio(e_p, e_x), float(e_x == 0.0), e_h > e_p))
                times.append(hop.timings_ms["H"] + hop.timings_ms["network"])
                if rows[-1][0] > worst_case.get(deviation, (0.0, "", 0))[0]:
                    worst_case[deviation] = (rows[-1][0], label, m)
        a = np.array(rows)
        nz = a[a[:, 2] == 0.0]
        print(
            f"{deviation:9} {len(a):5d} {int(a[:, 2].sum()):5d} {nz[:, 0].mean():7.4f} "
            f"{nz[:, 0].max():7.4f} {nz[:, 1].mean():10.4f} {nz[:, 1].max():11.4f} "
            f"{int(a[:, 3].sum()):6d} {int((a[a[:, 2] == 1.0, 0] != 1.0).sum()):7d} "
            f"{np.median(times):7.1f}"
        )
    print(
        "worst cases: "
        + ", ".join(f"{d} {r:.3f} ({lab}, m={m})" for d, (r, lab, m) in worst_case.items())
    )
    print(
        ">plain: cases where the network ends above the plain network; missed0: cases with "
        "optimum 0 (left out of the ratios) where the network is above 0; net ms: median "
        "H + network."
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="timing repetitions (best of)")
    parser.add_argument("--quick", action="store_true", help="n <= 200 in the quality table")
    parser.add_argument("--digital", action="store_true", help="only the digital curves (part 5)")
    args = parser.parse_args()
    print(machine_line())
    if args.digital:
        digital()
        return
    headline(args.repeat)
    grid_of_sizes(args.repeat)
    quality(args.quick)
    baseline(args.repeat)
    digital()


if __name__ == "__main__":
    main()
