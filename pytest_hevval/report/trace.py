"""Traceability: each requirement → the specs and signals that verify it → their verdict.

A spec's ``requirements`` are verified by the spec as a whole (Φ and every signal); a signal's
by that signal (and its descendants, which inherit them). One row per requirement and spec
result says which items verify it there, whether they pass, Φ with its interval, the model
version and the data. Given the team's list of requirement IDs, a requirement that no item
verifies is listed as uncovered (docs/reports.md, "Traceability").
"""

from __future__ import annotations

import csv
import html
import io
import json
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..core.uncertainty import Interval, value_text
from ..defaults import requirement_id_problem
from ..errors import HevvalError
from ..files import read_input
from ..results.spec_facts import FileData, ModelData
from ..results.spec_result import SpecResult
from .text import _md

__all__ = [
    "TraceRow",
    "read_requirement_list",
    "render_trace",
    "trace_markdown_section",
    "trace_rows",
]

#: Header cells a team's CSV list may start with (its first column names the IDs).
_HEADER_CELLS = frozenset({"id", "requirement", "requirements", "requirement id", "key"})
#: What the spec itself (rather than one signal) is called in a row's items.
WHOLE_SPEC = "whole spec (Φ and every signal)"


@dataclass(frozen=True)
class TraceRow:
    """One requirement in one spec result, or a listed requirement nothing verifies."""

    requirement: str
    #: None: an uncovered requirement (no spec or signal verifies it).
    spec: str | None = None
    spec_file: str | None = None
    #: Signal paths verifying the requirement here; empty with ``whole_spec``.
    signals: tuple[str, ...] = ()
    whole_spec: bool = False
    passed: bool | None = None
    phi: float | None = None
    phi_low: float | None = None
    phi_high: float | None = None
    model_version: str | None = None
    reference: str | None = None
    reference_digest: str | None = None
    model: str | None = None
    #: False: linked in a spec but missing from the team's list (a typo, or a list to update).
    listed: bool = True

    @property
    def status(self) -> str:
        if self.passed is None:
            return "UNCOVERED"
        return "PASS" if self.passed else "FAIL"

    @property
    def items(self) -> str:
        return WHOLE_SPEC if self.whole_spec else ", ".join(self.signals)

    @property
    def phi_text(self) -> str:
        if self.phi is None:
            return "—"
        known = self.phi_low is not None and self.phi_high is not None
        interval = Interval(self.phi, self.phi_low, self.phi_high) if known else None  # type: ignore[arg-type]
        return value_text(self.phi, interval)

    def to_dict(self) -> dict[str, Any]:
        return {
            "requirement": self.requirement,
            "status": self.status,
            "spec": self.spec,
            "spec_file": self.spec_file,
            "items": ["Phi", *self.signals] if self.whole_spec else list(self.signals),
            "whole_spec": self.whole_spec,
            "passed": self.passed,
            "phi": self.phi,
            "phi_interval": None
            if self.phi_low is None or self.phi_high is None
            else {"low": self.phi_low, "high": self.phi_high},
            "model_version": self.model_version,
            "reference": self.reference,
            "reference_digest": self.reference_digest,
            "model": self.model,
            "listed": self.listed,
        }


def _model_text(model: ModelData | None) -> str | None:
    if model is None:
        return None
    if model.callable:
        return f"callable {model.callable}"
    return None if model.path is None else f"{model.kind or 'file'} {model.path}"


def _digest_text(source: FileData | None) -> str | None:
    if source is None or not source.digest:
        return None
    return f"{source.hash or ''}:{source.digest}".lstrip(":")


def trace_rows(
    spec_results: Sequence[SpecResult],
    *,
    model_version: str | None = None,
    versions: Mapping[str, str] | None = None,
    listed: Iterable[str] | None = None,
) -> list[TraceRow]:
    """The traceability rows of a run's spec results, requirement by requirement.

    ``listed``: the team's requirement IDs; those no item verifies become uncovered rows,
    and linked IDs not among them are marked ``listed=False``. ``versions``: the model
    version of each result by its ``spec`` key (a history's newest result of each spec was
    recorded by its own run), which wins over ``model_version``.
    """
    team = list(dict.fromkeys(listed)) if listed is not None else None
    versions = versions or {}
    rows: list[TraceRow] = []
    for spec in spec_results:
        whole = [str(r) for r in spec.requirements]
        by_requirement: dict[str, list[str]] = {}
        for signal in spec.signals:
            for requirement in signal.requirements:
                if requirement not in whole:
                    by_requirement.setdefault(str(requirement), []).append(signal.path)
        signals = {s.path: s for s in spec.signals}
        reference = spec.data.reference
        interval = spec.phi_interval
        facts: dict[str, Any] = {
            "spec": spec.name,
            "spec_file": spec.spec,
            "phi": spec.phi,
            "phi_low": interval.low if interval is not None else None,
            "phi_high": interval.high if interval is not None else None,
            "model_version": versions.get(spec.spec, model_version),
            "reference": reference.path if reference is not None else None,
            "reference_digest": _digest_text(reference),
            "model": _model_text(spec.data.model),
        }
        for requirement in whole:
            rows.append(
                TraceRow(
                    requirement=requirement,
                    whole_spec=True,
                    passed=spec.passed,
                    listed=team is None or requirement in team,
                    **facts,
                )
            )
        for requirement, paths in by_requirement.items():
            rows.append(
                TraceRow(
                    requirement=requirement,
                    signals=tuple(paths),
                    passed=all(signals[p].passed for p in paths),
                    listed=team is None or requirement in team,
                    **facts,
                )
            )
    covered = {row.requirement for row in rows}
    rows += [TraceRow(requirement=r) for r in team or () if r not in covered]
    order = {r: i for i, r in enumerate(team or ())}
    return sorted(rows, key=lambda row: (order.get(row.requirement, len(order)), row.requirement))


def read_requirement_list(path: Path | str) -> list[str]:
    """The team's requirement IDs: one a line, or the first column of a CSV file.

    Blank lines and lines starting with ``#`` are skipped, and a CSV header row (``id``,
    ``requirement``, ``key``) too. A bad or repeated ID is an error naming the file and line.
    """
    file = str(path)
    try:
        text = read_input(path).decode("utf-8-sig")
    except OSError as exc:
        raise HevvalError(
            f"cannot read the requirement list ({exc.strerror or exc})",
            file=file,
            hint="pass a text file with one requirement ID a line, or a CSV file",
        ) from None
    except UnicodeDecodeError as exc:
        raise HevvalError(
            f"the requirement list is not UTF-8 text (byte {exc.start})",
            file=file,
            hint="save it as UTF-8",
        ) from None
    found: dict[str, int] = {}
    for number, cells in enumerate(csv.reader(io.StringIO(text)), start=1):
        first = cells[0].strip() if cells else ""
        if not first or first.startswith("#"):
            continue
        if not found and len(cells) > 1 and first.lower() in _HEADER_CELLS:
            continue
        problem = requirement_id_problem(first)
        if problem is not None:
            raise HevvalError(
                f"{problem} (got {first!r})", file=file, line=number, hint="one ID a line"
            )
        if first in found:
            raise HevvalError(
                f"requirement {first!r} is listed twice (first at line {found[first]})",
                file=file,
                line=number,
                hint="list each requirement once",
            )
        found[first] = number
    if not found:
        raise HevvalError(
            "the requirement list holds no ID",
            file=file,
            hint="one requirement ID a line, or a CSV file whose first column holds them",
        )
    return list(found)


_COLUMNS = ("requirement", "status", "spec", "items", "Φ [95 % interval]", "model version", "data")


def _cells(row: TraceRow) -> list[str]:
    data = row.reference or "—"
    if row.reference_digest:
        data += f" ({row.reference_digest})"
    note = "" if row.listed else " (not in the list)"
    return [
        row.requirement + note,
        row.status,
        row.spec or "—",
        row.items or "—",
        row.phi_text,
        row.model_version or "—",
        data,
    ]


def _summary(rows: Sequence[TraceRow]) -> str:
    requirements: dict[str, str] = {}
    for row in rows:
        # A requirement fails when any of its rows fails; uncovered only when it has no row.
        current = requirements.get(row.requirement)
        if current is None or row.status == "FAIL":
            requirements[row.requirement] = row.status
    counts = {s: sum(1 for v in requirements.values() if v == s) for s in ("PASS", "FAIL")}
    uncovered = sum(1 for v in requirements.values() if v == "UNCOVERED")
    many = "s" * (len(requirements) != 1)
    text = f"{len(requirements)} requirement{many}: {counts['PASS']} pass, {counts['FAIL']} fail"
    return text + (f", {uncovered} uncovered" if uncovered else "")


def render_trace(rows: Sequence[TraceRow], fmt: str) -> str:
    """The traceability rows as a terminal table, Markdown, CSV, a standalone HTML page or
    JSON."""
    if fmt == "json":
        document = {"summary": _summary(rows), "rows": [row.to_dict() for row in rows]}
        return json.dumps(document, indent=2, ensure_ascii=False, allow_nan=False) + "\n"
    if fmt == "csv":
        out = io.StringIO()
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow(_COLUMNS)
        writer.writerows(_cells(row) for row in rows)
        return out.getvalue()
    if fmt == "md":
        return "\n".join(trace_markdown_section(rows, heading="### Traceability")) + "\n"
    if fmt == "html":
        return _html(rows)
    table = [list(_COLUMNS), *(_cells(row) for row in rows)]
    widths = [max(len(line[i]) for line in table) for i in range(len(_COLUMNS))]
    lines = [
        "  ".join(cell.ljust(w) for cell, w in zip(line, widths, strict=True)) for line in table
    ]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join([*(line.rstrip() for line in lines), "", _summary(rows)]) + "\n"


def trace_markdown_section(rows: Sequence[TraceRow], *, heading: str) -> list[str]:
    """The rows as a Markdown table under ``heading`` (report.md's requirements section)."""
    lines = [heading, "", _summary(rows), "", "| " + " | ".join(_COLUMNS) + " |"]
    lines.append("|" + "---|" * len(_COLUMNS))
    lines += ["| " + " | ".join(_md(c) for c in _cells(row)) + " |" for row in rows]
    return lines


def _html(rows: Sequence[TraceRow]) -> str:
    head = "".join(f"<th>{html.escape(c)}</th>" for c in _COLUMNS)
    body = "".join(
        f'<tr class="{row.status.lower()}">'
        + "".join(f"<td>{html.escape(cell)}</td>" for cell in _cells(row))
        + "</tr>\n"
        for row in rows
    )
    return (
        '<!doctype html>\n<html lang="en"><head><meta charset="utf-8">'
        "<title>hevval traceability</title><style>"
        "body{font-family:system-ui,sans-serif;margin:24px}table{border-collapse:collapse}"
        "td,th{border:1px solid #d0d7de;padding:4px 8px;text-align:left;vertical-align:top}"
        "tr.fail td:nth-child(2){color:#cf222e;font-weight:600}"
        "tr.pass td:nth-child(2){color:#1a7f37;font-weight:600}"
        "tr.uncovered td:nth-child(2){color:#9a6700;font-weight:600}"
        "</style></head><body>\n<h1>Traceability</h1>\n"
        f"<p>{html.escape(_summary(rows))}</p>\n"
        f"<table><thead><tr>{head}</tr></thead><tbody>\n{body}</tbody></table>\n"
        "</body></html>\n"
    )
