"""A cache of what a run needs from the history folder, so that no run reads every record.

The records stay the only truth; this is what was learnt from them, kept in
``<history folder>/.index/index`` beside a ``.gitignore`` that keeps it out of git:

* for every record file: its name, its size, its start time, model version and whether it is
  an accepted baseline, so that the baseline (the newest record, the newest accepted one, or
  the newest of a version) is found without reading any record and then read alone;
* for every file that is not a record: its name, size and why, so that it is listed again
  without being read again;
* for every (spec, signal): the points of its trend in the HTML report, the newest
  :data:`TREND_RUNS` recorded runs that hold that signal (Φ of the spec and the signal's λ).

A file is known by its name and size. Names are unique (a time and a random suffix) and
pytest-hevval never rewrites a record, so a name the index does not know is a new record (a
run, a copy, a merge from another branch, whatever its time) and a known name of another size
is a record changed by hand. Modification times are not used: a fresh clone or a restored
cache gives every file a new one, and a merge brings files older than the newest one known.

The index is rebuilt from the records whenever it is missing, unreadable, made by another
version of pytest-hevval or inconsistent with the files it describes; anything it cannot be
trusted with leads to a full read, never to a wrong answer. Two processes that update it at
once each replace it whole (:func:`~pytest_hevval.files.write_atomic`); the loser's view may
lack a record, which the next run then reads once more.
"""

from __future__ import annotations

import bisect
import json
import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import Any, NamedTuple

from .. import __version__
from ..files import read_input, write_atomic
from .records import SCHEMA_VERSION, parse_utc

__all__ = [
    "INDEX_DIR",
    "TREND_RUNS",
    "HistoryIndex",
    "IndexStale",
    "IndexedRecord",
    "TrendPoint",
    "index_path",
    "load_index",
    "save_index",
]

#: The folder of the index inside the history folder: hidden, and not ``*.json``, so that
#: nothing that lists records (``HistoryStore``, ``hevval history``) ever sees it.
INDEX_DIR = ".index"
_INDEX_FILE = "index"
_GITIGNORE = (
    "# Created by pytest-hevval: a cache of the history records, rebuilt from them when\n"
    "# missing. Never commit it: it changes on every run.\n"
    "*\n"
)
#: Recorded runs a signal's trend shows in the HTML report, before the current run.
TREND_RUNS = 20
_FORMAT = "pytest-hevval history index"
# Raise when what the index holds, or how it is read, changes: older indexes are rebuilt.
_INDEX_VERSION = 2
_EPOCH = datetime(1, 1, 1, tzinfo=timezone.utc)
_MICROSECOND = timedelta(microseconds=1)


class IndexStale(Exception):
    """A file no longer says what the index says about it: the index must be rebuilt."""


def micros(moment: datetime) -> int:
    """An aware time as whole microseconds: exact, and ordered as the times are."""
    return (moment - _EPOCH) // _MICROSECOND


def index_path(directory: Path) -> Path:
    return directory / INDEX_DIR / _INDEX_FILE


class IndexedRecord(NamedTuple):
    """A record file as the index knows it."""

    name: str
    size: int
    started_us: int
    model_version: str
    accepted: bool

    @property
    def order(self) -> tuple[int, str]:
        """Records are ordered by start time, then by file name, as a full read orders them."""
        return (self.started_us, self.name)

    def describes(self, record: Mapping[str, Any]) -> bool:
        """Whether a record read from this file is the one indexed."""
        return (
            record["model_version"] == self.model_version
            and micros(parse_utc(record["started_utc"])) == self.started_us
            and record["accepted"] is self.accepted
        )


class TrendPoint(NamedTuple):
    """One recorded run on a signal's trend."""

    order: tuple[int, str]
    phi: float | None
    lambdas: dict[str, float | None]

    @property
    def name(self) -> str:
        return self.order[1]


@dataclass
class Trend:
    """The newest points of one (spec, signal); ``complete`` when they are all there are."""

    points: list[TrendPoint] = field(default_factory=list)
    complete: bool = True


TrendKey = tuple[str, str]


def trend_values(record: Mapping[str, Any]) -> dict[TrendKey, list[tuple[Any, Any]]]:
    """(Φ, λ) of each (spec, signal) of a validated record, in the record's order."""
    found: dict[TrendKey, list[tuple[Any, Any]]] = {}
    for spec in record["specs"]:
        key = spec.get("spec", "")
        if not isinstance(key, str):
            continue  # never the key of a result, which is a path
        for signal in spec["signals"]:
            found.setdefault((key, signal["path"]), []).append(
                (spec.get("phi"), signal.get("lambdas"))
            )
    return found


class HistoryIndex:
    """What the index holds, with the updates a changed folder needs."""

    def __init__(self, trend_runs: int = TREND_RUNS) -> None:
        self.trend_runs = trend_runs
        self.records: dict[str, IndexedRecord] = {}
        #: Files that are not records, with the reason: name → (size, message).
        self.unreadable: dict[str, tuple[int, str]] = {}
        self.trends: dict[TrendKey, Trend] = {}

    def sizes(self) -> dict[str, int]:
        """The size of every file the index knows, by name."""
        known = {name: entry.size for name, entry in self.records.items()}
        known.update((name, size) for name, (size, _) in self.unreadable.items())
        return known

    def ordered(self) -> list[IndexedRecord]:
        """The records, oldest first."""
        return sorted(self.records.values(), key=lambda entry: entry.order)

    def add(self, name: str, size: int, record: Mapping[str, Any]) -> None:
        """Index a validated record read from (or just written to) the file ``name``."""
        entry = IndexedRecord(
            name,
            size,
            micros(parse_utc(record["started_utc"])),
            record["model_version"],
            record["accepted"],
        )
        self.records[name] = entry
        for key, values in trend_values(record).items():
            trend = self.trends.setdefault(key, Trend())
            orders = [point.order for point in trend.points]
            at = bisect.bisect_left(orders, entry.order)
            trend.points[at:at] = [TrendPoint(entry.order, phi, lam) for phi, lam in values]
            if len(trend.points) > self.trend_runs:
                del trend.points[: -self.trend_runs]
                trend.complete = False

    def forget(self, names: Iterable[str]) -> dict[TrendKey, tuple[int, str] | None]:
        """Drop files gone or changed; return the trends that now miss older points, each with
        the order from which to read them again (``None``: from the newest record)."""
        gone = set(names)
        for name in gone:
            self.records.pop(name, None)
            self.unreadable.pop(name, None)
        refill: dict[TrendKey, tuple[int, str] | None] = {}
        for key, trend in list(self.trends.items()):
            if not any(point.name in gone for point in trend.points):
                continue
            kept = [point for point in trend.points if point.name not in gone]
            if not trend.complete:
                # The oldest run kept may have lost points to trimming: it is read again.
                cut = kept[0].order if kept else None
                kept = [point for point in kept if point.order != cut]
                refill[key] = cut
            trend.points = kept
            if not kept and trend.complete:
                del self.trends[key]
        return refill

    def refill(
        self,
        wanted: Mapping[TrendKey, tuple[int, str] | None],
        read: Callable[[str], Mapping[str, Any]],
    ) -> None:
        """Read older records, newest first, until each trend in ``wanted`` is full again or
        has every point there is. ``read`` gives the validated record of a file name, or
        raises :class:`IndexStale`."""
        pending = dict(wanted)
        for entry in reversed(self.ordered()):
            if not pending:
                break
            due = [key for key, cut in pending.items() if cut is None or entry.order <= cut]
            if not due:
                continue
            record = read(entry.name)
            if not entry.describes(record):
                raise IndexStale(entry.name)
            values = trend_values(record)
            for key in due:
                found = values.get(key)
                if not found:
                    continue
                trend = self.trends.setdefault(key, Trend(complete=False))
                trend.points[:0] = [TrendPoint(entry.order, phi, lam) for phi, lam in found]
                if len(trend.points) >= self.trend_runs:
                    del trend.points[: -self.trend_runs]
                    del pending[key]
        for key in pending:  # read back to the oldest record: every point there is
            short = self.trends.get(key)
            if short is not None:
                short.complete = True
                if not short.points:
                    del self.trends[key]

    # -- on disk -----------------------------------------------------------------------------

    def to_json(self) -> dict[str, Any]:
        return {
            "index": _FORMAT,
            "index_version": _INDEX_VERSION,
            "pytest_hevval": __version__,
            "schema_version": SCHEMA_VERSION,
            "trend_runs": self.trend_runs,
            # Columns, not one list per record: thousands of records then load as a few
            # lists that are checked whole, not value by value.
            "records": {
                "name": [e.name for e in self.records.values()],
                "size": [e.size for e in self.records.values()],
                "started_us": [e.started_us for e in self.records.values()],
                "model_version": [e.model_version for e in self.records.values()],
                "accepted": [e.accepted for e in self.records.values()],
            },
            "unreadable": {
                "name": list(self.unreadable),
                "size": [size for size, _ in self.unreadable.values()],
                "message": [message for _, message in self.unreadable.values()],
            },
            "trends": [
                [spec, signal, trend.complete, [[p.name, p.phi, p.lambdas] for p in trend.points]]
                for (spec, signal), trend in self.trends.items()
            ],
        }

    @classmethod
    def from_json(cls, document: Any, trend_runs: int) -> HistoryIndex:
        """The index in ``document``; :class:`ValueError` when it is not one this version made
        with ``trend_runs``, or breaks a rule an index made by it keeps."""
        _check(isinstance(document, dict), "not an object")
        expected = {
            "index": _FORMAT,
            "index_version": _INDEX_VERSION,
            "pytest_hevval": __version__,
            "schema_version": SCHEMA_VERSION,
            "trend_runs": trend_runs,
        }
        for key, value in expected.items():
            _check(document.get(key) == value, f"{key} is not {value!r}")
        index = cls(trend_runs)
        names, sizes, started, versions, accepted = _columns(
            document.get("records"), "name", "size", "started_us", "model_version", "accepted"
        )
        _check(_all(names, str) and all(names) and _all(versions, str) and all(versions), "a name")
        _check(_all(sizes, int) and min(sizes, default=0) >= 0 and _all(started, int), "a number")
        _check(_all(accepted, bool), "an acceptance")
        index.records = dict(
            zip(
                names,
                map(IndexedRecord, names, sizes, started, versions, accepted),
                strict=True,
            )
        )
        _check(len(index.records) == len(names), "a record listed twice")
        names, sizes, messages = _columns(document.get("unreadable"), "name", "size", "message")
        _check(_all(names, str) and all(names) and _all(messages, str), "a name or message")
        _check(_all(sizes, int) and min(sizes, default=0) >= 0, "a size")
        index.unreadable = dict(zip(names, zip(sizes, messages, strict=True), strict=True))
        _check(len(index.unreadable) == len(names), "a file listed twice")
        _check(index.records.keys().isdisjoint(index.unreadable), "a file listed twice")
        for item in _list(document.get("trends")):
            _check(isinstance(item, list) and len(item) == 4, "a bad trend")
            spec, signal, complete, raw_points = item
            _check(isinstance(spec, str) and isinstance(signal, str), "a bad trend key")
            _check(isinstance(complete, bool) and (spec, signal) not in index.trends, "bad trend")
            points = [index._point(raw) for raw in _list(raw_points)]
            _check(0 < len(points) <= trend_runs, "a trend of the wrong length")
            # A trend shorter than its length holds every point there is, or it would have
            # been refilled; one that claims otherwise was not written by this code.
            _check(complete or len(points) == trend_runs, "a short trend not marked complete")
            orders = [point.order for point in points]
            _check(orders == sorted(orders), "a trend out of order")
            index.trends[(spec, signal)] = Trend(points, complete)
        return index

    def _point(self, raw: Any) -> TrendPoint:
        # Plain loops and type() tests: an index holds tens of thousands of these values, and
        # reading it is the whole cost of a run's history once it exists.
        _check(type(raw) is list and len(raw) == 3, "a bad trend point")
        name, phi, lambdas = raw
        _check(type(name) is str and name in self.records, "a point of an unknown record")
        _check(_is_value(phi), "a bad Φ")
        _check(type(lambdas) is dict and bool(lambdas), "bad λ values")
        for value in lambdas.values():
            if not _is_value(value):
                raise ValueError("not a history index: a bad λ value")
        return TrendPoint(self.records[name].order, phi, lambdas)


def load_index(directory: Path, trend_runs: int = TREND_RUNS) -> HistoryIndex | None:
    """The index of ``directory``, or ``None`` when there is none this code can trust."""
    try:
        text = read_input(index_path(directory)).decode("utf-8")
        # from_json checks every value's place and type, which bounds the nesting as well
        # as read_json's walk over the whole document would, at a fraction of its cost.
        document = json.loads(text, parse_constant=_refuse_constant)
        return HistoryIndex.from_json(document, trend_runs)
    except (OSError, ValueError, RecursionError):  # missing, not a file, not JSON, not an index
        return None


def save_index(directory: Path, index: HistoryIndex) -> bool:
    """Replace the index of ``directory``; False when it cannot be written, which only costs
    the next run a longer read."""
    target = index_path(directory)
    ignore = target.parent / ".gitignore"
    try:
        # ASCII: a record may hold a lone surrogate, which UTF-8 cannot encode.
        text = json.dumps(index.to_json(), allow_nan=False)
        if not ignore.is_file():
            write_atomic(ignore, _GITIGNORE, replace=False)
        write_atomic(target, text + "\n")
    except (OSError, ValueError):
        return False
    return True


def _check(condition: bool, problem: str) -> None:
    if not condition:
        raise ValueError(f"not a history index: {problem}")


def _columns(value: Any, *keys: str) -> list[list[Any]]:
    _check(type(value) is dict, "a table is missing")
    columns = [_list(value.get(key)) for key in keys]
    _check(len({len(column) for column in columns}) == 1, "columns of different lengths")
    return columns


def _all(values: list[Any], kind: type) -> bool:
    """Whether every value is of type ``kind`` exactly (so no bool passes for an int)."""
    return set(map(type, values)) <= {kind}


def _list(value: Any) -> list[Any]:
    if not isinstance(value, list):
        raise ValueError("not a history index: a list is missing")
    return value


def _is_value(value: Any) -> bool:
    # Records hold finite floats or null; an index that holds anything else was not made here.
    return value is None or (type(value) is float and math.isfinite(value))


def _refuse_constant(name: str) -> Any:
    raise ValueError(f"not a history index: {name}")
