"""The hands that a run's scenarios use, and what they cache, built once per worker.

Each scenario runs in a child process forked from a forkserver (:mod:`.isolate`). A cold
child builds its hand (URDF, collision model), the per-finger tables that the
manifolds cache (the workspace cover of the extended joint box, the pad directions)
and loads the compiled kernels again: 0.8-1.0 s of every scenario on the 2-core
machine, as long as a whole regrasp search of a short scenario. The forkserver imports
this module; it warms the hands named in :data:`HANDS_ENV` (a JSON list, set by
:func:`~.isolate.warm_up`) by mapping a few points of a small box into every finger's
joint space (:func:`~regrasp_pin.grasp.manifold.build_manifold`) and by bounding the
fingers' gaps (:func:`~regrasp_pin.model.distances.capsule_gaps`), and every child
inherits the result (fork: copy on write). The caches hand back what they would have
computed: a warmed child's results are the same, bit for bit.
"""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Iterable

import numpy as np

from ..grasp.manifold import build_manifold
from ..model.distances import capsule_gaps
from ..model.motion import ObjectMotion
from ..model.objects import Box
from .build import suite_hand

__all__ = ["HANDS_ENV", "warm_hands"]

#: The environment variable that names the hands the forkserver warms (a JSON list of
#: bundled hand names or hand files).
HANDS_ENV = "REGRASP_PIN_WARM_HANDS"

log = logging.getLogger(__name__)


def warm_hands(names: Iterable[str]) -> None:
    """Build each named hand (:func:`~.build.suite_hand`, once per process) and run, on
    one thread, what fills its caches: a small manifold per finger (two times, a 20 mm box
    at the finger's mid-range tip) and the fingers' capsule gaps."""
    sample = Box((0.02, 0.02, 0.02)).sample_surface(0.005)
    times = np.array([0.0, 0.1])
    for name in names:
        hand = suite_hand(name)
        for finger in hand.fingers.values():
            T = np.eye(4)
            T[:3, 3] = finger.fk(finger.q_mid[None])[0] - [0.0, 0.0, 0.01 + finger.tip_radius]
            motion = ObjectMotion.from_poses(times, np.stack([T, T]))
            build_manifold(finger, sample, motion, times)
        names_f = list(hand.fingers)
        q = hand.neutral()[None]
        for a in names_f:
            others = [list(hand.fingers[b].geometry_ids) for b in names_f if b != a]
            capsule_gaps(hand, list(hand.fingers[a].geometry_ids), others, q)


def _warm_from_environment() -> None:
    """Warm the hands of :data:`HANDS_ENV`, if set (in the forkserver, at import)."""
    text = os.environ.get(HANDS_ENV)
    if not text:
        return
    try:
        warm_hands(json.loads(text))
    except Exception:  # a scenario then builds its hand itself and reports the error
        log.exception("could not warm the hands %s", text)


_warm_from_environment()
