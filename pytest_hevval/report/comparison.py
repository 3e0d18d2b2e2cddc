"""The comparison with the baseline in Markdown, for report.md and for comparison.md alone.

Made for a pull-request comment: which record the run was compared with, what got worse and
what got better and by how much (with both runs' 95 % intervals where recorded), the
regressions first, the worst changes in a short table and every change behind a
``<details>``. It reads the typed comparison, as every report reads typed results, and the
regressions from the run's verdict.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from ..core.registry import describe
from ..escape import markdown, markdown_code
from ..results.changes import Comparison, FieldDelta
from ..results.verdict import RunVerdict
from .text import regression_lines

__all__ = ["COMPARISON_ROWS", "Change", "changes", "comparison_markdown"]

#: Rows of the short tables (worst changes, best changes); every change is behind <details>.
COMPARISON_ROWS = 10
_BETTER_ROWS = 5
#: Values are shown to four decimals: a smaller change would read "+0.0000" and is counted
#: as none.
SHOWN_CHANGE = 0.5e-4


@dataclass(frozen=True)
class Change:
    """Φ of a spec, or one λ of a signal, that differs between the baseline and this run."""

    spec: str
    signal: str | None
    field: str
    before: float
    after: float
    before_interval: tuple[float, float] | None
    after_interval: tuple[float, float] | None
    #: A rule of compare-fail this change breaks.
    regression: bool
    #: Whether the two intervals are disjoint (None where either run has none).
    beyond_noise: bool | None = None

    @property
    def delta(self) -> float:
        return self.after - self.before

    @property
    def label(self) -> str:
        if self.field == "phi":
            return "Φ"
        symbol = describe(self.field).symbol
        return self.field if symbol == self.field else f"{symbol} {self.field}"


def _change(
    spec: str, signal: str | None, delta: FieldDelta, regressed: set[tuple[str, str | None, str]]
) -> Change | None:
    before, after = delta.before, delta.after
    if before is None or after is None or abs(after - before) < SHOWN_CHANGE:
        return None
    # Intervals are shown where both runs recorded one: only then can they be set side by side.
    beyond_noise = delta.beyond_noise
    return Change(
        spec,
        signal,
        delta.field,
        before,
        after,
        delta.before_interval if beyond_noise is not None else None,
        delta.after_interval if beyond_noise is not None else None,
        (spec, signal, delta.field) in regressed,
        beyond_noise,
    )


def changes(comparison: Comparison, verdict: RunVerdict | None = None) -> list[Change]:
    """Every Φ and λ that changed, the regressions first, then the drops, largest first, then
    the rises, largest first."""
    found_regressions = verdict.regressions if verdict is not None else ()
    regressed = {(r.spec, r.signal, r.field) for r in found_regressions}
    found: list[Change] = []
    for spec in comparison.specs:
        phi = _change(spec.key, None, spec.phi, regressed)
        found += [phi] if phi is not None else []
        for signal in spec.signals:
            for delta in signal.lambdas:
                change = _change(spec.key, signal.path, delta, regressed)
                found += [change] if change is not None else []
    found.sort(key=lambda c: (not c.regression, c.delta > 0, -abs(c.delta)))
    return found


def _number(value: float) -> str:
    return f"{value:.4f}" if math.isfinite(value) else "—"


def _bounds(interval: tuple[float, float] | None) -> str:
    return "—" if interval is None else f"[{_number(interval[0])}, {_number(interval[1])}]"


def _row(change: Change) -> str:
    mark = "❌" if change.regression else ("🔻" if change.delta < 0 else "🔺")
    where = markdown_code(
        change.spec if change.signal is None else f"{change.spec}::{change.signal}"
    )
    intervals = (
        ""
        if change.before_interval is None and change.after_interval is None
        else f"{_bounds(change.before_interval)} → {_bounds(change.after_interval)}"
        + (" (disjoint)" if change.beyond_noise else "")
    )
    return (
        f"| {mark} | {where} | {markdown(change.label)} | {_number(change.before)} "
        f"| {_number(change.after)} | {change.delta:+.4f} | {intervals} |"
    )


def _table(rows: Sequence[Change]) -> list[str]:
    return [
        "| | where | quantity | before | after | Δ | 95 % intervals (before → after) |",
        "|:-:|---|---|--:|--:|--:|---|",
        *(_row(change) for change in rows),
    ]


def comparison_markdown(
    comparison: Comparison, verdict: RunVerdict, *, heading: str = "####"
) -> list[str]:
    """The comparison's lines: what it was compared with, the counts, the worst changes, the
    best ones, then every change behind a ``<details>``."""
    found = changes(comparison, verdict)
    worse = [c for c in found if c.regression or c.delta < 0]
    better = [c for c in found if not c.regression and c.delta > 0]
    baseline = verdict.baseline
    against = markdown(baseline if baseline is not None else comparison.before_label)
    accepted = verdict.regressions_accepted
    count = len(verdict.regressions)
    said = (
        f"{count} regression{'s' * (count != 1)}"
        + (" (accepted with --hevval-accept)" if accepted else "")
        if count
        else "no regression"
    )
    lines = [
        f"{heading} Compared with {against}",
        "",
        f"{'⚠️' if count and accepted else '❌' if count else '✅'} {said}; "
        f"{len(worse)} value{'s' * (len(worse) != 1)} of Φ and λ worse, {len(better)} better.",
    ]
    if count:
        lines += ["", *regression_lines(verdict)]
    notes = [markdown(note) for note in comparison.pairings]
    notes += [
        f"{markdown_code(spec.key)}: data changed ({markdown(', '.join(spec.data_changed))})"
        for spec in comparison.specs
        if spec.data_changed
    ]
    notes += [f"{markdown_code(key)}: new spec (no baseline)" for key in comparison.added_specs]
    notes += [f"{markdown_code(key)}: not in this run" for key in comparison.removed_specs]
    if notes:
        lines += ["", *(f"- {note}" for note in notes)]
    if worse:
        lines += ["", "**Worst changes**", "", *_table(worse[:COMPARISON_ROWS])]
    if better:
        lines += ["", "**Best changes**", "", *_table(better[:_BETTER_ROWS])]
    if len(found) > len(worse[:COMPARISON_ROWS]) + len(better[:_BETTER_ROWS]):
        lines += [
            "",
            f"<details><summary>Every change ({len(found)})</summary>",
            "",
            *_table(found),
            "",
            "</details>",
        ]
    return lines
