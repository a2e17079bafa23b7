"""Summaries of failed attempts: the dominant cause and what to change."""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence

from ..exceptions import ADVICE, Attempt, FailureKind

__all__ = ["dominant_kind", "failure_summary"]

_ORDER = {k: i for i, k in enumerate(FailureKind)}


def dominant_kind(attempts: Sequence[Attempt], default: FailureKind) -> FailureKind:
    """The most frequent kind among ``attempts`` (ties: the first in :class:`FailureKind`)."""
    if not attempts:
        return default
    counts = Counter(a.kind for a in attempts)
    return min(counts, key=lambda k: (-counts[k], _ORDER[k]))


def failure_summary(attempts: Sequence[Attempt], default: FailureKind) -> str:
    """One sentence: how many attempts failed, the dominant cause and what to change."""
    kind = dominant_kind(attempts, default)
    counts = Counter(a.kind for a in attempts)
    parts = ", ".join(
        f"{n} {k.value}" for k, n in sorted(counts.items(), key=lambda kv: _ORDER[kv[0]])
    )
    head = f"{len(attempts)} attempts failed ({parts}); " if attempts else ""
    return f"{head}mostly {kind.value}: {ADVICE[kind]}"
