"""The compiled pad cosines and fingertip overshoot (regrasp_pin.model.tip_numba)
against numpy's: the same bits, and both the formulas they stand for."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import random_q

from regrasp_pin import Hand
from regrasp_pin.grasp import contact
from regrasp_pin.model import ik, tip_numba
from regrasp_pin.model.support import support


@pytest.fixture(scope="module", params=["five_finger", "allegro"])
def hand(request):
    return Hand.five_finger() if request.param == "five_finger" else Hand.allegro()


def _cases(hand, n, seed):
    """Per finger: configurations ``(n, k)`` and unit normals ``(n, 3)`` (palm frame)."""
    rng = np.random.default_rng(seed)
    q = random_q(hand, n, seed)
    for f in hand.fingers.values():
        normals = rng.normal(size=(n, 3))
        yield f, q[:, f.q_indices], normals / np.linalg.norm(normals, axis=1, keepdims=True)


def _both(f, qf, normals, backend):
    ik.set_ik_backend(backend)
    return contact.pad_cosines_and_overshoot(f, qf, normals)


def test_numpy_gives_the_formulas(hand, backend):
    """numpy's written-out sums are the pad's cosine ``-(R a) . n`` and the overshoot
    ``max_g (u . c_g + h_g(R_g^T u)) - r``, ``u = -R^T n``, to rounding."""
    for f, qf, normals in _cases(hand, 200, 3):
        cos, over = _both(f, qf, normals, "numpy")
        R, _ = f.chain.poses(qf)
        assert np.allclose(cos, -np.einsum("nij,j,ni->n", R, f.pad_axis_tip, normals), atol=1e-15)
        reach = f.tip_reach
        if reach is None or reach.params.shape[0] == 0:
            assert np.all(over == -np.inf)
            continue
        u = -np.einsum("nji,nj->ni", R, normals)
        local = np.einsum("ni,gij->ngj", u, reach.rotations)
        expected = (u @ reach.centres.T + support(local, reach.params[None])).max(axis=1)
        assert np.allclose(over, expected - reach.radius, atol=1e-15)
        assert np.ptp(over) > 1e-3  # the turn matters


def test_uncompiled_loop_gives_numpys_bits(hand, backend, monkeypatch):
    monkeypatch.setattr(tip_numba, "wanted", lambda name: name == "numba")
    monkeypatch.setattr(tip_numba, "pad_overshoot", tip_numba.pad_overshoot_python)
    monkeypatch.setattr(ik.ik_numba, "available", lambda: True)
    for f, qf, normals in _cases(hand, 40, 5):
        ref = _both(f, qf, normals, "numpy")
        got = _both(f, qf, normals, "numba")
        assert ref[0].tobytes() == got[0].tobytes() and ref[1].tobytes() == got[1].tobytes()


def test_compiled_loop_gives_numpys_bits(hand, backend):
    pytest.importorskip("numba")
    assert tip_numba.available()
    for f, qf, normals in _cases(hand, 3000, 7):
        ref = _both(f, qf, normals, "numpy")
        got = _both(f, qf, normals, "numba")
        assert ref[0].tobytes() == got[0].tobytes(), f.name
        assert ref[1].tobytes() == got[1].tobytes(), f.name
