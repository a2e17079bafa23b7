"""The compiled capsule loop (regrasp_pin.model.capsules_numba) against numpy's batches.

The loop is plain Python that numba compiles unchanged; it performs numpy's operations
in numpy's order, so both paths must give the same bounds to the bit, capped or not,
with the second geometries at their own rows or not. Without numba the plain Python
runs through the backend switch (a few hundred rows); with numba the compiled loop is
checked on more.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import random_q

from regrasp_pin import Hand
from regrasp_pin.model import capsules_numba, ik
from regrasp_pin.model.distances import capsule_gaps


@pytest.fixture(scope="module")
def allegro():
    return Hand.allegro()


@pytest.fixture(scope="module")
def five():
    return Hand.five_finger()


def _both(hand, q, cap, q_b=None, rows_b=None):
    """Every finger against the others, on numpy and on the 'numba' backend."""
    names = list(hand.fingers)
    out = {}
    for name in ("numpy", "numba"):
        ik.set_ik_backend(name)
        out[name] = [
            capsule_gaps(
                hand,
                list(hand.fingers[a].geometry_ids),
                [list(hand.fingers[b].geometry_ids) for b in names if b != a],
                q,
                cap_m=cap,
                q_b=q_b,
                rows_b=rows_b,
            )
            for a in names
        ]
    return out["numpy"], out["numba"]


def _check_same_bits(hand, n, seed):
    q = random_q(hand, n, seed)
    distinct = random_q(hand, 5, seed + 1)
    rows = np.random.default_rng(seed + 2).integers(0, 5, n)
    near = far = 0
    for cap in (np.inf, 0.004, 0.02):
        for kwargs in ({}, {"q_b": distinct, "rows_b": rows}):
            ref, got = _both(hand, q, cap, **kwargs)
            for r, g in zip(ref, got, strict=True):
                assert r.tobytes() == g.tobytes(), (cap, kwargs.keys())
                near += int((r < min(cap, 0.02)).sum())
                far += int((r == cap).sum())
    assert near > 0 and far > 0  # both sides of the caps occur


def test_uncompiled_loop_gives_numpys_bits(allegro, five, backend, monkeypatch):
    monkeypatch.setattr(ik.ik_numba, "available", lambda: True)
    monkeypatch.setattr(capsules_numba, "gaps", capsules_numba.gaps_python)
    _check_same_bits(allegro, 60, 3)
    _check_same_bits(five, 60, 5)


def test_compiled_loop_gives_numpys_bits(allegro, five, backend):
    pytest.importorskip("numba")
    assert capsules_numba.available()
    _check_same_bits(allegro, 2000, 7)
    _check_same_bits(five, 2000, 9)


def test_compiled_loop_without_numba_says_how_to_install(monkeypatch):
    monkeypatch.setattr(capsules_numba, "_compile", lambda: None)
    assert not capsules_numba.available()
    with pytest.raises(ImportError, match=r"regrasp-pin\[fast\]"):
        capsules_numba.gaps(*([None] * 11), 0.0)
