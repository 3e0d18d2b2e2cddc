"""An append-only folder of history records, safe for concurrent writers and parallel branches.

Layout: one file per run, ``<UTC time>_<model-version slug>_<8 hex>.json``, for example
``20240501T120000.123456Z_v1.4-3-gabc123_9f2c01ab.json``. Names sort by time, and the random
suffix means two writers (or two branches merged later) never pick the same name, which
sequential numbers cannot promise.

Writes are atomic: the JSON goes to a hidden temporary file in the same folder, is fsync'ed,
then hard-linked to its final name. ``os.link`` fails instead of replacing an existing file, so
a record is never overwritten; readers never see a half-written ``*.json``.
"""

from __future__ import annotations

import contextlib
import json
import re
import uuid
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Any

from ..defaults import HISTORY_DIR
from ..files import fsync_directory, publish, read_json, write_temporary
from ._base import HistoryError
from .records import migrate_record, parse_utc, validate_record

__all__ = ["DEFAULT_HISTORY_DIR", "HistoryStore", "StoreProblem", "StoredRecord", "slugify"]

DEFAULT_HISTORY_DIR = HISTORY_DIR
_SLUG_MAX = 40
_NAME_ATTEMPTS = 20


def slugify(version: str) -> str:
    """A file-name-safe form of a model version (letters, digits, ``.``, ``-``, ``+``)."""
    slug = re.sub(r"[^A-Za-z0-9.+-]+", "-", version).strip("-.")[:_SLUG_MAX].strip("-.")
    return slug or "unknown"


@dataclass(frozen=True)
class StoreProblem:
    """A file in the history folder that could not be read as a record."""

    path: Path
    message: str

    def __str__(self) -> str:
        return f"{self.path}: {self.message}"


@dataclass(frozen=True)
class StoredRecord:
    """A validated schema-2 record with the file it came from."""

    path: Path
    record: dict[str, Any]
    started_utc: datetime = field(compare=False)


class HistoryStore:
    """The history folder. Nothing here deletes or rewrites an existing record.

    ``problems`` lists the files skipped by the latest scan (unreadable, partial, or not a
    record), so that a bad file never hides the good ones and never raises.
    """

    def __init__(self, directory: Path | str) -> None:
        self.directory = Path(directory)
        self.problems: list[StoreProblem] = []

    def __repr__(self) -> str:
        return f"HistoryStore({str(self.directory)!r})"

    # -- writing ---------------------------------------------------------------------------

    def append(self, record: Mapping[str, Any]) -> Path:
        """Validate ``record`` and write it as a new file; return the file's path."""
        checked = validate_record(record)
        started = parse_utc(checked["started_utc"])
        payload = record_text(checked).encode("utf-8")
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise HistoryError(
                f"cannot create the history folder: {exc.strerror or exc}",
                file=str(self.directory),
                hint="choose a writable folder with --hevval-history-dir",
            ) from None
        stem = f"{started.strftime('%Y%m%dT%H%M%S.%fZ')}_{slugify(checked['model_version'])}"
        temp = self._write_temp(payload)
        try:
            for _ in range(_NAME_ATTEMPTS):
                final = self.directory / f"{stem}_{uuid.uuid4().hex[:8]}.json"
                if publish(temp, final, replace=False):
                    fsync_directory(self.directory)
                    return final
        except OSError as exc:
            raise _write_error(self.directory, exc) from None
        finally:
            with contextlib.suppress(FileNotFoundError):
                temp.unlink()
        raise HistoryError(  # pragma: no cover - 20 uuid4 collisions in a row
            "could not find a free file name for the record",
            file=str(self.directory),
        )

    def _write_temp(self, payload: bytes) -> Path:
        try:
            return write_temporary(self.directory, payload, stem="record")
        except OSError as exc:
            raise HistoryError(
                f"cannot write to the history folder: {exc.strerror or exc}",
                file=str(self.directory),
                hint="choose a writable folder with --hevval-history-dir",
            ) from None

    # -- reading ---------------------------------------------------------------------------

    def entries(self) -> list[StoredRecord]:
        """Every readable record with its path, oldest first; fills :attr:`problems`."""
        self.problems = []
        if not self.directory.is_dir():
            return []
        found: list[StoredRecord] = []
        for path in sorted(self.directory.glob("*.json")):
            try:
                document = read_json(path)
            except OSError as exc:
                self.problems.append(StoreProblem(path, f"unreadable: {exc.strerror or exc}"))
                continue
            except json.JSONDecodeError as exc:
                problem = (
                    "empty file (a write may be in progress)"
                    if not exc.doc.strip()
                    else f"not valid JSON at line {exc.lineno}: {exc.msg}"
                )
                self.problems.append(StoreProblem(path, problem))
                continue
            except ValueError as exc:  # not UTF-8, or nested too deep
                self.problems.append(StoreProblem(path, f"unreadable: {exc}"))
                continue
            try:
                record = migrate_record(document, file=str(path))
            except HistoryError as exc:
                self.problems.append(StoreProblem(path, exc.problem))
                continue
            found.append(StoredRecord(path, record, parse_utc(record["started_utc"])))
        found.sort(key=lambda entry: (entry.started_utc, entry.path.name))
        return found

    def records(self) -> list[dict[str, Any]]:
        """Every readable record, oldest first; unreadable files go to :attr:`problems`."""
        return [entry.record for entry in self.entries()]

    def latest(self, before: datetime | None = None) -> dict[str, Any] | None:
        """The newest record, or the newest one started strictly before ``before``."""
        entries = self.entries()
        if before is not None:
            if before.tzinfo is None:
                raise HistoryError(
                    "latest(before=...) needs a timezone-aware datetime",
                    hint="pass datetime.now(timezone.utc)",
                )
            entries = [entry for entry in entries if entry.started_utc < before]
        return entries[-1].record if entries else None

    def find(self, version: str) -> dict[str, Any] | None:
        """The newest record of model version ``version``, or ``None``."""
        matches = [entry for entry in self.entries() if entry.record["model_version"] == version]
        return matches[-1].record if matches else None

    def versions(self) -> list[str]:
        """Distinct recorded model versions, oldest first."""
        seen: dict[str, None] = {}
        for entry in self.entries():
            seen.setdefault(entry.record["model_version"], None)
        return list(seen)


def record_text(record: Mapping[str, Any]) -> str:
    """A record as strict JSON: one top-level key per line, and each spec on one line.

    Readable line by line, and written by ``json``'s compiled encoder: an indented dump goes
    through its pure-Python one, several times slower on a campaign's tens of thousands of
    numbers.
    """
    lines = []
    for key, value in record.items():
        if key == "specs" and isinstance(value, list):
            specs = ",\n  ".join(json.dumps(spec, allow_nan=False) for spec in value)
            text = f"[\n  {specs}\n ]" if value else "[]"
        else:
            text = json.dumps(value, allow_nan=False)
        lines.append(f" {json.dumps(key)}: {text}")
    return "{\n" + ",\n".join(lines) + "\n}\n"


def _write_error(directory: Path, exc: OSError) -> HistoryError:
    return HistoryError(
        f"cannot write the history record: {exc.strerror or exc}",
        file=str(directory),
        hint="free disk space or choose another folder with --hevval-history-dir; "
        "the records already there are unchanged",
    )
