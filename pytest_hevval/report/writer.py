"""Writing report files: the ``report`` option's grammar and atomic writes.

The writers take the typed results; report.json alone is made from the results' JSON
(:func:`.text.report_document`), at the file it is written to. A message about the option
names it as the front end in use spells it (:mod:`pytest_hevval.flags`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from ..errors import HevvalError, did_you_mean
from ..files import output_error, write_atomic
from ..flags import PYTEST, FrontEnd
from ..results.changes import Comparison
from ..results.spec_result import SpecResult
from ..results.verdict import RunVerdict
from .panels import SignalPanels

__all__ = [
    "COMPARISON_FILE",
    "FILE_NAMES",
    "FORMATS",
    "ReportOptionError",
    "parse_formats",
    "write_reports",
]

#: Report formats in the order they are written, with their file names.
FILE_NAMES: dict[str, str] = {
    "html": "report.html",
    "json": "report.json",
    "md": "report.md",
    "evidence": "evidence.json",
}
FORMATS: tuple[str, ...] = tuple(FILE_NAMES)
#: The comparison with the baseline alone, written beside report.md when a comparison ran.
COMPARISON_FILE = "comparison.md"
_ALIASES = {"markdown": "md", "htm": "html"}


class ReportOptionError(HevvalError, ValueError):
    """A ``report`` option's value names no known format."""


def parse_formats(value: str, front_end: FrontEnd = PYTEST) -> set[str]:
    """Formats named in a comma-separated ``report`` value, e.g. ``"html,json,md"``.

    Names are case-insensitive and may repeat; ``markdown`` means ``md``. Messages name the
    option as ``front_end`` spells it.

    Raises
    ------
    ReportOptionError
        An empty value or an unknown name.
    """
    names = [part.strip().lower() for part in value.split(",")]
    names = [_ALIASES.get(name, name) for name in names if name]
    choices = ", ".join(FORMATS)
    flag = front_end.flag("report")
    if not names:
        raise ReportOptionError(
            f"{flag}: expected a comma-separated list of formats (got {value!r})",
            hint=f"choose from {choices}, e.g. {flag}=html,json,md",
        )
    for name in names:
        if name not in FILE_NAMES:
            suggestion = did_you_mean(name, FORMATS)
            raise ReportOptionError(
                f"{flag}: unknown report format {name!r} (choose from {choices})",
                hint=suggestion or None,
            )
    return set(names)


def write_reports(
    results: Sequence[SpecResult],
    formats: set[str],
    directory: Path,
    *,
    title: str = "hevval validation report",
    generated_utc: str | None = None,
    verdict: RunVerdict | None = None,
    comparison: Comparison | None = None,
    facts: Mapping[str, Any] | None = None,
    panels: SignalPanels | None = None,
    data: Sequence[Mapping[str, Any]] | None = None,
    front_end: FrontEnd = PYTEST,
) -> list[Path]:
    """Write report.html / report.json / report.md / evidence.json for ``formats`` into
    ``directory``; each says ``verdict``, the run's (else the verdict of the results alone).
    With ``comparison`` (the comparison with the baseline) and a
    verdict, report.json and report.md carry it, and with ``md`` it is also written alone to
    comparison.md. ``facts`` are the run's model version, start and tool versions, which the
    evidence record holds (docs/evidence.md). ``panels``: each signal's diagnosis and history
    trend. ``data``: the results' JSON (``SpecResult.to_dict`` of each, in order) where the
    caller holds it already; report.json is written from it.

    The directory is created if needed; each file is replaced atomically. Returns the written
    paths in the order html, json, md.
    """
    unknown = sorted(set(formats) - set(FILE_NAMES))
    if unknown:
        raise ReportOptionError(
            f"{front_end.flag('report')}: unknown report format {unknown[0]!r} "
            f"(choose from {', '.join(FORMATS)})"
        )
    panels = panels if panels is not None else SignalPanels()
    directory = Path(directory)
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise output_error(directory, exc) from None
    stamp = generated_utc or datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")
    written: list[Path] = []
    for name in FORMATS:
        if name not in formats:
            continue
        if name == "html":
            from .html import render_html

            text = render_html(
                results,
                title=title,
                generated_utc=stamp,
                formats=formats,
                verdict=verdict,
                panels=panels,
            )
        elif name == "json":
            from .text import render_json

            text = render_json(results, verdict, comparison, panels=panels, data=data)
        elif name == "evidence":
            from .evidence import render_evidence

            text = render_evidence(results, facts or {}, source="pytest run", verdict=verdict)
        else:
            from .text import render_markdown

            text = render_markdown(results, verdict, comparison)
        path = directory / FILE_NAMES[name]
        write_atomic(path, text)
        written.append(path)
    compared = "md" in formats and comparison is not None and verdict is not None
    if "md" in formats and comparison is not None and verdict is not None:
        from .text import render_comparison

        path = directory / COMPARISON_FILE
        write_atomic(path, render_comparison(results, verdict, comparison))
        written.append(path)
    # A report of an earlier run beside this run's would be read as this run's: only this
    # run's reports stay (the report files' own names only; nothing else is touched).
    left = [name for kind, name in FILE_NAMES.items() if kind not in formats]
    for file_name in [*left, *([] if compared else [COMPARISON_FILE])]:
        stale = directory / file_name
        try:
            if stale.is_file() and not stale.is_symlink():
                stale.unlink()
        except OSError as exc:
            raise output_error(stale, exc) from None
    return written
