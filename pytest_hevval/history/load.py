"""The runs ``hevval compare`` is given: ``history:latest``, ``history:previous``,
``history:<model version>``, a history record file or a ``hevval run --json`` file."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from ..errors import did_you_mean
from ..files import read_json
from ..flags import COMMAND
from ..results.envelope import RunDocument, read_document
from ..results.recorded import RecordedRun
from ._base import HistoryError
from .store import HistoryStore

__all__ = [
    "HISTORY_PREFIX",
    "NAMED_BASELINES",
    "baseline_record",
    "baseline_run",
    "latest_results",
    "load_document",
    "load_side",
    "report_problems",
    "side_label",
]

#: How a compare operand names a recorded run.
HISTORY_PREFIX = "history:"
#: The records ``--hevval-compare`` and ``history:`` name by a word, not a model version: the
#: newest record, and the newest record accepted as a baseline.
NAMED_BASELINES = ("latest", "accepted")


def baseline_record(store: HistoryStore, wanted: str) -> dict[str, Any] | None:
    """The record ``wanted`` names: ``latest``, ``accepted`` or a model version."""
    if wanted == "latest":
        return store.latest()
    if wanted == "accepted":
        return store.accepted()
    return store.find(wanted)


def baseline_run(store: HistoryStore, wanted: str) -> RecordedRun | None:
    """The run :func:`baseline_record` names, as a comparison reads it."""
    record = baseline_record(store, wanted)
    return None if record is None else RecordedRun.from_json(record)


def report_problems(store: HistoryStore) -> None:
    """Say on stderr which records of the store could not be read."""
    for problem in store.problems:
        print(f"skipped {problem}", file=sys.stderr)


def latest_results(directory: Path) -> list[dict[str, Any]]:
    """The newest recorded result of every spec (and campaign recording) in the history, each
    with the ``model_version`` and ``started_utc`` of the run that recorded it: the latest
    verdict of each, where the newest run may have scored only some of them."""
    store = HistoryStore(directory)
    records = store.records()
    report_problems(store)
    if not records:
        raise HistoryError(
            f"no readable records in {directory}",
            hint=f"point {COMMAND.flag('history-dir')} at the history folder, or record runs first",
        )
    newest: dict[str, dict[str, Any]] = {}
    for record in reversed(records):
        for spec in record["specs"]:
            key = str(spec.get("spec", spec.get("name", "")))
            if key not in newest:
                newest[key] = {
                    **spec,
                    "model_version": record["model_version"],
                    "started_utc": record["started_utc"],
                }
    return list(newest.values())


def load_side(ref: str, directory: Path) -> tuple[RecordedRun, str]:
    """Resolve a compare operand to (the run, its label).

    ``ref`` is ``history:latest``, ``history:previous`` (the record before the latest),
    ``history:accepted`` (the newest record accepted as a baseline),
    ``history:<model version>`` (looked up in ``directory``),
    a history record file, or a ``hevval run --json`` file (``{"specs": [...]}``).
    """
    found = load_document(ref, directory)
    return found.recorded(), side_label(found, ref)


def side_label(found: RunDocument, ref: str) -> str:
    """How a comparison names the run ``ref`` gave: its model version, else (a run document
    without one) the file's name."""
    version = found.content.get("model_version")
    if found.kind != "record" and not (isinstance(version, str) and version):
        version = Path(ref).name
    return str(version)


def load_document(ref: str, directory: Path) -> RunDocument:
    """The whole run ``ref`` names (the forms of :func:`load_side`), read through the run
    envelope: a history record (migrated to the current schema), a ``hevval run --json``
    document or a report.json."""
    if ref.startswith(HISTORY_PREFIX):
        wanted = ref[len(HISTORY_PREFIX) :]
        store = HistoryStore(directory)
        if wanted == "previous":
            newest = store.newest(2)
            record = newest[-1].record if len(newest) == 2 else None
        else:
            record = baseline_record(store, wanted)
        report_problems(store)
        if record is None and wanted == "previous" and store.versions():
            raise HistoryError(
                f"only one readable record in {directory}",
                key=ref,
                hint="history:previous needs two recorded runs",
            )
        if record is None and wanted == "accepted" and store.versions():
            raise HistoryError(
                f"no record in {directory} is accepted as a baseline",
                key=ref,
                hint="accept a run with --hevval-accept (hevval run --accept), or compare "
                "with history:latest",
            )
        if record is None:
            versions = store.versions()
            if not versions:
                raise HistoryError(
                    f"no readable records in {directory}",
                    key=ref,
                    hint=f"point {COMMAND.flag('history-dir')} at the history folder, "
                    "or record runs first",
                )
            suggestion = did_you_mean(wanted, versions)
            raise HistoryError(
                f"no record of model version {wanted!r} in {directory}"
                + (f"; {suggestion}" if suggestion else ""),
                key=ref,
                hint="recorded versions: " + ", ".join(versions[-10:]),
            )
        return RunDocument("record", dict(record))
    path = Path(ref)
    try:
        document = read_json(path)
    except FileNotFoundError:
        raise HistoryError(
            "no such file",
            file=ref,
            hint="pass a JSON file, history:latest or history:<model version>",
        ) from None
    except OSError as exc:
        raise HistoryError(f"cannot read: {exc.strerror or exc}", file=ref) from None
    except json.JSONDecodeError as exc:
        raise HistoryError(
            f"not valid JSON at line {exc.lineno}: {exc.msg}",
            file=ref,
            hint="pass the output of `hevval run --json` or a history record",
        ) from None
    except ValueError as exc:  # not UTF-8, or nested too deep
        raise HistoryError(
            f"cannot read: {exc}",
            file=ref,
            hint="pass the output of `hevval run --json` or a history record",
        ) from None
    return read_document(document, file=ref)
