"""The portable cosine and sine (regrasp_pin.model.trig).

Checked against the C library's double-precision cos/sin (math.cos, math.sin: within
a few 1e-16 in absolute terms, as fdlibm's kernels are), at the exact values of the
quadrants' ends, and the numpy and scalar versions against each other bit for bit
(the property the IK's two backends rely on).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from regrasp_pin.model.trig import cos_sin, cos_sin_scalar


@pytest.fixture(scope="module")
def angles():
    rng = np.random.default_rng(7)
    quarter = np.arange(-16, 17) * (math.pi / 4)  # every octant's boundary
    return np.concatenate(
        [
            rng.uniform(-4.0, 4.0, 20_000),  # joint angles (limits +- an extension)
            rng.uniform(-1e5, 1e5, 2_000),
            quarter,
            np.nextafter(quarter, np.inf),
            np.nextafter(quarter, -np.inf),
            [0.0, -0.0, 1e-300, -1e-300, 1e-8],
        ]
    )


def test_close_to_the_c_librarys(angles):
    c, s = cos_sin(angles)
    want_c = np.array([math.cos(x) for x in angles])
    want_s = np.array([math.sin(x) for x in angles])
    assert np.max(np.abs(c - want_c)) <= 4e-16
    assert np.max(np.abs(s - want_s)) <= 4e-16
    # on the unit circle within rounding
    assert np.max(np.abs(c * c + s * s - 1.0)) <= 1e-15


def test_exact_where_the_c_librarys_is():
    c, s = cos_sin(np.array([0.0, -0.0]))
    assert c.tolist() == [1.0, 1.0] and s.tolist() == [0.0, 0.0]
    tiny = np.array([1e-300, -1e-200])
    assert np.array_equal(cos_sin(tiny)[1], tiny)  # sin x = x below the polynomial's reach


def test_the_numpy_and_scalar_versions_give_the_same_bits(angles):
    c, s = cos_sin(angles)
    one = np.array([cos_sin_scalar(float(x)) for x in angles[::7]])
    assert np.array_equal(one[:, 0], c[::7]) and np.array_equal(one[:, 1], s[::7])


def test_shapes_and_non_finite_input():
    theta = np.linspace(-3.0, 3.0, 24).reshape(2, 3, 4)
    c, s = cos_sin(theta)
    assert c.shape == s.shape == theta.shape and c.dtype == s.dtype == np.float64
    assert np.array_equal(c[1, 2], cos_sin(theta[1, 2])[0])  # element-wise
    with np.errstate(invalid="ignore"):
        c, s = cos_sin(np.array([np.nan, np.inf, -np.inf]))
    assert np.isnan(c).all() and np.isnan(s).all()
