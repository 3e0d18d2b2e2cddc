"""Text, Markdown and JSON views of a comparison
(:class:`~pytest_hevval.results.changes.Comparison`; pure: data in, text out)."""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import Any

from ..core.registry import describe
from ..escape import markdown, markdown_code
from ..results.changes import Comparison, FieldDelta, SignalComparison
from .regressions import Regression

__all__ = ["FORMATS", "comparison_json", "comparison_markdown", "comparison_table", "render"]

FORMATS = ("table", "md", "json")

_ERROR_LABELS = {
    "lag_s": "lag",
    "mae": "MAE",
    "rms": "RMS",
    "delta_e": "ΔE (RMS−MAE)",
    "error_std": "error σ",
    "mean_error": "mean error",
}


def _lambda_label(name: str) -> str:
    symbol = describe(name).symbol
    return name if symbol == name else f"{symbol} {name}"


def _value(value: float | None, *, physical: bool) -> str:
    if value is None:
        return "—"
    return f"{value:.4g}" if physical else f"{value:.4f}"


def _delta(delta: FieldDelta, *, physical: bool) -> str:
    change = delta.delta
    if change is None:
        return "—"
    if change == 0:
        return "0"
    return f"{change:+.3g}" if physical else f"{change:+.4f}"


def _signal_rows(signal: SignalComparison) -> list[tuple[str, str, str, str]]:
    rows = []
    for delta in signal.lambdas:
        rows.append(
            (
                _lambda_label(delta.field),
                _value(delta.before, physical=False),
                _value(delta.after, physical=False),
                _delta(delta, physical=False),
            )
        )
    for delta in signal.errors:
        unit = "s" if delta.field == "lag_s" else signal.unit
        label = _ERROR_LABELS.get(delta.field, delta.field) + (f" [{unit}]" if unit else "")
        rows.append(
            (
                label,
                _value(delta.before, physical=True),
                _value(delta.after, physical=True),
                _delta(delta, physical=True),
            )
        )
    return rows


def _passed(before: bool | None, after: bool | None) -> str:
    words = {True: "pass", False: "FAIL", None: "?"}
    return f"{words[before]} → {words[after]}"


def _columns(rows: Sequence[Sequence[str]], indent: str) -> list[str]:
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    out = []
    for row in rows:
        cells = [row[0].ljust(widths[0])] + [
            c.rjust(w) for c, w in zip(row[1:], widths[1:], strict=True)
        ]
        out.append(indent + "  ".join(cells).rstrip())
    return out


#: The windows, phases and cells named per signal and direction; the rest are counted.
WHERE_NAMED = 4


def _where_lines(signal: SignalComparison) -> list[str]:
    """Where the model change helped and where it hurt (windows, phases, conditions, cells)."""
    lines = []
    for word, changes in (("better", signal.better), ("worse", signal.worse)):
        if changes:
            named = "; ".join(c.text(signal.unit) for c in changes[:WHERE_NAMED])
            more = f" (+{len(changes) - WHERE_NAMED} more)" if len(changes) > WHERE_NAMED else ""
            lines.append(f"    {word} in: {named}{more}")
    return lines


def comparison_table(comparison: Comparison, found: Sequence[Regression] | None = None) -> str:
    """Terminal text: per signal each λ, the physical errors and the lag, then Φ per spec."""
    lines = [f"compare {comparison.before_label} → {comparison.after_label}"]
    for spec in comparison.specs:
        lines += ["", f"{spec.key} ({spec.name})"]
        for signal in spec.signals:
            unit = f" [{signal.unit}]" if signal.unit else ""
            lines.append(
                f"  {signal.path}{unit}  {_passed(signal.passed_before, signal.passed_after)}"
            )
            rows = [("", comparison.before_label, comparison.after_label, "Δ")]
            lines += _columns(rows + _signal_rows(signal), "    ")
            lines += _where_lines(signal)
        for path in spec.added_signals:
            lines.append(f"  {path}: new (no baseline)")
        for path in spec.removed_signals:
            lines.append(f"  {path}: missing from the current run")
    lines += _footer_text(comparison, found)
    return "\n".join(lines) + "\n"


def _footer_text(comparison: Comparison, found: Sequence[Regression] | None) -> list[str]:
    lines = ["", "Φ"]
    rows = [("spec", comparison.before_label, comparison.after_label, "Δ", "outcome")]
    for spec in comparison.specs:
        rows.append(
            (
                spec.key,
                _value(spec.phi.before, physical=False),
                _value(spec.phi.after, physical=False),
                _delta(spec.phi, physical=False),
                _passed(spec.passed_before, spec.passed_after),
            )
        )
    lines += _columns(rows, "  ")
    for key in comparison.added_specs:
        lines.append(f"  {key}: new spec (no baseline)")
    for key in comparison.removed_specs:
        lines.append(f"  {key}: missing from the current run")
    if found is not None:
        lines.append("")
        if found:
            lines.append(f"{len(found)} regression(s):")
            lines += [f"  {item}" for item in found]
        else:
            lines.append("no regressions")
    return lines


def comparison_markdown(comparison: Comparison, found: Sequence[Regression] | None = None) -> str:
    """GitHub-flavoured Markdown: one table per signal, then a Φ table."""
    before, after = markdown(comparison.before_label), markdown(comparison.after_label)
    lines = [
        "## hevval compare "
        f"{markdown_code(comparison.before_label)} → {markdown_code(comparison.after_label)}"
    ]
    for spec in comparison.specs:
        lines += ["", f"### {markdown(spec.name)} ({markdown_code(spec.key)})"]
        for signal in spec.signals:
            unit = f" [{markdown(signal.unit)}]" if signal.unit else ""
            lines += [
                "",
                f"#### {markdown_code(signal.path)}{unit}: "
                f"{_passed(signal.passed_before, signal.passed_after)}",
                "",
                f"| | {before} | {after} | Δ |",
                "|---|---:|---:|---:|",
            ]
            lines += [
                f"| {markdown(label)} | {b} | {a} | {d} |"
                for label, b, a, d in _signal_rows(signal)
            ]
        extra = [f"- {markdown_code(p)}: new (no baseline)" for p in spec.added_signals]
        extra += [
            f"- {markdown_code(p)}: missing from the current run" for p in spec.removed_signals
        ]
        if extra:
            lines += ["", *extra]
    lines += [
        "",
        "### Φ",
        "",
        f"| spec | {before} | {after} | Δ | outcome |",
        "|---|---:|---:|---:|---|",
    ]
    for spec in comparison.specs:
        lines.append(
            f"| {markdown_code(spec.key)} | {_value(spec.phi.before, physical=False)} | "
            f"{_value(spec.phi.after, physical=False)} | {_delta(spec.phi, physical=False)} | "
            f"{_passed(spec.passed_before, spec.passed_after)} |"
        )
    notes = [f"- {markdown_code(k)}: new spec (no baseline)" for k in comparison.added_specs]
    notes += [
        f"- {markdown_code(k)}: missing from the current run" for k in comparison.removed_specs
    ]
    if notes:
        lines += ["", *notes]
    if found is not None:
        lines += ["", "### Regressions", ""]
        lines += [f"- {markdown(str(item))}" for item in found] or ["None."]
    return "\n".join(lines) + "\n"


def comparison_json(comparison: Comparison, found: Sequence[Regression] | None = None) -> str:
    """The comparison (and regressions, when rules were given) as strict JSON."""
    document: dict[str, Any] = {"comparison": comparison.to_dict()}
    if found is not None:
        document["regressions"] = [item.to_dict() for item in found]
    return json.dumps(document, indent=2, ensure_ascii=False, allow_nan=False) + "\n"


def render(comparison: Comparison, fmt: str, found: Sequence[Regression] | None = None) -> str:
    """Dispatch on ``fmt`` (one of :data:`FORMATS`)."""
    if fmt == "md":
        return comparison_markdown(comparison, found)
    if fmt == "json":
        return comparison_json(comparison, found)
    return comparison_table(comparison, found)
