"""The scalar segment helper of the compiled loops (regrasp_pin.model.segments_numba)
against numpy's batch, and the namespace in which numba_jit.compile_together compiles
helpers from another module.

The helper makes numpy's operations in numpy's order, so its offsets must equal
:func:`~regrasp_pin.model.distances._segment_distance_soa`'s to the bit, for general
pairs and for the degenerate ones its branches handle (parallel segments, a segment that
is a point, both points).
"""

from __future__ import annotations

import types

import numpy as np
import pytest

from regrasp_pin.model import segments_numba
from regrasp_pin.model.distances import _segment_distance_soa
from regrasp_pin.model.numba_jit import compile_together


def _pairs(rng: np.random.Generator, n: int) -> tuple[np.ndarray, ...]:
    """Segment ends ``(3, n)``: random pairs, then parallel ones, points against
    segments, segments against points, and point pairs."""
    a1, b1, a2, b2 = (rng.normal(0.0, 0.02, (3, n)) for _ in range(4))
    k = n // 5
    b2[:, k : 2 * k] = a2[:, k : 2 * k] + 0.7 * (b1[:, k : 2 * k] - a1[:, k : 2 * k])
    b1[:, 2 * k : 3 * k] = a1[:, 2 * k : 3 * k]
    b2[:, 3 * k : 4 * k] = a2[:, 3 * k : 4 * k]
    b1[:, 4 * k :] = a1[:, 4 * k :]
    b2[:, 4 * k :] = a2[:, 4 * k :]
    return a1, b1, a2, b2


def _offsets(fn, a1, b1, a2, b2) -> np.ndarray:
    d1, d2, r = b1 - a1, b2 - a2, a1 - a2
    return np.array([fn(*d1[:, i], *d2[:, i], *r[:, i]) for i in range(a1.shape[1])]).T


def test_segment_offset_is_numpys_batch_to_the_bit():
    a1, b1, a2, b2 = _pairs(np.random.default_rng(7), 500)
    want_d, want = _segment_distance_soa(a1, b1, a2, b2)
    got = _offsets(segments_numba.segment_offset, a1, b1, a2, b2)
    assert np.array_equal(got, want)
    assert np.array_equal(np.sqrt((got * got).sum(axis=0)), want_d)
    # the nearest points lie on the segments: no point of a sampled pair is nearer
    s = np.linspace(0.0, 1.0, 41)
    p = a1[:, None, :] + s[None, :, None] * (b1 - a1)[:, None, :]
    q = a2[:, None, :] + s[None, :, None] * (b2 - a2)[:, None, :]
    sampled = np.linalg.norm(p[:, :, None, :] - q[:, None, :, :], axis=0).min(axis=(0, 1))
    assert np.all(want_d <= sampled + 1e-15)


NEEDS_NUMBA = "compile_together needs numba (pip install regrasp-pin[fast])"


def _offset_x(x):
    """A kernel: segment 1 from the origin along x, segment 2 the point (x, 1, 0); the
    offset's x is the point's clipped foot minus x. ``segment_offset`` is whatever the
    globals it is compiled in bind."""
    return segment_offset(1.0, 0.0, 0.0, 0.0, 0.0, 0.0, -x, -1.0, 0.0)[0]  # noqa: F821


def _kernel(**glb):
    """:func:`_offset_x` in a module of its own whose globals are ``glb``."""
    return types.FunctionType(_offset_x.__code__, {"__name__": __name__, **glb}, "kernel")


def test_compile_together_brings_a_helpers_globals():
    pytest.importorskip("numba", reason=NEEDS_NUMBA)
    # the kernel's module has neither clip01 nor EPS: they come with the helper
    kernel = _kernel(segment_offset=segments_numba.segment_offset)
    compiled = compile_together((segments_numba.clip01, segments_numba.segment_offset), (kernel,))
    assert compiled is not None
    for x, want in ((0.5, 0.0), (-0.25, 0.25), (1.5, -0.5)):
        assert compiled["kernel"](x) == kernel(x) == want


def test_compile_together_refuses_a_name_bound_to_something_else():
    pytest.importorskip("numba", reason=NEEDS_NUMBA)
    kernel = _kernel(segment_offset=segments_numba.segment_offset, EPS=1e-3)
    with pytest.raises(ValueError, match="'EPS'"):
        compile_together((segments_numba.clip01, segments_numba.segment_offset), (kernel,))
