"""An append-only folder of history records, safe for concurrent writers and parallel branches.

Layout: one file per run, ``<UTC time>_<model-version slug>_<8 hex>.json``, for example
``20240501T120000.123456Z_v1.4-3-gabc123_9f2c01ab.json``. Names sort by time, and the random
suffix means two writers (or two branches merged later) never pick the same name, which
sequential numbers cannot promise.

Writes are atomic: the JSON goes to a hidden temporary file in the same folder, is fsync'ed,
then hard-linked to its final name. ``os.link`` fails instead of replacing an existing file, so
a record is never overwritten; readers never see a half-written ``*.json``.

The baseline and the report's trends come through an index (:mod:`.index`), a cache kept in
the ``.index`` subfolder: a run reads it, the records it does not know yet and the one record
it compares with, not every record. Where there is no index yet (a fresh clone: the index is
never committed) and every file carries a record's name, the baseline and the trends of given
signals are read from the newest records alone, newest first, and the index is built only
when something asks for older data. :meth:`HistoryStore.entries` still reads them all.
"""

from __future__ import annotations

import functools
import json
import os
import re
import uuid
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, NamedTuple

from ..defaults import HISTORY_DIR
from ..files import (
    forget_temporary,
    fsync_directory,
    publish,
    read_input,
    read_json,
    write_temporary,
)
from ..flags import PYTEST, FrontEnd
from ..results.recorded import RecordedPoint, RecordedRun
from ._base import HistoryError
from .index import (
    TREND_RUNS,
    HistoryIndex,
    IndexedRecord,
    IndexStale,
    TrendKey,
    index_path,
    load_index,
    micros,
    save_index,
)
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

    def __init__(
        self,
        directory: Path | str,
        *,
        trend_runs: int = TREND_RUNS,
        front_end: FrontEnd = PYTEST,
    ) -> None:
        self.directory = Path(directory)
        #: How the front end in use spells the options a message names.
        self.front_end = front_end
        self.problems: list[StoreProblem] = []
        #: Recorded runs kept per signal for :meth:`trends`.
        self.trend_runs = trend_runs

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
                hint=f"choose a writable folder with {self.front_end.flag('history-dir')}",
            ) from None
        stem = f"{started.strftime('%Y%m%dT%H%M%S.%fZ')}_{slugify(checked['model_version'])}"
        temp = self._write_temp(payload)
        try:
            for _ in range(_NAME_ATTEMPTS):
                final = self.directory / f"{stem}_{uuid.uuid4().hex[:8]}.json"
                if publish(temp, final, replace=False):
                    fsync_directory(self.directory)
                    break
            else:
                raise HistoryError(  # pragma: no cover - 20 uuid4 collisions in a row
                    "could not find a free file name for the record",
                    file=str(self.directory),
                )
        except OSError as exc:
            raise _write_error(self.directory, exc, self.front_end) from None
        finally:
            forget_temporary(temp)
        self._index_new(final, len(payload), checked)
        return final

    def _index_new(self, path: Path, size: int, record: Mapping[str, Any]) -> None:
        """Add a record just written to an existing index, so that the next run need not read
        it. Without an index nothing is done: building one is for the runs that read."""
        index = load_index(self.directory, self.trend_runs)
        if index is not None and path.name not in index.records:
            index.add(path.name, size, record)
            save_index(self.directory, index)

    def _write_temp(self, payload: bytes) -> Path:
        try:
            return write_temporary(self.directory, payload, stem="record")
        except OSError as exc:
            raise HistoryError(
                f"cannot write to the history folder: {exc.strerror or exc}",
                file=str(self.directory),
                hint=f"choose a writable folder with {self.front_end.flag('history-dir')}",
            ) from None

    # -- reading ---------------------------------------------------------------------------

    def entries(self) -> list[StoredRecord]:
        """Every readable record with its path, oldest first; fills :attr:`problems`.

        Reads every file; the other readers below go through the index instead.
        """
        self.problems = []
        if not self.directory.is_dir():
            return []
        found: list[StoredRecord] = []
        for name in sorted(_listing(self.directory)):
            read = _read(self.directory / name)
            if isinstance(read, StoredRecord):
                found.append(read)
            else:
                self.problems.append(read.problem)
        found.sort(key=lambda entry: (entry.started_utc, entry.path.name))
        return found

    def records(self) -> list[dict[str, Any]]:
        """Every readable record, oldest first; unreadable files go to :attr:`problems`."""
        return [entry.record for entry in self.entries()]

    def runs(self) -> list[RecordedRun]:
        """Every readable record, oldest first, as history compares runs and draws trends."""
        return [RecordedRun.from_json(record) for record in self.records()]

    def latest(self, before: datetime | None = None) -> dict[str, Any] | None:
        """The newest record, or the newest one started strictly before ``before``."""
        found = self.newest(1, before=before)
        return found[0].record if found else None

    def find(self, version: str) -> dict[str, Any] | None:
        """The newest record of model version ``version``, or ``None``."""
        found = self.newest(1, version=version)
        return found[0].record if found else None

    def newest(
        self,
        count: int,
        *,
        version: str | None = None,
        before: datetime | None = None,
        accepted_only: bool = False,
    ) -> list[StoredRecord]:
        """Up to ``count`` records, newest first: of model version ``version`` when given,
        started strictly before ``before`` when given, accepted as baselines with
        ``accepted_only``. Only these records are read."""
        if before is not None and before.tzinfo is None:
            raise HistoryError(
                "latest(before=...) needs a timezone-aware datetime",
                hint="pass datetime.now(timezone.utc)",
            )
        wanted = _Wanted(version, None if before is None else micros(before), accepted_only)
        walked = self._walk_newest(lambda index, found: len(found) == count, wanted)
        if walked is not None:
            return walked[1]
        found = self._pick(self._catalogue(), count, wanted, strict=True)
        if found is None:  # a file changed behind the index's back: read every record again
            found = self._pick(self._catalogue(rebuild=True), count, wanted, strict=False)
        return found or []

    def accepted(self) -> dict[str, Any] | None:
        """The newest record accepted as a baseline, or ``None``."""
        found = self.newest(1, accepted_only=True)
        return found[0].record if found else None

    def _pick(
        self,
        index: HistoryIndex,
        count: int,
        wanted: _Wanted,
        *,
        strict: bool,
    ) -> list[StoredRecord] | None:
        """The newest ``count`` matching records, read and validated; ``None`` when ``strict``
        and a file does not hold what the index says."""
        found: list[StoredRecord] = []
        for entry in reversed(index.ordered()):
            if len(found) == count:
                break
            if not wanted.matches(entry):
                continue
            read = _read(self.directory / entry.name)
            if isinstance(read, StoredRecord) and entry.describes(read.record):
                found.append(read)
            elif strict:
                return None
            elif isinstance(read, _Problem):
                # Unreadable since the index was rebuilt a moment ago: skipped and named, as
                # a full read would do. A file changed again in that moment is skipped too.
                self.problems.append(read.problem)
        return found

    def versions(self) -> list[str]:
        """Distinct recorded model versions, oldest first."""
        seen: dict[str, None] = {}
        for entry in self._catalogue().ordered():
            seen.setdefault(entry.model_version, None)
        return list(seen)

    def trends(
        self, keys: Iterable[tuple[str, str]] | None = None
    ) -> dict[tuple[str, str], list[RecordedPoint]]:
        """The recorded points of each (spec path, signal path), oldest first: the newest
        :attr:`trend_runs` runs that hold the signal; of the given ``keys`` only, when
        given. No record the index already knows is read; without an index, the trends of
        given keys are read from the newest records, until each has its runs or every record
        is read."""
        wanted = None if keys is None else set(keys)
        index = None
        if wanted is not None:
            walked = self._walk_newest(
                lambda index, found: (
                    all(
                        len(index.trends[key].points) >= self.trend_runs
                        for key in wanted
                        if key in index.trends
                    )
                    and wanted <= index.trends.keys()
                ),
                None,
                functools.partial(_may_hold, self.trend_runs, wanted),
            )
            index = walked[0] if walked is not None else None
        if index is None:
            index = self._catalogue()
        return {
            key: [
                RecordedPoint.from_json(
                    index.records[point.name].model_version, point.phi, point.lambdas
                )
                for point in trend.points
            ]
            for key, trend in index.trends.items()
            if wanted is None or key in wanted
        }

    def _walk_newest(
        self,
        done: Callable[[HistoryIndex, list[StoredRecord]], bool],
        wanted: _Wanted | None,
        may_hold: Callable[[HistoryIndex, Path], bool] | None = None,
    ) -> tuple[HistoryIndex, list[StoredRecord]] | None:
        """Without an index, read the records newest first, by the times their names carry,
        until ``done`` (given what is read so far, and the records ``wanted`` matches, newest
        first) or every record is read: then the index holds everything and is saved. A file
        that ``may_hold`` (given what is read so far) says cannot hold what is still wanted
        is passed over, and the index is then not saved.

        ``None`` when this cannot be trusted to give what reading every record gives: there
        is an index (use it), a file's name is not a record's name, its size cannot be read,
        or a record read does not start at the time its name says; the caller then goes
        through the index, built by reading every record."""
        self.problems = []
        if not self.directory.is_dir():
            return HistoryIndex(self.trend_runs), []
        if index_path(self.directory).exists():
            return None
        listing = _listing(self.directory)
        named: list[tuple[int, str, int]] = []
        for name, size in listing.items():
            started = _name_time(name)
            if started is None or size is None:
                return None
            named.append((started, name, size))
        named.sort(reverse=True)
        index = HistoryIndex(self.trend_runs)
        found: list[StoredRecord] = []
        passed_over = False
        for started, name, size in named:
            if done(index, found):
                return index, found
            if may_hold is not None and not may_hold(index, self.directory / name):
                passed_over = True
                continue
            read = _read(self.directory / name)
            if not isinstance(read, StoredRecord) or micros(read.started_utc) != started:
                return None
            index.add(name, size, read.record)
            if wanted is not None and wanted.matches(index.records[name]):
                found.append(read)
        if named and not passed_over:  # every record read: the index is whole, and kept
            save_index(self.directory, index)
        return index, found

    # -- the index ---------------------------------------------------------------------------

    def _catalogue(self, *, rebuild: bool = False) -> HistoryIndex:
        """The index brought up to date with the folder, saved when it changed; fills
        :attr:`problems` as a full read would."""
        self.problems = []
        if not self.directory.is_dir():
            return HistoryIndex(self.trend_runs)
        listing = _listing(self.directory)
        loaded = None if rebuild else load_index(self.directory, self.trend_runs)
        try:
            index, changed = self._update(loaded, listing)
        except IndexStale:
            index, changed = self._update(None, listing)
        if changed and (loaded is not None or index.records or index.unreadable):
            save_index(self.directory, index)
        return index

    def _update(
        self, loaded: HistoryIndex | None, listing: Mapping[str, int | None]
    ) -> tuple[HistoryIndex, bool]:
        self.problems = []
        index = loaded if loaded is not None else HistoryIndex(self.trend_runs)
        gone = [name for name, size in index.sizes().items() if listing.get(name, -1) != size]
        if gone:
            # Older points of the trends that lose some are read before the new records are
            # added, so that each record is placed once.
            index.refill(index.forget(gone), self._read_known)
        changed = loaded is None or bool(gone)
        for name in sorted(listing):
            size = listing[name]
            if name in index.records or name in index.unreadable:
                continue
            read = _read(self.directory / name)
            if isinstance(read, StoredRecord) and size is not None:
                index.add(name, size, read.record)
                changed = True
            elif isinstance(read, _Problem) and read.lasting and size is not None:
                index.unreadable[name] = (size, read.problem.message)
                changed = True
            else:  # to be tried again next time: a permission, a file being replaced
                self.problems.append(
                    read.problem
                    if isinstance(read, _Problem)
                    else StoreProblem(read.path, "unreadable: its size cannot be read")
                )
        self.problems.extend(
            StoreProblem(self.directory / name, message)
            for name, (_, message) in index.unreadable.items()
        )
        self.problems.sort(key=lambda problem: problem.path)
        return index, changed

    def _read_known(self, name: str) -> dict[str, Any]:
        read = _read(self.directory / name)
        if not isinstance(read, StoredRecord):
            raise IndexStale(name)
        return read.record


#: A record's file name starts with its start time (see :meth:`HistoryStore.append`).
_NAME_TIME = re.compile(r"^(\d{8}T\d{6}\.\d{6})Z_")


def _name_time(name: str) -> int | None:
    """The start time a record's file name carries, in whole microseconds; None for a name
    that is not a record's."""
    match = _NAME_TIME.match(name)
    if match is None:
        return None
    try:
        moment = datetime.strptime(match[1], "%Y%m%dT%H%M%S.%f").replace(tzinfo=timezone.utc)
    except ValueError:
        return None
    return micros(moment)


#: How every record this version writes begins (``record_text``): the spec results' keys and
#: values in it are written by ``json.dumps`` with its default separators and escapes.
_RECORD_HEAD = b'{\n "schema_version": 4,'


def _may_hold(trend_runs: int, wanted: set[TrendKey], index: HistoryIndex, path: Path) -> bool:
    """Whether the record in ``path`` may hold a point of a trend in ``wanted`` that is not
    yet full: without parsing it, by finding the spec's and the signal's paths as its writer
    wrote them. A file this version did not write, or cannot read, is read to find out."""
    short = [
        key
        for key in wanted
        if key not in index.trends or len(index.trends[key].points) < trend_runs
    ]
    try:
        data = read_input(path)
    except (OSError, ValueError):
        return True
    if not data.startswith(_RECORD_HEAD):
        return True
    return any(
        b'"spec": ' + json.dumps(spec).encode() in data
        and b'"path": ' + json.dumps(signal).encode() in data
        for spec, signal in short
    )


class _Wanted(NamedTuple):
    """Which records :meth:`HistoryStore.newest` returns."""

    version: str | None
    #: Started strictly before this time (whole microseconds), when given.
    limit: int | None
    accepted_only: bool

    def matches(self, entry: IndexedRecord) -> bool:
        return (
            (self.version is None or entry.model_version == self.version)
            and (self.limit is None or entry.started_us < self.limit)
            and (entry.accepted or not self.accepted_only)
        )


def _listing(directory: Path) -> dict[str, int | None]:
    """The ``*.json`` names in ``directory`` with their sizes (``None`` where the size cannot be
    read: such a file is read, and named as a problem). One pass of ``os.scandir``: with
    thousands of records, pathlib's glob cost more than everything else a run reads."""
    found: dict[str, int | None] = {}
    try:
        entries = list(os.scandir(directory))
    except OSError:
        return found
    for entry in entries:
        if not os.path.normcase(entry.name).endswith(".json"):
            continue
        try:
            found[entry.name] = entry.stat().st_size
        except OSError:
            found[entry.name] = None
    return found


@dataclass(frozen=True)
class _Problem:
    problem: StoreProblem
    #: Whether the file's content is the cause, which stays until the file changes; a
    #: permission or a vanished file is tried again on the next read.
    lasting: bool


def _read(path: Path) -> StoredRecord | _Problem:
    """The validated record in ``path``, or why there is none."""
    try:
        document = read_json(path)
    except OSError as exc:
        return _Problem(StoreProblem(path, f"unreadable: {exc.strerror or exc}"), lasting=False)
    except json.JSONDecodeError as exc:
        problem = (
            "empty file (a write may be in progress)"
            if not exc.doc.strip()
            else f"not valid JSON at line {exc.lineno}: {exc.msg}"
        )
        return _Problem(StoreProblem(path, problem), lasting=True)
    except ValueError as exc:  # not UTF-8, or nested too deep
        return _Problem(StoreProblem(path, f"unreadable: {exc}"), lasting=True)
    try:
        record = migrate_record(document, file=str(path))
    except HistoryError as exc:
        return _Problem(StoreProblem(path, exc.problem), lasting=True)
    return StoredRecord(path, record, parse_utc(record["started_utc"]))


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


def _write_error(directory: Path, exc: OSError, front_end: FrontEnd) -> HistoryError:
    return HistoryError(
        f"cannot write the history record: {exc.strerror or exc}",
        file=str(directory),
        hint=f"free disk space or choose another folder with {front_end.flag('history-dir')}; "
        "the records already there are unchanged",
    )
