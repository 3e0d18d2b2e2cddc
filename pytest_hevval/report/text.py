"""Machine- and chat-readable reports: JSON (the source of truth), Markdown, CI annotations.

Each takes the typed results. JSON is made in one place, :func:`report_document`, from the
results' own JSON. Standard library only, so these work without the ``html`` extra.
"""

from __future__ import annotations

import contextlib
import json
from collections.abc import Mapping, Sequence
from pathlib import Path, PurePath
from typing import Any

from .. import __version__
from ..defaults import split_key
from ..escape import markdown, markdown_code
from ..results.campaign import CampaignVerdict, RecordingOutcome
from ..results.changes import Comparison
from ..results.codec import plain_json
from ..results.spec_result import SignalResult, SpecResult
from ..results.verdict import RunVerdict
from . import model
from .panels import SignalPanels

__all__ = [
    "REPORT_SCHEMA_VERSION",
    "github_annotations",
    "headline",
    "regression_lines",
    "render_comparison",
    "render_json",
    "render_markdown",
    "report_document",
]

#: Version of the report.json layout (the per-spec dicts carry their own ``schema_version``).
REPORT_SCHEMA_VERSION = 1

# A step summary or PR comment should stay readable; the full list is in the HTML/JSON.
_MARKDOWN_SIGNALS = 15


def _worst_json(spec_results: Sequence[SpecResult]) -> list[dict[str, Any]]:
    out = []
    for row in model.worst_rows(spec_results, limit=12):
        cell = row.worst
        out.append(
            {
                "spec": row.spec,
                "spec_index": row.spec_index,
                "path": row.signal.path,
                "passed": row.signal.passed,
                "characteristic": cell.characteristic if cell else None,
                "value": cell.value if cell else None,
                "threshold": cell.threshold if cell else None,
                "margin": row.margin,
                "origins": list(row.signal.origins),
            }
        )
    return out


def report_document(
    results: Sequence[SpecResult],
    verdict: RunVerdict | None = None,
    comparison: Comparison | None = None,
    *,
    panels: SignalPanels | None = None,
    data: Sequence[Mapping[str, Any]] | None = None,
) -> dict[str, Any]:
    """The report.json document: every spec result's JSON (``data``, ``to_dict`` of each
    result where not given) with each signal's diagnosis and trend beside it, the summary
    (with the run's verdict, ``summary.passed``), the worst-signal table, the campaigns'
    verdicts and, when the run decided one, ``verdict``: its regressions against the baseline
    and the specs that could not be scored; and the ``comparison`` with the baseline when one
    ran."""
    panels = panels if panels is not None else SignalPanels()
    found = data if data is not None else [result.to_dict() for result in results]
    campaigns = model.campaigns_of(results, verdict)
    return {
        "report_schema_version": REPORT_SCHEMA_VERSION,
        "generated_by": f"pytest-hevval {__version__}",
        "summary": model.summary(results, verdict),
        **({"verdict": verdict.to_dict()} if verdict is not None else {}),
        **({"comparison": comparison.to_dict()} if comparison is not None else {}),
        "worst": _worst_json(results),
        "specs": [
            panels.decorate(result, item) for result, item in zip(results, found, strict=True)
        ],
        **({"campaigns": [v.to_dict() for v in campaigns]} if campaigns else {}),
    }


def render_json(
    results: Sequence[SpecResult],
    verdict: RunVerdict | None = None,
    comparison: Comparison | None = None,
    *,
    panels: SignalPanels | None = None,
    data: Sequence[Mapping[str, Any]] | None = None,
) -> str:
    """report.json: :func:`report_document` as text.

    Keys are sorted and separators fixed, so equal results give byte-identical files.
    """
    payload = report_document(results, verdict, comparison, panels=panels, data=data)
    options: dict[str, Any] = {
        "sort_keys": True,
        "ensure_ascii": False,
        "allow_nan": False,
        "separators": (",", ":"),
    }
    try:
        # Fast path: plain data goes straight to the C encoder; only numpy values and paths
        # need the hook. Walking tens of MB of figure data in Python would take many seconds.
        text = json.dumps(payload, default=_json_default, **options)
    except ValueError:  # NaN or inf somewhere: clean the whole tree
        text = json.dumps(plain_json(payload), **options)
    return text + "\n"


def _campaign_markdown(verdicts: Sequence[CampaignVerdict]) -> list[str]:
    lines: list[str] = []
    for found in verdicts:
        mark = "✅" if found.passed else "❌"
        lines += [
            "",
            f"**{mark} campaign {_md(found.name)}** ({_code(found.spec)}): "
            f"pass rate {_percent(found.pass_rate)} of the validation recordings"
            + (
                f" (min {_percent(found.min_pass_rate)})" if found.min_pass_rate is not None else ""
            ),
            "",
        ]
        if found.excluded:
            lines += [
                "Excluded from the gate (calibration): "
                + ", ".join(_code(r) for r in found.excluded),
                "",
            ]
        if found.unused_models:
            lines += [
                "Model output files no recording uses: "
                + ", ".join(_code(r) for r in found.unused_models),
                "",
            ]
        lines += ["| recording | role | Φ | failing signals |", "|---|---|--:|---|"]
        for recording in found.recordings:
            failing = ", ".join(_code(s) for s in recording.failed_signals) or "—"
            lines.append(
                f"| {'✅' if recording.passed else '❌'} {_md(recording.id)} "
                f"| {recording.role} | {_phi_cell(recording)} | {failing} |"
            )
        lines += [
            "",
            "| signal | pass rate | u-pooling area |",
            "|---|--:|--:|",
            *(
                f"| {_code(path)} | {_percent(rate)} | {_num(found.pooled_area.get(path), 3)} |"
                for path, rate in found.signal_pass_rates.items()
            ),
        ]
        if found.failures:
            lines += ["", *(f"- gate: {_md(failure)}" for failure in found.failures)]
    return lines


def _percent(value: object) -> str:
    return f"{float(value):.0%}" if model.is_finite_number(value) else "—"


def _json_default(value: Any) -> Any:
    cleaned = plain_json(value)
    if isinstance(cleaned, str) and not isinstance(value, (str, PurePath)):
        raise TypeError(f"not JSON serialisable: {type(value).__name__}")
    return cleaned


def _num(value: object, digits: int = 4) -> str:
    return f"{float(value):.{digits}f}" if model.is_finite_number(value) else "—"


def _phi_cell(recording: RecordingOutcome) -> str:
    """A campaign recording's Φ with its interval, marked where the interval holds min_phi."""
    interval = recording.phi_interval
    text = _num(recording.phi)
    if interval is not None:
        text += f" [{_num(interval.low)}, {_num(interval.high)}]"
    return text + (" (within noise of min_phi)" if recording.within_noise else "")


def _md(text: object) -> str:
    """Text safe inside a GitHub Markdown table cell (no table breaks, no raw HTML)."""
    return markdown(text)


def _code(text: object) -> str:
    return markdown_code(text)


def _phi(spec: SpecResult) -> str:
    """Φ with its 95 % interval where the result carries one: ``0.9248 [0.9225, 0.9272]``."""
    low, high = model.interval_bounds(spec.phi_interval)
    bounds = f" [{_num(low)}, {_num(high)}]" if low is not None else ""
    return f"{_num(spec.phi)}{bounds}"


def _min_phi(spec: SpecResult) -> str:
    return f"{_num(spec.min_phi)}{model.min_phi_bound(spec)}"


def _below(signal: SignalResult) -> list[str]:
    parts = []
    for c in model.cells(signal):
        if c.status == "fail":
            threshold = f" < {_num(c.threshold, 3)}" if c.threshold is not None else ""
            parts.append(
                f"{c.label} {model.LABELS[c.characteristic]} {_num(c.value, 3)}{threshold}"
            )
    return parts


def _where(signal: SignalResult) -> tuple[bool, list[str]]:
    """Whether the error appears in ``signal`` itself, and the other signals it appears in."""
    path = signal.path
    origins = [str(o) for o in signal.origins]
    others = [o for o in origins if o != path]
    here = signal.origin or path in origins or not origins
    return here, others


def _where_text(signal: SignalResult) -> str:
    here, others = _where(signal)
    return ", ".join((["here"] if here else []) + others)


def _measurement_markdown(spec_results: Sequence[SpecResult]) -> list[str]:
    """Each miss checked against a declared measurement uncertainty, per spec."""
    lines: list[str] = []
    for spec in spec_results:
        found = [
            (signal, text)
            for signal in model.ordered_signals(spec)
            for text in model.measurement_lines(signal)
        ]
        if not found:
            continue
        lines += ["", f"**Measurement uncertainty of {_md(spec.name)}**", ""]
        lines += [f"- {_code(signal.path)}: {_md(text)}" for signal, text in found]
    return lines


def _standard_metrics_markdown(spec_results: Sequence[SpecResult]) -> list[str]:
    """A "standard metrics" table per spec that switched any on, one row per signal and metric."""
    lines: list[str] = []
    for spec in spec_results:
        rows = [
            (signal, row)
            for signal in model.ordered_signals(spec)
            for row in model.standard_metric_rows(signal)
        ]
        if not rows:
            continue
        lines += [
            "",
            f"**Standard metrics of {_md(spec.name)}**",
            "",
            "| signal | metric | score | threshold | components |",
            "|---|---|--:|--:|---|",
        ]
        for signal, row in rows:
            gate = _num(row.cell.threshold, 3) if row.cell.threshold is not None else "—"
            lines.append(
                f"| {_code(signal.path)} | {_md(row.cell.label)} {_md(row.title)} "
                f"| {_num(row.cell.value)} | {gate} | {_md(row.components_text())} |"
            )
    return lines


def _runtime_markdown(spec_results: Sequence[SpecResult]) -> list[str]:
    """The model's runtime per spec that ran its model (a callable or an FMU)."""
    from .terminal import runtime_of, runtime_text

    rows = []
    for spec in spec_results:
        runtime, kind = runtime_of(spec)
        if runtime is None and kind != "file":
            continue
        failures = runtime.failures() if runtime is not None else []
        mark = "❌ " if failures else "✅ " if runtime is not None and runtime.gate else ""
        gate = "; ".join(failures) or ("met" if mark else "—")
        rows.append(
            f"| {mark}{_md(spec.name)} | {_md(runtime_text(runtime, kind))} | {_md(gate)} |"
        )
    if not rows:
        return []
    return ["", "**Model runtime**", "", "| spec | runtime | gate |", "|---|---|---|", *rows]


def headline(spec_results: Sequence[SpecResult], verdict: RunVerdict | None) -> str:
    """The Markdown headline of a run: its verdict in one line."""
    counts = model.summary(spec_results, verdict)
    return f"### {'✅' if counts['passed'] else '❌'} hevval: {_md(counts['outcome'])}"


def render_markdown(
    spec_results: Sequence[SpecResult],
    verdict: RunVerdict | None = None,
    comparison: Comparison | None = None,
) -> str:
    """A short summary for a GitHub step summary or PR comment; its headline is the run's
    verdict (``verdict``, else the verdict of the results alone). With ``comparison`` (the
    comparison with the baseline) and ``verdict``, the comparison follows the spec table
    (:mod:`.comparison`)."""
    regressed = verdict.regressed if verdict is not None else {}
    lines = [
        headline(spec_results, verdict),
        "",
        "| | spec | Φ | min Φ | failing signals |",
        "|:-:|---|--:|--:|--:|",
    ]
    for spec in spec_results:
        failing_paths = {s.path for s in model.failing_signals(spec)}
        worse = regressed.get(spec.spec, frozenset())
        # A signal failed by a regression counts as failing, as its item does.
        failing_paths |= {path for path in worse if path is not None}
        failed = not spec.passed or bool(worse)
        lines.append(
            f"| {'❌' if failed else '✅'} | {_md(spec.name)} "
            f"| {_phi(spec)} | {_num(spec.min_phi)} "
            f"| {len(failing_paths)} / {len(spec.signals)} |"
        )
    if verdict is not None and comparison is not None:
        from .comparison import comparison_markdown

        lines += ["", *comparison_markdown(comparison, verdict)]
    if verdict is not None:
        lines += _verdict_markdown(verdict, regressions=comparison is None)
    for spec in spec_results:
        failing = model.failing_signals(spec)
        if spec.passed and not failing:
            continue
        relation = "<" if model.phi_failed(spec) else "≥"
        mark = "❌" if not spec.passed else "✅"
        lines += [
            "",
            f"**{mark} {_md(spec.name)}** — Φ {_phi(spec)} {relation} min Φ "
            f"{_min_phi(spec)} ({_code(spec.spec)})",
        ]
        if not failing:
            continue
        lines += ["", "| signal | below threshold | error appears in |", "|---|---|---|"]
        for signal in failing[:_MARKDOWN_SIGNALS]:
            where = f" (line {signal.line})"
            below = "; ".join(_below(signal)) or "—"
            places = _md(_where_text(signal))
            lines.append(f"| {_code(signal.path)}{where} | {_md(below)} | {places} |")
        if len(failing) > _MARKDOWN_SIGNALS:
            lines.append(f"| … and {len(failing) - _MARKDOWN_SIGNALS} more (see report.html) | | |")
    lines += _measurement_markdown(spec_results)
    lines += _standard_metrics_markdown(spec_results)
    lines += _campaign_markdown(model.campaigns_of(spec_results, verdict))
    lines += _runtime_markdown(spec_results)
    from .trace import trace_markdown_section, trace_rows

    trace = trace_rows(spec_results)
    if trace:
        lines += ["", *trace_markdown_section(trace, heading="**Requirements**")]
    lines += ["", f"<sub>pytest-hevval {__version__}</sub>"]
    for spec in spec_results:
        quality = model.data_quality(spec)
        if not quality or not quality.get("findings"):
            continue
        lines += [
            "",
            f"**Data quality of {_md(spec.name)}** ({quality.get('action', 'warn')}): "
            "the measurement, not the model",
            "",
        ]
        for found in quality["findings"]:
            lines.append(
                f"- {_code(str(found['channel']))}: {_md(str(found['kind']))} at "
                f"{found['start_s']:.6g}–{found['stop_s']:.6g} s ({_md(str(found['detail']))})"
            )
    return "\n".join(lines) + "\n"


def regression_lines(verdict: RunVerdict) -> list[str]:
    """The run's regressions as a Markdown list (the first fifteen; all in report.json)."""
    count = len(verdict.regressions)
    lines = [f"- {_md(item.text)}" for item in verdict.regressions[:_MARKDOWN_SIGNALS]]
    if count > _MARKDOWN_SIGNALS:
        lines.append(f"- … and {count - _MARKDOWN_SIGNALS} more (see report.json)")
    return lines


def _verdict_markdown(verdict: RunVerdict, *, regressions: bool) -> list[str]:
    """The regressions against the baseline (when ``regressions``: no comparison lists them)
    and the specs that could not be scored."""
    lines: list[str] = []
    if verdict.regressions and regressions:
        count = len(verdict.regressions)
        against = f" against {_md(verdict.baseline)}" if verdict.baseline else ""
        accepted = (
            " (accepted with --hevval-accept: reported, not failed)"
            if verdict.regressions_accepted
            else ""
        )
        lines += [
            "",
            f"**{'⚠️' if verdict.regressions_accepted else '❌'} {count} "
            f"regression{'s' * (count != 1)}{against}**{accepted}",
            "",
            *regression_lines(verdict),
        ]
    if verdict.errors:
        lines += ["", "**❌ Could not be scored**", ""]
        lines += [f"- {_md(error)}" for error in verdict.errors]
    return lines


def render_comparison(
    spec_results: Sequence[SpecResult], verdict: RunVerdict, comparison: Comparison
) -> str:
    """comparison.md: the run's headline and its comparison with the baseline, alone, for a
    workflow that posts just that as a pull-request comment."""
    from .comparison import comparison_markdown

    lines = [headline(spec_results, verdict), "", *comparison_markdown(comparison, verdict)]
    return "\n".join([*lines, "", f"<sub>pytest-hevval {__version__}</sub>"]) + "\n"


def _escape_data(text: str) -> str:
    return text.replace("%", "%25").replace("\r", "%0D").replace("\n", "%0A")


def _escape_property(text: str) -> str:
    return _escape_data(text).replace(":", "%3A").replace(",", "%2C")


def _relative(spec_path: str, rootdir: Path | str) -> str:
    path = Path(spec_path)
    if path.is_absolute():
        with contextlib.suppress(ValueError):
            path = path.resolve().relative_to(Path(rootdir).resolve())
    return path.as_posix()


def github_annotations(spec_results: Sequence[SpecResult], rootdir: Path | str) -> list[str]:
    """``::error`` workflow commands pointing at the spec line of every failing signal.

    A spec whose Φ is below min Φ gets one more, file-level annotation first. Within a spec the
    worst signals come first, because GitHub shows only the first few annotations of a step.
    """
    out: list[str] = []
    for spec in spec_results:
        name = spec.name
        file = _escape_property(_relative(split_key(spec.spec)[0], rootdir))
        if model.phi_failed(spec):
            message = f"{name}: Φ {_phi(spec)} is below min Φ {_min_phi(spec)}"
            out.append(f"::error file={file},title=hevval::{_escape_data(message)}")
        for signal in model.failing_signals(spec):
            below = "; ".join(_below(signal)) or "failed"
            here, others = _where(signal)
            places = (["this signal"] if here else []) + others
            origin = "the error appears in " + " and ".join(places)
            message = f"{name}: {signal.path}: {below} ({origin})"
            line = signal.line
            location = f",line={line}" if line > 0 else ""
            out.append(f"::error file={file}{location},title=hevval::{_escape_data(message)}")
    return out
