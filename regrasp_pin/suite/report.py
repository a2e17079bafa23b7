"""The plain-text report of a suite's results."""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from numbers import Integral

import numpy as np
from scipy.stats import binomtest, fisher_exact

from ..exceptions import FailureKind, InputError
from ..planning.outcomes import DISTANCE_KINDS
from ..scenarios import HANDS
from .run import ScenarioResult
from .specs import MOTION_KINDS, OBJECT_KINDS

__all__ = [
    "PairedChange",
    "RateDifference",
    "paired_change",
    "rate_difference",
    "rate_interval",
    "result_line",
    "summarize",
    "time_spent",
]

#: Confidence level of the full-plan rate's interval and of the paired comparison
CONFIDENCE = 0.95


def _rate(results: Sequence[ScenarioResult]) -> str:
    if not results:
        return "-"
    k = sum(r.ok for r in results)
    return f"{k}/{len(results)} {k / len(results):4.0%}"


def rate_interval(k: int, n: int, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """The Wilson score interval of a full-plan rate of ``k`` in ``n`` scenarios: the
    rates that the suite's scenarios, a sample of the generator's, leave plausible at
    ``confidence``. One seed's 100 scenarios give about +-10 points at 40 %: two suites
    (two seeds, or one change) differ by more than that only when the rate really
    differs.

    Raises:
        InputError: ``n`` < 1, ``k`` not in ``0..n``, or ``confidence`` not in (0, 1).
    """
    if isinstance(n, bool) or not (isinstance(n, Integral) and n >= 1):
        raise InputError("n", f"is {n!r}", "a whole number >= 1 (scenarios)")
    if isinstance(k, bool) or not (isinstance(k, Integral) and 0 <= k <= n):
        raise InputError("k", f"is {k!r}", f"a whole number in 0..{n} (full plans)")
    if not (isinstance(confidence, float | int) and 0.0 < confidence < 1.0):
        raise InputError("confidence", f"is {confidence!r}", "a number in (0, 1), e.g. 0.95")
    ci = binomtest(int(k), int(n)).proportion_ci(confidence_level=confidence, method="wilson")
    return float(ci.low), float(ci.high)


def _beyond_chance(p_value: float) -> bool:
    """Whether a test's ``p_value`` rejects chance at the report's :data:`CONFIDENCE`."""
    return p_value < 1.0 - CONFIDENCE


@dataclass(frozen=True)
class PairedChange:
    """How the outcomes of the same scenarios changed between two runs.

    Attributes:
        n: Scenarios in both runs.
        won: Full plans now that failed before.
        lost: Failures now that were full plans before.
        p_value: Two-sided exact sign test (McNemar's) of ``won`` against ``lost``: how
            likely a split at least this uneven is when a change wins and loses at
            random (the search reshuffles outcomes: one regrasp landing 10 ms sooner
            changes every later one). 1.0 when nothing changed.
    """

    n: int
    won: int
    lost: int
    p_value: float

    def line(self) -> str:
        """The comparison in plain words, one line."""
        verdict = (
            "more than the noise of the search"
            if _beyond_chance(self.p_value)
            else "within the noise of the search"
        )
        return (
            f"won {self.won}, lost {self.lost} of {self.n} (sign test p={self.p_value:.2g}: "
            f"{verdict})"
        )


def paired_change(
    results: Sequence[ScenarioResult], baseline: Sequence[ScenarioResult]
) -> PairedChange:
    """The full plans won and lost by ``results`` against ``baseline`` over the
    scenarios (by name) in both, and whether the difference exceeds chance
    (:class:`PairedChange`)."""
    old = {r.name: r.ok for r in baseline}
    both = [r for r in results if r.name in old]
    won = sum(r.ok and not old[r.name] for r in both)
    lost = sum(old[r.name] and not r.ok for r in both)
    p = binomtest(won, won + lost, 0.5).pvalue if won + lost else 1.0
    return PairedChange(n=len(both), won=won, lost=lost, p_value=float(min(p, 1.0)))


@dataclass(frozen=True)
class RateDifference:
    """Two full-plan rates over different scenarios (another hand, another seed), and
    whether they differ by more than chance.

    Attributes:
        k, n: Full plans and scenarios of the first run.
        k_other, n_other: The same of the other run.
        p_value: Two-sided Fisher exact test of the 2 x 2 table (full plan or not, by
            run): how likely rates at least this far apart are when both runs draw from
            one rate.
    """

    k: int
    n: int
    k_other: int
    n_other: int
    p_value: float

    def line(self) -> str:
        """The comparison in plain words, one line."""
        verdict = (
            "the rates differ by more than chance"
            if _beyond_chance(self.p_value)
            else "no difference beyond chance"
        )
        return (
            f"{self.k}/{self.n} {self.k / self.n:.0%} against "
            f"{self.k_other}/{self.n_other} {self.k_other / self.n_other:.0%} "
            f"(Fisher exact p={self.p_value:.2g}: {verdict})"
        )


def rate_difference(
    results: Sequence[ScenarioResult], other: Sequence[ScenarioResult]
) -> RateDifference:
    """The full-plan rates of two runs over different scenarios, compared
    (:class:`RateDifference`); for the same scenarios, :func:`paired_change` is the
    sharper test.

    Raises:
        InputError: a run without results.
    """
    if not results or not other:
        raise InputError(
            "results" if not results else "other",
            "is empty",
            "the results of a run with at least one scenario",
        )
    k, n = sum(r.ok for r in results), len(results)
    k_o, n_o = sum(r.ok for r in other), len(other)
    _, p = fisher_exact([[k, n - k], [k_o, n_o - k_o]])
    return RateDifference(k, n, k_o, n_o, float(min(p, 1.0)))


def _stats(values: Iterable[float | None], unit: str, scale: float = 1.0) -> str:
    v = np.array([x for x in values if x is not None], float) * scale
    if v.size == 0:
        return "n/a"
    med, p95 = np.percentile(v, [50, 95])
    return f"median {med:.3g} {unit}, p95 {p95:.3g} {unit}, max {v.max():.3g} {unit} (n={v.size})"


def _missed_by(kind: str | None, group: Sequence[ScenarioResult]) -> str:
    """For a kind whose numbers are distances, how far its failures missed [mm]
    (required - measured: the attempt nearest to passing of each); else ""."""
    if kind not in {k.value for k in DISTANCE_KINDS}:
        return ""
    short = [
        (r.required - r.measured) * 1e3
        for r in group
        if r.measured is not None and r.required is not None
    ]
    if not short:
        return ""
    lo, mid, hi = np.min(short), np.median(short), np.max(short)
    return f"; missed by {lo:.2f}-{hi:.2f} mm, median {mid:.2f} mm"


def _came_near(kind: str | None, group: Sequence[ScenarioResult]) -> str:
    """For finger collisions, the fingers that the failing fingers came too near: per
    scenario the one its attempts of that kind name most often (ties by name), counted
    over the scenarios; "" when none is named (results of older versions)."""
    if kind != FailureKind.FINGER_COLLISION.value:
        return ""
    near: Counter[str] = Counter()
    for r in group:
        named = Counter(a["other"] for a in r.attempts if a.get("kind") == kind and a.get("other"))
        if named:
            near[min(named, key=lambda f: (-named[f], f))] += 1
    if not near:
        return ""
    ranked = sorted(near.items(), key=lambda kv: (-kv[1], kv[0]))
    return "; near " + ", ".join(f"{f} {c}" for f, c in ranked)


#: The stages of a plan's setup, built before its search (``ScenarioResult.stage_s``)
_SETUP_STAGES = ("manifolds", "must hold")


def time_spent(results: Sequence[ScenarioResult], skipped: Sequence[ScenarioResult] = ()) -> str:
    """Where a suite's time went [s], summed over its scenarios, each in one process.

    On one worker the sums add up to about the wall time, less the workers' start; on
    several they are what each scenario took on its worker. Three lines:

    - builds: of the scenarios (:func:`~.build.build_scenario`, with the backups' grasp
      searches, given apart) and of the specs ``skipped`` without an initial grasp;
    - planning: of the full plans and of the failures; of all of it, the setup of the
      first plan (the fingers' manifolds and the must-hold proof, built before the
      search and once for its backups: ``stage_s``), the backups' plans, and the rest:
      the searches;
    - the re-checks of the full plans.

    Args:
        results: The scenarios' results.
        skipped: The specs skipped without an initial grasp (their ``build_s``).

    Returns:
        The lines (no trailing newline); a scenario without a setup time (a result
        of an older version) is counted as searching, and their number is given.
    """
    res = list(results)

    def total(values: Iterable[float | None]) -> float:
        return float(sum(v for v in values if v is not None))

    backups_choose = total(b.get("choose_s") for r in res for b in r.backups)
    backups_plan = total(b.get("plan_s") for r in res for b in r.backups)
    builds, skipped_s = total(r.build_s for r in res), total(r.build_s for r in skipped)
    full = total(r.plan_s for r in res if r.ok)
    failed = total(r.plan_s for r in res if not r.ok)
    setup = {k: total(r.stage_s.get(k) for r in res) for k in _SETUP_STAGES}
    search = full + failed - sum(setup.values()) - backups_plan
    rechecks = total(r.recheck_s for r in res)
    without = sum(1 for r in res if r.plan_s is not None and not r.stage_s)
    lines = [
        f"time spent, summed over the scenarios: "
        f"{builds + skipped_s + full + failed + rechecks:.1f} s",
        f"  builds     {builds + skipped_s:8.1f} s  (the scenarios' {builds:.1f} s, of it the "
        f"backups' grasp searches {backups_choose:.1f} s; the {len(skipped)} specs skipped "
        f"{skipped_s:.1f} s)",
        f"  planning   {full + failed:8.1f} s  (full plans {full:.1f} s, failures {failed:.1f} s; "
        f"the setups' manifolds {setup['manifolds']:.1f} s and must-hold proofs "
        f"{setup['must hold']:.1f} s, the backups' plans {backups_plan:.1f} s, "
        f"the searches {search:.1f} s"
        + (f"; {without} without stage times" if without else "")
        + ")",
        f"  re-checks  {rechecks:8.1f} s  ({sum(r.ok for r in res)} full plans)",
    ]
    return "\n".join(lines)


def summarize(results: Sequence[ScenarioResult]) -> str:
    """A plain-text report of a suite's results.

    The full-plan rate with its interval (:func:`rate_interval`), success rates per
    hand x object kind and per motion kind, failures by kind (with
    the stage and the fingers), how many scenarios backed up to another initial grasp
    and planned fully then, planning time per regrasp and per scenario (median and
    95th percentile), and how many full plans passed the independent re-check.

    Args:
        results: The results (every one counts; leave skipped specs out).

    Returns:
        The report (several lines, no trailing newline).
    """
    res = list(results)
    lines = [f"scenarios: {len(res)}, full plans: {_rate(res)}"]
    if not res:
        return "\n".join(lines)
    lo, hi = rate_interval(sum(r.ok for r in res), len(res))
    lines[0] += f" ({CONFIDENCE:.0%} interval {lo:.0%}-{hi:.0%})"
    proven = [r for r in res if r.failure_kind == FailureKind.INFEASIBLE.value]
    if proven:
        rest = [r for r in res if r.failure_kind != FailureKind.INFEASIBLE.value]
        lines.append(
            f"proven to have no plan (kind infeasible): {len(proven)}; "
            f"full plans of the others: {_rate(rest)}"
        )
    hands = [h for h in HANDS if any(r.hand == h for r in res)]
    hands += sorted({r.hand for r in res} - set(hands))
    kinds = [k for k in OBJECT_KINDS if any(r.object_kind == k for r in res)]
    kinds += sorted({r.object_kind for r in res} - set(kinds))
    lines.append("")
    lines.append("full plans by hand x object:")
    lines.append(f"  {'':14}" + "".join(f"{k:>12}" for k in [*kinds, "all"]))
    for h in hands:
        row = [_rate([r for r in res if r.hand == h and r.object_kind == k]) for k in kinds]
        row.append(_rate([r for r in res if r.hand == h]))
        lines.append(f"  {h:14}" + "".join(f"{c:>12}" for c in row))
    lines.append(
        f"  {'all':14}"
        + "".join(f"{_rate([r for r in res if r.object_kind == k]):>12}" for k in kinds)
        + f"{_rate(res):>12}"
    )
    lines.append("full plans by motion:")
    motions = [m for m in MOTION_KINDS if any(r.motion_kind == m for r in res)]
    motions += sorted({r.motion_kind for r in res} - set(motions))
    for m in motions:
        lines.append(f"  {m:18}{_rate([r for r in res if r.motion_kind == m]):>12}")
    failed = [r for r in res if not r.ok]
    lines += _failure_lines(res, failed)
    planned = [r for r in res if r.plan_s is not None]
    lines.append(
        "planning time per regrasp: " + _stats((ms for r in planned for ms in r.regrasp_ms), "ms")
    )
    lines.append("planning time per scenario: " + _stats((r.plan_s for r in planned), "s"))
    lines.append("build time per scenario: " + _stats((r.build_s for r in res), "s"))
    got = [
        r.planned_until_s / r.duration_s
        for r in planned
        if r.planned_until_s is not None and r.duration_s
    ]
    if got:
        reached = np.mean(got)
        lines.append(f"motion planned before success or failure: {reached:.0%} on average")
    touching = [
        r
        for r in res
        if r.initial_finger_clearance_m is not None and r.initial_finger_clearance_m <= 0.0
    ]
    if touching:
        lines.append(
            f"initial grasps with fingers inside each other: {len(touching)} "
            f"(full plans among them: {_rate(touching)})"
        )
    full = [r for r in res if r.ok]
    passed = sum(r.recheck_ok is True for r in full)
    lines.append(f"re-check of the full plans: {passed}/{len(full)} passed")
    for r in full:
        if r.recheck_ok is False:
            lines.append(f"  {r.name}: {'; '.join(r.recheck_problems[:3])}")
    return "\n".join(lines)


def _failure_lines(res: list[ScenarioResult], failed: list[ScenarioResult]) -> list[str]:
    """The failures by kind, the backups to another initial grasp, and the failures
    that came before any verified regrasp."""
    lines: list[str] = []
    lines.append(f"failures by kind: {len(failed)}")
    for kind, count in Counter(r.failure_kind for r in failed).most_common():
        group = [r for r in failed if r.failure_kind == kind]
        stages = Counter(r.failed_stage for r in group)
        fingers = Counter(r.finger for r in group if r.finger)
        detail = ", ".join(f"{s} {c}" for s, c in sorted(stages.items(), key=str))
        if fingers:
            detail += "; " + ", ".join(f"{f} {c}" for f, c in fingers.most_common())
        detail += _came_near(kind, group) + _missed_by(kind, group)
        lines.append(f"  {kind!s:24}{count:4d}   ({detail})")
    backed = [r for r in res if r.backups]
    if backed:
        won = sum(r.ok for r in backed)
        tries = sum(len(r.backups) for r in backed)
        lines.append(
            f"backed up to another initial grasp (a finger failed on its start contact): "
            f"{len(backed)} scenarios, {tries} grasps; full plans after it: {won}"
        )
    in_plan = [r for r in failed if r.failed_stage == "plan"]
    if in_plan:
        first = sum(r.n_regrasps == 0 for r in in_plan)
        lines.append(f"planning failures before any verified regrasp: {first}/{len(in_plan)}")
    return lines


def result_line(r: ScenarioResult, done: int, total: int) -> str:
    """One line per scenario as it finishes (and a failure's reason on a second line)."""
    plan = "     -  " if r.plan_s is None else f"{r.plan_s:6.1f} s"
    times = f"build {r.build_s or 0:5.1f} s  plan {plan}"
    head = f"[{done:3d}/{total}] {r.name:60}"
    c0 = r.initial_finger_clearance_m
    if c0 is not None and c0 <= 0.0:
        times += f"  (starts with fingers {-c0 * 1e3:.1f} mm inside each other)"
    if r.backups:
        times += "  backed up: " + ", ".join(
            f"{b['finger']} after {b['after']} -> {b.get('outcome')}" for b in r.backups
        )
    if r.ok:
        check = {True: "re-check ok", False: "RE-CHECK FAILED", None: "not re-checked"}
        status = f"ok   {r.n_regrasps:2d} regrasps  {check[r.recheck_ok]:15}"
        text = f"{head} {status} {times}"
        if r.recheck_ok is False:
            text += "\n      " + "; ".join(r.recheck_problems[:3])
        return text
    where = " ".join(
        x
        for x in (
            r.finger or "",
            f"t={r.time_s:.2f}/{r.duration_s:.1f} s" if r.time_s is not None else "",
        )
        if x
    )
    status = f"FAIL {r.failure_kind} ({r.failed_stage}) {where} after {r.n_regrasps} regrasps"
    return f"{head} {status:45} {times}\n      {(r.failure or '')[:200]}"
