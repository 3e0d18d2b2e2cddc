"""``hevval history`` and ``hevval compare``: argparse front ends returning exit codes.

Exit codes: 0 success; 1 regressions found (``compare --fail``) or no matching records
(``history``); 2 bad arguments or unreadable input.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ..errors import did_you_mean
from ..files import write_atomic
from ._base import HistoryError
from .compare import (
    Comparison,
    campaign_change_lines,
    compare,
    parse_compare_fail,
    regressions,
    specs_of,
)
from .records import migrate_record
from .render import render
from .store import HistoryStore
from .trends import (
    HistoryRow,
    characteristic_names,
    detect_steps,
    history_table,
    plot_history,
    render_history_table,
    row_series,
)

__all__ = ["compare_main", "history_main", "load_side", "run_compare", "run_history"]

_HISTORY_PREFIX = "history:"


def _write(text: str, output: str | None) -> None:
    if output is None or output == "-":
        sys.stdout.write(text)
        return
    try:
        write_atomic(output, text)
    except OSError as exc:
        raise HistoryError(
            f"cannot write: {exc.strerror or exc}", file=output, hint="choose another --output"
        ) from None


def _report_problems(store: HistoryStore) -> None:
    for problem in store.problems:
        print(f"skipped {problem}", file=sys.stderr)


# -- hevval history -------------------------------------------------------------------------


def history_main(argv: Sequence[str]) -> int:
    """``hevval history ...``: kept for callers of the old entry point."""
    from ..cli import main

    return main(["history", *argv])


def run_history(args: argparse.Namespace) -> int:
    """``hevval history``: Φ and the characteristics over the recorded model versions."""
    store = HistoryStore(Path(args.history_dir))
    records = store.records()
    _report_problems(store)
    rows = history_table(records, spec=args.spec, signal=args.signal)
    if not rows:
        what = "no readable records" if not records else "no recorded runs match"
        print(f"hevval history: {what} in {args.history_dir}", file=sys.stderr)
        return 1
    if args.json is not None:
        document = {"rows": [row.to_dict() for row in rows]}
        _write(json.dumps(document, indent=2, ensure_ascii=False) + "\n", args.json)
    if args.json != "-":
        sys.stdout.write(render_history_table(rows) + "\n")
        steps = _step_report(rows, args.min_step)
        if steps:
            sys.stdout.write("\n" + "\n".join(steps) + "\n")
    if args.plot is not None:
        plot_history(rows, Path(args.plot))
        print(f"wrote {args.plot}", file=sys.stderr)
    return 0


def _step_report(rows: Sequence[HistoryRow], min_size: float) -> list[str]:
    lines = []
    for (spec, signal), series in row_series(rows).items():
        fields = ["phi"] if signal is None else ["phi", *characteristic_names(series)]
        for field in fields:
            steps = detect_steps(
                [r.value(field) for r in series],
                min_size=min_size,
                intervals=[r.interval(field) for r in series],
            )
            for step in steps:
                if not step.regression:
                    continue
                at = series[step.index]
                label = "Φ" if field == "phi" else field
                where = spec if signal is None else f"{spec}::{signal}"
                lines.append(
                    f"drop: {where} {label} {step.before:.4f} → {step.after:.4f} "
                    f"from model version {at.model_version} ({at.started_utc[:10]})"
                )
    return sorted(set(lines))


# -- hevval compare -------------------------------------------------------------------------


def load_side(ref: str, directory: Path) -> tuple[list[Mapping[str, Any]], str]:
    """Resolve a compare operand to (spec results, label).

    ``ref`` is ``history:latest``, ``history:previous`` (the record before the latest),
    ``history:<model version>`` (looked up in ``directory``),
    a history record file, or a ``hevval run --json`` file (``{"specs": [...]}``).
    """
    if ref.startswith(_HISTORY_PREFIX):
        wanted = ref[len(_HISTORY_PREFIX) :]
        store = HistoryStore(directory)
        if wanted in ("latest", "previous"):
            entries = store.entries()
            position = -1 if wanted == "latest" else -2
            record = entries[position].record if len(entries) >= -position else None
        else:
            record = store.find(wanted)
        _report_problems(store)
        if record is None and wanted == "previous" and store.versions():
            raise HistoryError(
                f"only one readable record in {directory}",
                key=ref,
                hint="history:previous needs two recorded runs",
            )
        if record is None:
            versions = store.versions()
            if not versions:
                raise HistoryError(
                    f"no readable records in {directory}",
                    key=ref,
                    hint="point --dir at the history folder, or record runs first",
                )
            suggestion = did_you_mean(wanted, versions)
            raise HistoryError(
                f"no record of model version {wanted!r} in {directory}"
                + (f"; {suggestion}" if suggestion else ""),
                key=ref,
                hint="recorded versions: " + ", ".join(versions[-10:]),
            )
        return specs_of(record), record["model_version"]
    path = Path(ref)
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise HistoryError(
            "no such file",
            file=ref,
            hint="pass a JSON file, history:latest or history:<model version>",
        ) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise HistoryError(f"cannot read: {exc}", file=ref) from None
    except json.JSONDecodeError as exc:
        raise HistoryError(
            f"not valid JSON at line {exc.lineno}: {exc.msg}",
            file=ref,
            hint="pass the output of `hevval run --json` or a history record",
        ) from None
    if (
        isinstance(document, dict)
        and "schema_version" in document
        and ("model_version" in document or "results" in document)
    ):
        record = migrate_record(document, file=ref)
        return specs_of(record), record["model_version"]
    if isinstance(document, dict) and isinstance(document.get("specs"), list):
        version = document.get("model_version")
        return specs_of(document), version if isinstance(version, str) and version else path.name
    raise HistoryError(
        "neither a history record nor a run result (no 'specs' list)",
        file=ref,
        hint="pass the output of `hevval run --json` or a history record",
    )


def compare_main(argv: Sequence[str]) -> int:
    """``hevval compare ...``: kept for callers of the old entry point."""
    from ..cli import main

    return main(["compare", *argv])


def run_compare(args: argparse.Namespace) -> int:
    """``hevval compare``: two runs signal by signal, then Φ per spec."""
    rules = (
        parse_compare_fail(args.compare_fail, option="--compare-fail")
        if args.compare_fail is not None
        else None
    )
    directory = Path(args.history_dir)
    before, before_label = load_side(args.before, directory)
    after, after_label = load_side(args.after, directory)
    if before_label == after_label:
        before_label, after_label = f"{before_label} (before)", f"{after_label} (after)"
    # Two runs named on the command line are meant to be compared, so one spec against one
    # spec pairs even when the model version lives in the file name (trip-v1 → trip-v2).
    comparison = compare(
        after, before, before_label=before_label, after_label=after_label, pair_single=True
    )
    found = regressions(comparison, rules) if rules is not None else None
    text = _with_pairings(render(comparison, args.format, found), comparison, args.format)
    if args.format != "json":
        text += "".join(f"\n{line}\n" for line in campaign_change_lines(comparison))
    _write(text, args.output)
    return 1 if found else 0


def _with_pairings(text: str, comparison: Comparison, fmt: str) -> str:
    """Say under the title which different specs were compared and whose data changed; JSON
    carries ``pairings`` and each spec's ``data_changed``."""
    if fmt == "json" or not comparison.notes:
        return text
    title, _, rest = text.partition("\n")
    if fmt == "md":
        # A blank line ends the heading; two trailing spaces break lines inside the paragraph.
        notes = [note.replace("|", "\\|") for note in comparison.notes]
        return title + "\n\n" + "  \n".join(notes) + "\n" + rest
    return title + "\n" + "".join(note + "\n" for note in comparison.notes) + rest
