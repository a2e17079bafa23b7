"""Shared test helpers: ``assert_close`` with an explicit tolerance, random hand
configurations, the IK backend restored after a test, a scenario's initial grasp held
without regrasping, and where the third-party Shadow Hand is."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from regrasp_pin.grasp.contact import ContactModel
from regrasp_pin.model import ik


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


def random_q(hand, n, seed, names=None):
    """``(n, nq)`` seeded hand configurations: the fingers ``names`` (default all, in
    the hand's order) uniform within their joint limits, the rest neutral."""
    rng = np.random.default_rng(seed)
    q = np.tile(hand.neutral(), (n, 1))
    for name in hand.fingers if names is None else names:
        f = hand.fingers[name]
        q[:, f.q_indices] = rng.uniform(f.lower, f.upper, (n, f.k))
    return q


@pytest.fixture
def backend():
    """Restore the IK backend that was in use after the test."""
    previous = ik.ik_backend()
    yield
    ik.set_ik_backend(previous)


def held_grasp(scen):
    """Every finger of ``scen`` holding its initial-grasp contact from t=0 over the
    whole motion (no regrasp), on a 10 ms grid.

    Returns:
        ``(grid, base_q, holding)``: the times [s], the hand configuration of the idle
        fingers, and finger -> :class:`~regrasp_pin.grasp.holding.Holding`.
    """
    from regrasp_pin.grasp.holding import rest_configuration, start_holding

    hand, p = scen.hand, scen.params
    grid = np.round(np.arange(0.0, scen.motion.t_end + 1e-9, 0.01), 9)
    idle = [n for n in hand.finger_names if n not in p.fingers]
    base = rest_configuration(hand, scen.obj, scen.motion, idle)
    holding = {
        n: start_holding(
            hand,
            scen.obj,
            scen.motion,
            grid,
            n,
            scen.grasp.points_object[n],
            scen.grasp.normals_object[n],
            scen.grasp.q[n],
            0.0,
            p.contact,
        )
        for n in p.fingers
    }
    return grid, base, holding


def face_with_normal(obj, normal) -> int:
    """Id of the face of ``obj`` whose outward normal is closest to ``normal``."""
    return int(np.argmax(obj.normals @ np.asarray(normal, dtype=float)))


#: The Shadow Hand's hand file; its URDF lives outside the repository (../shared/hands).
#: Every finger's pad cone at 60 deg: the contact model that the scenarios of some
#: planner tests were found with (before the bundled fingers' own cone became their tip
#: sphere's front hemisphere, 90 deg); with it each still shows its mechanism (a
#: neighbour making room, a faster regrasp, holds that end together, ...).
CONE_60 = ContactModel(cone_deg=60.0)

SHADOW_HAND_FILE = Path(__file__).resolve().parents[1] / "examples" / "hands" / "shadow_hand.json"


def shadow_urdf() -> Path:
    """The Shadow Hand URDF named by :data:`SHADOW_HAND_FILE`; skips the test (saying
    where it looked) when the third-party hands folder is not on this machine."""
    import pytest

    rel = json.loads(SHADOW_HAND_FILE.read_text())["urdf"]
    urdf = (SHADOW_HAND_FILE.parent / rel).resolve()
    if not urdf.is_file():
        pytest.skip(f"third-party hand models absent: no Shadow Hand URDF at {urdf}")
    return urdf


def staircase(rng: np.random.Generator, runs: int) -> np.ndarray:
    """A lattice path of ``runs`` straight runs of 4-14 unit steps, each turning 90 deg."""
    pts, d = [np.zeros(2)], np.array([1.0, 0.0])
    for _ in range(runs):
        for _ in range(int(rng.integers(4, 15))):
            pts.append(pts[-1] + d)
        d = np.array([-d[1], d[0]]) if rng.random() < 0.5 else np.array([d[1], -d[0]])
    return np.array(pts)


def placed(P: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``P`` (n, 2) scaled to 4 mm steps and placed by a random rotation and a shift of up
    to 1 m in 3-D: the same deviations in exact arithmetic, other last bits in floats."""
    R = Rotation.random(random_state=int(rng.integers(2**31))).as_matrix()
    return (0.004 * np.c_[P, np.zeros(len(P))]) @ R.T + rng.uniform(-1.0, 1.0, 3)
