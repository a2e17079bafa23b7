"""Closed digital curves of the kind the polygonal-approximation literature benchmarks on.

Each shape is rasterized on a small pixel grid and its outline traced as an 8-connected
chain (Moore-neighbour tracing), the way the classical test curves (chromosome, leaf,
semicircles, infinity; 45 to 120 points) are made. The shapes have sharp corners, thin
parts one pixel wide (the outline then visits a pixel twice: repeated points), a pinch
between two lobes and a spiral arm. Grid sizes are chosen so that the outline has about
the requested number of points.

Usage as a script prints the shapes and their point counts:
``python bench/digital_curves.py``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

Shape = Callable[[np.ndarray, np.ndarray, float], np.ndarray]

# Moore neighbourhood in (row, col), clockwise on screen (rows grow downwards), from west.
_DIRS = ((0, -1), (-1, -1), (-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1))


def _disc(u: np.ndarray, v: np.ndarray, cu: float, cv: float, r: float) -> np.ndarray:
    return (u - cu) ** 2 + (v - cv) ** 2 <= r * r


def _row(v: np.ndarray, px: float) -> np.ndarray:
    """The single pixel row at or just above v = 0."""
    return (v >= -1e-9) & (v < px - 1e-9)


def _leaf(u: np.ndarray, v: np.ndarray, px: float) -> np.ndarray:
    """A lens (two sharp tips) with a one-pixel stem at one tip."""
    lens = _disc(u, v, 0.0, 0.5, 0.95) & _disc(u, v, 0.0, -0.5, 0.95)
    stem = _row(v, px) & (u >= -1.0) & (u <= -0.7)
    return lens | stem


def _chromosome(u: np.ndarray, v: np.ndarray, px: float) -> np.ndarray:
    """Two bent lobes joined at a waist."""
    out = np.zeros(u.shape, dtype=bool)
    for cu, ang in ((-0.42, 0.5), (0.42, -0.5)):
        c, s = np.cos(ang), np.sin(ang)
        a = (u - cu) * c + v * s
        b = -(u - cu) * s + v * c
        out |= (a / 0.55) ** 2 + (b / 0.26) ** 2 <= 1.0
    return out


def _semicircles(u: np.ndarray, v: np.ndarray, px: float) -> np.ndarray:
    """A half disc with a half-disc notch: four sharp corners."""
    return _disc(u, v, 0.0, -0.45, 0.95) & (v >= -0.45) & ~_disc(u, v, 0.0, -0.45, 0.4)


def _eight(u: np.ndarray, v: np.ndarray, px: float) -> np.ndarray:
    """Two lobes joined by a one-pixel bridge (the 'infinity' curve)."""
    lobes = _disc(u, v, -0.5, 0.0, 0.46) | _disc(u, v, 0.5, 0.0, 0.46)
    bridge = _row(v, px) & (np.abs(u) <= 0.15)
    return lobes | bridge


def _star(u: np.ndarray, v: np.ndarray, px: float) -> np.ndarray:
    """Five thin spikes around a core: sharp corners and thin parts."""
    out = _disc(u, v, 0.0, 0.0, 0.32)
    for k in range(5):
        a = np.pi / 2 + 2 * np.pi * k / 5
        apex = np.array([np.cos(a), np.sin(a)])
        b1 = 0.3 * np.array([np.cos(a - 0.45), np.sin(a - 0.45)])
        b2 = 0.3 * np.array([np.cos(a + 0.45), np.sin(a + 0.45)])
        inside = np.ones(u.shape, dtype=bool)
        for p, q in ((b1, apex), (apex, b2), (b2, b1)):
            inside &= (q[0] - p[0]) * (v - p[1]) - (q[1] - p[1]) * (u - p[0]) >= 0
        out |= inside
    return out


def _comb(u: np.ndarray, v: np.ndarray, px: float) -> np.ndarray:
    """A bar with teeth, two of them one pixel wide: right angles and repeated pixels."""
    out = (np.abs(u) <= 0.9) & (v >= -0.9) & (v <= -0.45)
    for cu, half, top in ((-0.75, 0.12, 0.8), (-0.3, 0.5 * px, 0.6), (0.2, 0.15, 0.3)):
        out |= (np.abs(u - cu) <= half) & (v <= top) & (v >= -0.5)
    out |= (np.abs(u - 0.7) <= 0.5 * px) & (v <= 0.85) & (v >= -0.5)
    return out


def _spiral(u: np.ndarray, v: np.ndarray, px: float) -> np.ndarray:
    """A band along an Archimedean spiral (1.6 turns), about two pixels wide."""
    t = np.linspace(0.0, 3.2 * np.pi, 400)
    r = 0.12 + 0.8 * t / t[-1]
    sx, sy = r * np.cos(t), r * np.sin(t)
    d2 = (u.reshape(-1, 1) - sx) ** 2 + (v.reshape(-1, 1) - sy) ** 2
    return (d2.min(axis=1) <= (1.1 * px) ** 2).reshape(u.shape)


def _blob(u: np.ndarray, v: np.ndarray, px: float) -> np.ndarray:
    """A smooth wavy outline (no corners), for contrast."""
    a = np.arctan2(v, u)
    return np.hypot(u, v) <= 0.8 + 0.15 * np.sin(3 * a)


SHAPES: dict[str, Shape] = {
    "leaf": _leaf,
    "chromosome": _chromosome,
    "semicircles": _semicircles,
    "eight": _eight,
    "star": _star,
    "comb": _comb,
    "spiral": _spiral,
    "blob": _blob,
}


def rasterize(shape: Shape, size: int) -> np.ndarray:
    """Pixel mask ``(size + 2, size + 2)`` of ``shape`` on ``[-1, 1]^2``, with an empty border."""
    c = (size - 1) / 2
    px = 2.0 / size
    rows, cols = np.mgrid[0:size, 0:size]
    u = (cols - c) * px
    v = (c - rows) * px
    mask = np.zeros((size + 2, size + 2), dtype=bool)
    mask[1:-1, 1:-1] = shape(u, v, px)
    return mask


def trace(mask: np.ndarray) -> np.ndarray:
    """Outer outline of the first (top-left) component of ``mask``, 8-connected, closed.

    Moore-neighbour tracing: from the current pixel, the neighbours are searched clockwise
    starting after the background pixel we came from; the first foreground one is next. It
    stops when it is about to leave the start pixel the same way as the first time. One-
    pixel-wide parts are walked along both sides, so their pixels appear twice.

    Returns:
        Points ``(n, 2)`` as (x, y) = (column, -row) [pixels], clockwise, not repeating the
        first point at the end.
    """
    rows, cols = np.nonzero(mask)
    start = (int(rows[0]), int(cols[0]))
    cur, back = start, 0  # we "came from" the west, which is background
    out = [start]
    for _ in range(8 * mask.size):
        for k in range(1, 9):
            d = (back + k) % 8
            nb = (cur[0] + _DIRS[d][0], cur[1] + _DIRS[d][1])
            if mask[nb]:
                break
        else:  # a single pixel
            break
        pd = (back + k - 1) % 8
        prev = (cur[0] + _DIRS[pd][0] - nb[0], cur[1] + _DIRS[pd][1] - nb[1])
        if cur == start and len(out) > 1 and nb == out[1]:
            out.pop()  # the start again
            break
        back = _DIRS.index(prev)
        cur = nb
        out.append(cur)
    rc = np.asarray(out, dtype=float)
    return np.c_[rc[:, 1], -rc[:, 0]]


def digital_curve(name: str, target_n: int) -> np.ndarray:
    """The outline of shape ``name`` whose point count is closest to ``target_n``.

    Args:
        name: One of :data:`SHAPES`.
        target_n: Wanted number of outline points.

    Returns:
        Points ``(n, 2)`` [pixels], an 8-connected closed chain.
    """
    best: np.ndarray | None = None
    for size in range(8, 80):
        P = trace(rasterize(SHAPES[name], size))
        if best is None or abs(len(P) - target_n) < abs(len(best) - target_n):
            best = P
        if len(P) > 1.3 * target_n:
            break
    assert best is not None
    return best


def benchmark_curves(targets: tuple[int, ...] = (55, 110)) -> list[tuple[str, np.ndarray]]:
    """Every shape at every target size: ``[(label, points), ...]``."""
    curves = [digital_curve(name, t) for name in SHAPES for t in targets]
    names = [name for name in SHAPES for _ in targets]
    return [(f"{name}-{len(P)}", P) for name, P in zip(names, curves, strict=True)]


def main() -> None:
    for label, P in benchmark_curves():
        steps = np.abs(np.diff(np.vstack([P, P[:1]]), axis=0)).max(axis=1)
        _, counts = np.unique(P, axis=0, return_counts=True)
        print(
            f"{label:16} n={len(P):4d}  8-connected={bool(np.all(steps == 1))}  "
            f"repeated pixels={int((counts > 1).sum())}"
        )


if __name__ == "__main__":
    main()
