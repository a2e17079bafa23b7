"""Input checks shared by the public API (regrasp_pin._validate): each names the
argument and what it accepts."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from regrasp_pin._validate import (
    as_array,
    as_batch,
    choice,
    frozen,
    known_fields,
    positive,
    positive_int,
)
from regrasp_pin.exceptions import InputError, UnknownNameError


def test_as_array_checks_shape_and_finiteness():
    out = as_array([[1, 2, 3]], "p", (None, 3))
    assert out.dtype == np.float64 and out.shape == (1, 3)
    with pytest.raises(InputError, match="has shape \\(2,\\)") as info:
        as_array([1, 2], "p", (3,))
    assert info.value.argument == "p" and info.value.expected == "shape (3,)"
    with pytest.raises(InputError, match="NaN or inf"):
        as_array([0.0, np.nan, 1.0], "p", (3,))
    assert np.isnan(as_array([0.0, np.nan, 1.0], "p", (3,), finite=False)[1])
    with pytest.raises(InputError, match="not a numeric array"):
        as_array(["a", "b", "c"], "p", (3,))


def test_as_batch_accepts_one_or_many_and_reports_the_given_shape():
    one, single = as_batch([1.0, 2.0, 3.0], "x", 3)
    many, several = as_batch(np.zeros((4, 3)), "x", 3)
    assert one.shape == (1, 3) and single and many.shape == (4, 3) and not several
    with pytest.raises(InputError, match="has shape \\(4,\\)"):
        as_batch([1.0, 2.0, 3.0, 4.0], "x", 3)


@pytest.mark.parametrize("bad", [0.0, -1.0, np.inf, np.nan, "a", None])
def test_positive_refuses_what_is_not_a_finite_positive_number(bad):
    with pytest.raises(InputError) as info:
        positive(bad, "step")
    assert info.value.argument == "step"


def test_positive_may_allow_zero():
    assert positive(0, "gap", allow_zero=True) == 0.0
    assert positive(np.float32(0.5), "gap") == 0.5


@pytest.mark.parametrize("bad", [True, 2.0, "3", 0])
def test_positive_int_refuses_bools_floats_and_small_values(bad):
    with pytest.raises(InputError, match="integer >= 1"):
        positive_int(bad, "m")


def test_positive_int_accepts_numpy_integers():
    assert positive_int(np.int64(4), "m", minimum=3) == 4


def test_choice_lists_the_valid_names():
    assert choice("box", "kind", ("box", "prism")) == "box"
    with pytest.raises(UnknownNameError, match="prism"):
        choice("sphere", "kind", ("box", "prism"))


def test_frozen_is_contiguous_and_read_only():
    a = np.arange(12.0).reshape(3, 4)[:, ::2]
    f = frozen(a)
    assert f.flags.c_contiguous and not f.flags.writeable
    np.testing.assert_array_equal(f, a)
    with pytest.raises(ValueError):
        f[0, 0] = 1.0


@dataclasses.dataclass
class _Spec:
    kind: str
    size: float = 1.0


def test_known_fields_refuses_unknown_and_missing_fields():
    known_fields({"kind": "box"}, _Spec, "spec")
    with pytest.raises(InputError, match="unknown field\\(s\\) \\['colour'\\]"):
        known_fields({"kind": "box", "colour": "red"}, _Spec, "spec")
    with pytest.raises(InputError) as info:
        known_fields({"size": 2.0}, _Spec, "spec")
    assert info.value.argument == "spec" and "kind" in str(info.value)
    with pytest.raises(InputError, match="a dict"):
        known_fields([("kind", "box")], _Spec, "spec")
