"""Timing of a regrasp: its time law, and durations from joint velocity limits.

A regrasp follows its path with a progress ``s(tau)`` (its *time law*, ``TIME_LAWS``):

- ``"minimum-jerk"`` (the default): the smoothest, whose peak speed is ``MJ_PEAK =
  1.875`` times the mean;
- ``"cruise"``: speeds up and slows down as a minimum-jerk velocity ramp over the first
  and last ``CRUISE_RAMP`` of the duration and cruises between, so that its peak speed
  is only ``CRUISE_PEAK = 1 / (1 - CRUISE_RAMP)`` (1.43) times the mean: the same move
  in 0.76 of the time within the same velocity limits, at the price of a larger peak
  acceleration (``CRUISE_ACCEL`` = 8.9 against 5.8 times ``|dq| / D^2`` at the same
  duration). Velocity and acceleration are continuous and zero at both ends, as with
  minimum jerk.

A joint that moves ``dq`` [rad] in a duration ``D`` [s] therefore peaks near ``peak *
|dq| / D`` if the path is straight in joint space; a curved path moves further, which
``PATH_FACTOR`` allows for. The duration is *computed* from the limits (time scaling),
and stretched by the measured ratio when the trajectory that was actually solved still
moves a joint too fast.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..exceptions import FailureKind, InputError, PlanningError
from ..model.hand import speed_shares

__all__ = [
    "CRUISE_ACCEL",
    "CRUISE_PEAK",
    "CRUISE_RAMP",
    "MJ_PEAK",
    "PATH_FACTOR",
    "TIME_LAWS",
    "check_joint_speed",
    "checked_time_law",
    "cruise",
    "duration_for_move",
    "durations_for_moves",
    "inverse_minimum_jerk",
    "inverse_progress",
    "joint_paced",
    "minimum_jerk",
    "next_duration",
    "peak_ratio",
    "progress",
    "stretched_duration",
    "velocity_blend",
]

MJ_PEAK = 1.875  # peak / mean speed of the minimum-jerk profile
CRUISE_RAMP = 0.3  # share of the duration over which the cruise law speeds up (and slows)
CRUISE_PEAK = 1.0 / (1.0 - CRUISE_RAMP)  # peak / mean speed of the cruise law
CRUISE_ACCEL = MJ_PEAK * CRUISE_PEAK / CRUISE_RAMP  # its peak acceleration / (|dq| / D^2)
#: the regrasp's time laws (module docstring), the default first
TIME_LAWS = ("minimum-jerk", "cruise")
PATH_FACTOR = 1.5  # joint-space path length / straight joint distance, allowed for
STRETCH_MARGIN = 1.05  # a measured over-speed ratio is stretched by this much more
_TABLE_TAU = np.linspace(0.0, 1.0, 2001)


def minimum_jerk(tau: np.ndarray) -> np.ndarray:
    """Minimum-jerk progress ``10 tau^3 - 15 tau^4 + 6 tau^5`` for ``tau`` in [0, 1]."""
    tau = np.clip(tau, 0.0, 1.0)
    return tau**3 * (10.0 - 15.0 * tau + 6.0 * tau * tau)


def inverse_minimum_jerk(s: np.ndarray) -> np.ndarray:
    """The time fraction ``tau`` at which the progress is ``s`` (both in [0, 1])."""
    return inverse_progress(s, "minimum-jerk")


def cruise(tau: np.ndarray) -> np.ndarray:
    """The cruise law's progress for ``tau`` in [0, 1] (module docstring): over the
    first ``CRUISE_RAMP`` the speed rises from 0 to ``CRUISE_PEAK`` as minimum jerk
    does, whose integral is ``2.5 x^4 - 3 x^5 + x^6`` (x the ramp's own fraction); it
    cruises at that speed; the last ramp mirrors the first."""
    tau = np.clip(np.asarray(tau, float), 0.0, 1.0)
    r = CRUISE_RAMP

    def ramp(t: np.ndarray) -> np.ndarray:
        x = np.clip(t / r, 0.0, 1.0)
        return CRUISE_PEAK * r * x**4 * (2.5 - 3.0 * x + x * x)

    middle = CRUISE_PEAK * (tau - 0.5 * r)
    return np.where(tau < r, ramp(tau), np.where(tau > 1.0 - r, 1.0 - ramp(1.0 - tau), middle))


_LAWS = {"minimum-jerk": (minimum_jerk, MJ_PEAK), "cruise": (cruise, CRUISE_PEAK)}


def checked_time_law(law: str, argument: str = "time_law") -> str:
    """``law`` if it is one of ``TIME_LAWS``; else an InputError naming ``argument``."""
    if not isinstance(law, str) or law not in _LAWS:
        raise InputError(argument, f"{law!r} is not a time law", f"one of {TIME_LAWS}")
    return law


def _law(law: str) -> tuple:
    return _LAWS[checked_time_law(law)]


def progress(tau: np.ndarray, law: str = "minimum-jerk") -> np.ndarray:
    """The progress ``s`` in [0, 1] of the time ``law`` (``TIME_LAWS``) at the time
    fractions ``tau`` in [0, 1]."""
    return _law(law)[0](tau)


def inverse_progress(s: np.ndarray, law: str = "minimum-jerk") -> np.ndarray:
    """The time fraction ``tau`` at which the ``law``'s progress is ``s`` (both in
    [0, 1]; each law rises strictly inside)."""
    return np.interp(s, _law(law)[0](_TABLE_TAU), _TABLE_TAU)


def peak_ratio(law: str = "minimum-jerk") -> float:
    """Peak over mean speed of the time ``law``: ``MJ_PEAK`` or ``CRUISE_PEAK``."""
    return float(_law(law)[1])


def _round_up(duration_s: float | np.ndarray, dt_s: float) -> np.ndarray:
    # a duration is a whole number of steps; 1e-9 keeps 0.4 / 0.01 from becoming 41 steps
    return np.ceil(np.asarray(duration_s, float) / dt_s - 1e-9) * dt_s


def duration_for_move(
    q_from: np.ndarray,
    q_to: np.ndarray,
    velocity_limit: np.ndarray,
    *,
    minimum_s: float,
    dt_s: float,
    path_factor: float = PATH_FACTOR,
    law: str = "minimum-jerk",
) -> float:
    """Shortest regrasp duration [s] that keeps every joint under its velocity limit.

    Args:
        q_from: ``(k,)`` configuration at lift-off [rad].
        q_to: ``(k,)`` configuration at landing [rad].
        velocity_limit: ``(k,)`` joint velocity limits [rad/s].
        minimum_s: The duration is never shorter than this [s].
        dt_s: The duration is a multiple of this step [s].
        path_factor: Joint-space path length over the straight distance: the default
            allows for a regrasp's detour around the object; 1 for a straight
            joint-space move (the time law along the segment).
        law: The time law the move follows (``TIME_LAWS``): its peak speed ratio.
    """
    q_to = np.asarray(q_to, float)
    return float(
        durations_for_moves(
            q_from,
            q_to[None],
            velocity_limit,
            minimum_s=minimum_s,
            dt_s=dt_s,
            path_factor=path_factor,
            law=law,
        )[0]
    )


def durations_for_moves(
    q_from: np.ndarray,
    q_to: np.ndarray,
    velocity_limit: np.ndarray,
    *,
    minimum_s: float,
    dt_s: float,
    path_factor: float = PATH_FACTOR,
    law: str = "minimum-jerk",
) -> np.ndarray:
    """:func:`duration_for_move` [s] from ``q_from`` ``(k,)`` to each row of ``q_to``
    ``(C, k)`` [rad]: ``(C,)``, each a whole number of steps ``dt_s``."""
    dq = np.abs(np.asarray(q_to, float) - np.asarray(q_from, float)[None])
    ratio = np.max(dq / np.asarray(velocity_limit, float)[None], axis=1)
    return _round_up(np.maximum(peak_ratio(law) * path_factor * ratio, minimum_s), dt_s)


def stretched_duration(duration_s: float, speed_ratio: float, *, dt_s: float) -> float:
    """The duration [s] after which a trajectory that reached ``speed_ratio`` times a
    joint's velocity limit stays under it (time scaling: speeds fall as 1 / duration)."""
    return float(_round_up(duration_s * max(speed_ratio, 1.0) * STRETCH_MARGIN, dt_s))


def next_duration(tried: Sequence[tuple[float, float]], *, dt_s: float) -> float | None:
    """The next duration [s] to try after velocity failures, or None if none can pass.

    ``tried`` holds ``(duration [s], peak speed / limit)`` of the failed tries, in order.
    After one, time scaling (:func:`stretched_duration`). A regrasp's path changes with
    its duration (the object turns further during a longer flight, so the joints must
    move further): after two or more, the last two tries are fitted with
    ``ratio = a / D + b`` (time-scaled part ``a``, part ``b`` that does not fall with
    the duration) and the duration that brings the fit to ``1 / STRETCH_MARGIN`` is
    taken when longer than time scaling's; None when the fit says no duration can
    (``b`` at or above it: the speeds would not fall under the limit).
    """
    D1, r1 = tried[-1]
    scaled = stretched_duration(D1, r1, dt_s=dt_s)
    if len(tried) < 2:
        return scaled
    D0, r0 = tried[-2]
    if abs(1.0 / D0 - 1.0 / D1) < 1e-9:
        return scaled
    a = (r0 - r1) / (1.0 / D0 - 1.0 / D1)
    b = r1 - a / D1
    goal = 1.0 / STRETCH_MARGIN
    if a <= 0.0:
        return scaled  # not slower when shorter: no trend to follow
    if b >= goal:
        return None
    return max(scaled, float(_round_up(a / (goal - b), dt_s)))


def check_joint_speed(
    finger: str,
    joint_names: Sequence[str],
    velocity_limit: np.ndarray,
    times: np.ndarray,
    q: np.ndarray,
) -> None:
    """Raise a ``velocity`` PlanningError (the fastest joint, its speed and limit
    [rad/s]) if a joint of ``q`` ``(S, k)`` [rad] moves faster than its limit between
    the samples ``times`` ``(S,)`` [s] (:func:`~regrasp_pin.model.hand.speed_shares`:
    joints without a positive limit are not counted)."""
    vel = np.abs(np.diff(q, axis=0)) / np.diff(times)[:, None]
    ratio = speed_shares(np.diff(q, axis=0), np.diff(times), velocity_limit)
    if (ratio > 1.0).any():
        i, j = (int(v) for v in np.unravel_index(np.argmax(ratio), vel.shape))
        raise PlanningError(
            f"joint {joint_names[j]} would move at {vel[i, j]:.2f} rad/s "
            f"(limit {velocity_limit[j]:.2f})",
            finger=finger,
            time_s=float(times[i]),
            kind=FailureKind.VELOCITY,
            measured=float(vel[i, j]),
            required=float(velocity_limit[j]),
        )


def joint_paced(
    u: np.ndarray, q: np.ndarray, velocity_limit: np.ndarray, progress: np.ndarray
) -> np.ndarray:
    """Path parameters ``(S,)`` that pace a path by its joints instead of its length.

    A path traversed with a time law's progress along its length (``u`` ``(S,)``,
    increasing, at the sample times) moves the joints unevenly: a joint that turns
    through most of its move over a short stretch of the path (near a singularity or a
    joint limit) peaks far above the law's peak ratio (:func:`peak_ratio`) times its
    mean speed. Measured on that trajectory ``q`` ``(S, k)`` [rad], the time each step
    needs at full speed is ``max_j |dq_j| / velocity_limit_j`` [s]; spending the same
    ``progress`` ``(S,)`` (the time law's, from 0 to 1) along that cumulative time
    instead of along the length brings every joint's peak to about the law's peak
    ratio times the path's mean joint-limited pace (time scaling along the path).
    About: ``q`` also holds the joints' motion that follows the moving object, which
    the new pacing does not rescale, so the trajectory solved at the new parameters is
    checked again. Each step counts at least a quarter of its share of the path's mean
    pace by length, so that the tip keeps moving where the joints barely do. The ends
    stay where they are.
    """
    du = np.diff(u)
    dt_full = np.max(np.abs(np.diff(q, axis=0)) / np.asarray(velocity_limit, float), axis=1)
    span = float(u[-1] - u[0])
    floor = 0.25 * float(dt_full.sum()) * du / span if span > 0.0 else np.zeros_like(du)
    paced = np.concatenate([[0.0], np.cumsum(np.maximum(dt_full, floor))])
    if paced[-1] <= 0.0:
        return np.array(u, float)
    out = np.interp(progress * paced[-1], paced, u)
    out[0], out[-1] = u[0], u[-1]
    return out


def velocity_blend(times: np.ndarray, v_from: np.ndarray, v_to: np.ndarray) -> np.ndarray:
    """``(S, k)`` joint offsets [rad] over a move's ``times`` ``(S,)`` [s] that are zero
    at both ends, start at velocity ``v_from`` and end at ``v_to`` ``(k,)`` [rad/s]
    (cubic Hermite velocity bases). Added to a move by a time law, which starts and ends
    at rest, they make the joint velocities continuous with what comes before and after
    (a finger following the moving object)."""
    span = float(times[-1] - times[0])
    u = (times - times[0]) / span
    return span * (np.outer(u * (1.0 - u) ** 2, v_from) + np.outer(u**2 * (u - 1.0), v_to))
