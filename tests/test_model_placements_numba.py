"""The compiled placements (regrasp_pin.model.placements_numba) against numpy's batches.

The loop is plain Python that numba compiles unchanged; it performs numpy's operations
in numpy's order on the cosines and sines numpy computed, so both paths must place
every collision geometry, capsule end and fingertip frame at the same bits. Without numba the
plain Python runs uncompiled on a few dozen configurations; with numba the compiled
loop is checked on more, and through the distance bounds that read it.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import random_q

from regrasp_pin import Hand
from regrasp_pin.model import bounds_numba, distances, ik, kinematics, placements_numba
from regrasp_pin.model.objects import Box


@pytest.fixture(scope="module", params=["allegro", "five_finger"])
def hand(request):
    return getattr(Hand, request.param)()


def _frames(hand):
    """Every finger's collision geometries (repeats and links of several fingers in one
    call, as the verification asks) and their capsules' ends; then, on every finger's
    tip chain, frames whose constants have no term, unit terms and a permutation (the
    sums' special cases)."""
    geoms = [distances._geometry(hand, g) for f in hand.fingers.values() for g in f.geometry_ids]
    geoms = geoms + geoms[:3]  # a chain asked twice
    chains = [g.chain for g in geoms]
    R_off = [g.R_frame_geom for g in geoms]
    p_off = [g.p_frame_geom for g in geoms]
    ends = [g.p_frame_geom + g.R_frame_geom @ g.seg_b for g in geoms]
    swap = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [-1.0, 0.0, 0.0]])
    for f in hand.fingers.values():
        for R, p in ((np.eye(3), np.zeros(3)), (swap, np.array([0.0, 0.0, 1.0]))):
            chains.append(f.chain)
            R_off.append(R)
            p_off.append(p)
            ends.append(p)
    return chains, np.array(R_off), np.array(p_off), np.array(ends)


def _check_same_bits(hand, n, seed):
    chains, R_off, p_off, ends = _frames(hand)
    q = random_q(hand, n, seed)
    R0, p0 = kinematics.attached_placements(chains, R_off, p_off, q)
    R1, p1 = kinematics.attached_placements(chains, R_off, p_off, q, compiled=True)
    assert R0.tobytes() == R1.tobytes()
    assert p0.tobytes() == p1.tobytes()
    s0 = kinematics.attached_points_soa(chains, ends, q)
    s1 = kinematics.attached_points_soa(chains, ends, q, compiled=True)
    assert s0.tobytes() == s1.tobytes()
    for f in hand.fingers.values():  # the tip frames (FingerChain.poses)
        qf = q[:, f.q_indices]
        R0, p0 = f.chain.poses(qf)
        R1, p1 = f.chain.poses(qf, compiled=True)
        assert R0.tobytes() == R1.tobytes() and p0.tobytes() == p1.tobytes(), f.name
    if n > 1:  # not one placement repeated: the configurations differ
        assert not np.allclose(p0[0], p0[-1])


def test_uncompiled_loop_gives_numpys_bits(hand, monkeypatch):
    monkeypatch.setattr(placements_numba, "placements", placements_numba.placements_python)
    _check_same_bits(hand, 25, 3)
    _check_same_bits(hand, 1, 4)


def test_compiled_loop_gives_numpys_bits(hand):
    pytest.importorskip("numba")
    assert placements_numba.available()
    _check_same_bits(hand, 2000, 7)
    _check_same_bits(hand, 1, 8)


def test_the_verifications_bounds_read_the_same_placements_on_both_backends(hand, backend):
    """The bounds of one finger's dense motion against the object and the other fingers
    (:class:`~regrasp_pin.model.distances.PairDistances`) read the placements: the same
    bits on the numba backend when numpy computes the bounds on both (the compiled
    bounds agree to rounding only: tests/test_model_bounds_numba.py)."""
    pytest.importorskip("numba")
    box = Box((0.05, 0.05, 0.05))
    f = next(iter(hand.fingers.values()))
    q = random_q(hand, 300, 11)
    T = np.tile(np.eye(4), (300, 1, 1))
    T[:, :3, 3] = [0.07, 0.0, 0.04]
    calls = []
    compiled = placements_numba.placements

    def counted(*args):
        calls.append(args[0].shape)
        compiled(*args)

    out = {}
    for name in ("numpy", "numba"):
        ik.set_ik_backend(name)
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(placements_numba, "placements", counted)
            mp.setattr(bounds_numba, "wanted", lambda backend: False)
            pd = distances.PairDistances(hand, box, f, q, T, np.full(300, -1e-4), 0.002, 0.0005)
        out[name] = (pd.lb.tobytes(), pd._R.tobytes(), pd._p.tobytes())
        assert bool(calls) == (name == "numba")  # the numba backend places by the loop
    assert out["numpy"] == out["numba"]


def test_compiled_loop_without_numba_says_how_to_install(monkeypatch):
    monkeypatch.setattr(placements_numba, "_compile", lambda: None)
    assert not placements_numba.available()
    with pytest.raises(ImportError, match=r"regrasp-pin\[fast\]"):
        placements_numba.placements()
