"""A suite folder's report as files: ``report.md`` and ``report.html``.

Both hold the full-plan rate per hand x object kind x motion kind, the failures by kind
(a bar chart), the distribution of the planning time per scenario, and one row per
scenario with links to its plan file and to its static viewer page
(``viewer/<name>.html``, written by :func:`~regrasp_pin.viz.export_html` when meshcat
is installed). :func:`write_report` rebuilds them from the folder's ``results.jsonl``
alone (``regrasp-pin suite --report DIR``).
"""

from __future__ import annotations

import html
import logging
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..exceptions import InputError
from ..scenarios import HANDS
from .cluster import load_run
from .report import summarize
from .run import ScenarioResult
from .specs import MOTION_KINDS, OBJECT_KINDS

__all__ = ["ReportFiles", "write_report"]

log = logging.getLogger(__name__)

_BINS_S = (0.0, 1.0, 2.0, 5.0, 10.0, 20.0, 30.0, 60.0, 120.0, np.inf)


@dataclass(frozen=True)
class ReportFiles:
    """The files :func:`write_report` wrote.

    Attributes:
        markdown: ``report.md``.
        html: ``report.html``.
        viewer_pages: Static viewer pages written (``viewer/<name>.html``).
    """

    markdown: Path
    html: Path
    viewer_pages: tuple[Path, ...]


def _order(values: set[str], known: Sequence[str]) -> list[str]:
    return [v for v in known if v in values] + sorted(values - set(known))


def _rate(group: list[ScenarioResult]) -> str:
    if not group:
        return "-"
    k = sum(r.ok for r in group)
    return f"{k}/{len(group)} ({k / len(group):.0%})"


def _rate_table(res: list[ScenarioResult]) -> tuple[list[str], list[list[str]]]:
    """Header and rows: hand x object kind, one column per motion kind and all."""
    motions = _order({r.motion_kind for r in res}, MOTION_KINDS)
    hands = _order({r.hand for r in res}, HANDS)
    kinds = _order({r.object_kind for r in res}, OBJECT_KINDS)
    head = ["hand", "object", *motions, "all"]
    rows = []
    for h in hands:
        for k in kinds:
            group = [r for r in res if r.hand == h and r.object_kind == k]
            if group:
                rows.append(
                    [h, k, *(_rate([r for r in group if r.motion_kind == m]) for m in motions)]
                    + [_rate(group)]
                )
    rows.append(["all", "all", *(_rate([r for r in res if r.motion_kind == m]) for m in motions)])
    rows[-1].append(_rate(res))
    return head, rows


def _time_histogram(res: list[ScenarioResult]) -> list[tuple[str, int]]:
    times = np.array([r.plan_s for r in res if r.plan_s is not None], float)
    out = []
    for lo, hi in zip(_BINS_S[:-1], _BINS_S[1:], strict=True):
        label = f"{lo:g}-{hi:g} s" if np.isfinite(hi) else f">= {lo:g} s"
        out.append((label, int(((times >= lo) & (times < hi)).sum())))
    return out


def _outcome(r: ScenarioResult) -> str:
    if r.ok:
        return "ok" if r.recheck_ok is not False else "ok, RE-CHECK FAILED"
    return str(r.failure_kind)


def _viewer_pages(folder: Path, res: list[ScenarioResult]) -> dict[str, Path]:
    """Static viewer pages of the plans in ``folder`` (none without meshcat)."""
    try:
        from ..viz import export_html
    except ImportError as exc:  # the viz extra is optional
        log.warning("no viewer pages: %s (pip install 'regrasp-pin[viz]')", exc)
        return {}
    pages = {}
    for r in res:
        plan = _plan_file(folder, r)
        if plan is None:
            continue
        page = folder / "viewer" / f"{r.name}.html"
        if not page.is_file() or page.stat().st_mtime < plan.stat().st_mtime:
            export_html(plan, page)
        pages[r.name] = page
    return pages


def _plan_file(folder: Path, r: ScenarioResult) -> Path | None:
    """The scenario's plan (or partial plan) file in ``folder``, if it is there."""
    if r.plan_path is None:
        return None
    path = folder / Path(r.plan_path).name
    return path if path.is_file() else None


def _markdown(
    title: str, summary: str, res: list[ScenarioResult], folder: Path, pages: dict[str, Path]
) -> str:
    head, rows = _rate_table(res)
    failed = Counter(r.failure_kind for r in res if not r.ok)
    top = max(failed.values(), default=1)
    lines = [f"# {title}", "", "## Full plans by hand x object x motion", ""]
    lines.append("| " + " | ".join(head) + " |")
    lines.append("|" + "---|" * len(head))
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    lines += ["", "## Failures by kind", "", "| kind | count | |", "|---|---:|---|"]
    for kind, count in failed.most_common():
        lines.append(f"| {kind} | {count} | {'#' * max(1, round(20 * count / top))} |")
    lines += ["", "## Planning time per scenario", "", "| time | scenarios |", "|---|---:|"]
    lines += [f"| {label} | {count} |" for label, count in _time_histogram(res)]
    lines += ["", "## Summary", "", "```", summary, "```", "", "## Scenarios", ""]
    lines += [
        "| scenario | outcome | regrasps | plan [s] | plan file | viewer |",
        "|---|---|---:|---:|---|---|",
    ]
    for r in res:
        plan = _plan_file(folder, r)
        page = pages.get(r.name)
        lines.append(
            f"| {r.name} | {_outcome(r)} | {r.n_regrasps} | "
            + ("-" if r.plan_s is None else f"{r.plan_s:.1f}")
            + " | "
            + ("-" if plan is None else f"[{plan.name}]({plan.name})")
            + " | "
            + ("-" if page is None else f"[view](viewer/{page.name})")
            + " |"
        )
    return "\n".join(lines) + "\n"


_CSS = """
body { font-family: system-ui, sans-serif; margin: 2em; max-width: 70em; }
table { border-collapse: collapse; margin: 0.5em 0 1.5em; }
td, th { border: 1px solid #ccc; padding: 0.2em 0.6em; text-align: left; }
td.n { text-align: right; }
.bar { background: #4a7ab5; height: 1em; display: inline-block; }
.fail { color: #a02020; }
pre { background: #f4f4f4; padding: 1em; }
"""


def _html(
    title: str, summary: str, res: list[ScenarioResult], folder: Path, pages: dict[str, Path]
) -> str:
    e = html.escape
    head, rows = _rate_table(res)
    failed = Counter(r.failure_kind for r in res if not r.ok)
    hist = _time_histogram(res)

    def bars(items: list[tuple[str, int]]) -> str:
        top = max((c for _, c in items), default=1) or 1
        return "".join(
            f"<tr><td>{e(label)}</td><td class='n'>{c}</td><td style='width:20em'>"
            f"<span class='bar' style='width:{100 * c / top:.1f}%'></span></td></tr>"
            for label, c in items
        )

    out = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{e(title)}</title>"]
    out.append(f"<style>{_CSS}</style></head><body><h1>{e(title)}</h1>")
    out.append("<h2>Full plans by hand x object x motion</h2><table><tr>")
    out.append("".join(f"<th>{e(h)}</th>" for h in head) + "</tr>")
    out += ["<tr>" + "".join(f"<td>{e(c)}</td>" for c in row) + "</tr>" for row in rows]
    out.append("</table><h2>Failures by kind</h2><table>")
    out.append(bars([(str(k), c) for k, c in failed.most_common()]) + "</table>")
    out.append("<h2>Planning time per scenario</h2><table>" + bars(hist) + "</table>")
    out.append(f"<h2>Summary</h2><pre>{e(summary)}</pre><h2>Scenarios</h2><table>")
    out.append(
        "<tr><th>scenario</th><th>outcome</th><th>regrasps</th><th>plan [s]</th>"
        "<th>plan file</th><th>viewer</th></tr>"
    )
    for r in res:
        plan, page = _plan_file(folder, r), pages.get(r.name)
        cls = "" if r.ok else " class='fail'"
        why = "" if r.ok else f" title='{e(r.failure or '')}'"
        out.append(
            f"<tr><td>{e(r.name)}</td><td{cls}{why}>{e(_outcome(r))}</td>"
            f"<td class='n'>{r.n_regrasps}</td><td class='n'>"
            + ("-" if r.plan_s is None else f"{r.plan_s:.1f}")
            + "</td><td>"
            + ("-" if plan is None else f"<a href='{e(plan.name)}'>{e(plan.name)}</a>")
            + "</td><td>"
            + ("-" if page is None else f"<a href='viewer/{e(page.name)}'>view</a>")
            + "</td></tr>"
        )
    out.append("</table></body></html>")
    return "\n".join(out) + "\n"


def write_report(
    out: str | Path,
    results: Sequence[ScenarioResult] | None = None,
    *,
    viewer_pages: bool = True,
    title: str | None = None,
) -> ReportFiles:
    """Write ``report.md`` and ``report.html`` into the suite folder ``out``.

    Args:
        out: The suite folder (plans and ``results.jsonl``, as :func:`~.cluster.run_suite`
            writes them).
        results: The results; default: read from ``out/results.jsonl``.
        viewer_pages: Also write a static viewer page per plan file
            (``viewer/<name>.html``, about 2 MB and 1 s each; needs meshcat) and link it.
        title: The report's title; default from the folder's name.

    Returns:
        The :class:`ReportFiles`.

    Raises:
        InputError: ``out`` is not a folder, or has no results to report.
    """
    folder = Path(out)
    if not folder.is_dir():
        raise InputError("out", f"{str(folder)!r} is not a folder", "a suite's output folder")
    res = list(results) if results is not None else load_run(folder)[0]
    if not res:
        raise InputError("out", f"no results in {folder}", "a folder with a results.jsonl")
    pages = _viewer_pages(folder, res) if viewer_pages else {}
    name = title or f"Scenario suite: {folder.resolve().name}"
    summary = summarize(res)
    md = folder / "report.md"
    md.write_text(_markdown(name, summary, res, folder, pages))
    page = folder / "report.html"
    page.write_text(_html(name, summary, res, folder, pages))
    return ReportFiles(md, page, tuple(pages.values()))
