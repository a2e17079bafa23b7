"""Shared test helpers: one ``assert_close`` with an explicit tolerance."""

from __future__ import annotations

import numpy as np


def assert_close(actual, expected, *, atol: float, rtol: float = 0.0, what: str = "") -> None:
    """Assert ``|actual - expected| <= atol + rtol * |expected|`` elementwise, with context."""
    a = np.asarray(actual, dtype=float)
    e = np.asarray(expected, dtype=float)
    assert a.shape == e.shape or e.ndim == 0, f"{what}: shape {a.shape} != {e.shape}"
    err = np.abs(a - e)
    bound = atol + rtol * np.abs(e)
    worst = float(np.max(err - bound)) if err.size else 0.0
    assert np.all(err <= bound), (
        f"{what}: max error {float(np.max(err)):.3e} exceeds tolerance "
        f"(atol={atol:g}, rtol={rtol:g}; worst excess {worst:.3e})"
    )
