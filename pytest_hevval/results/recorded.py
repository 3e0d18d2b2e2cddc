"""A run as history compares it: the figures of each result that a comparison, a trend or a
runtime check reads, typed.

A comparison sets the current run beside a recorded one. The current run's results are typed
(:class:`~.spec_result.SpecResult`); a recorded run is read from a file that this or an earlier
version wrote: a history record keeps only part of a result (windows without their λ; no
figures), records of schema 1 had no set, level or α, and a value that was not a finite number
was stored as ``null``. :class:`RecordedSpec` is what both have in common, made from a typed
result (:meth:`RecordedSpec.of`) or read from a result's JSON (:meth:`RecordedSpec.from_json`),
which are the same for the same result. The comparator, the trends and the runtime rule take
these, never JSON.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from .codec import (
    data_identity,
    finite_bounds,
    interval_bounds,
    interval_table,
    json_number,
    json_numbers,
    lambdas_or_none,
)
from .local_tables import GroupTable, LocalResult
from .runtime import ModelRuntime
from .spec_result import PHYSICAL_ERRORS, SignalResult, SpecResult

__all__ = [
    "DATA_SIDES",
    "GroupRows",
    "RecordedPoint",
    "RecordedRun",
    "RecordedSignal",
    "RecordedSpec",
    "Side",
    "recorded_specs",
    "spec_key",
]

#: The data files a result names by digest, whose change a comparison reports.
DATA_SIDES = ("reference", "model")
#: The local tables a comparison reads, besides each condition's.
_LOCAL_TABLES = ("windows", "phases", "regions")

#: One local table as history keeps it: label → (samples, RMS error or None where undefined).
GroupRows = Mapping[str, tuple[int, float | None]]
Interval = tuple[float, float]


def spec_key(spec: Mapping[str, Any]) -> str:
    """Identity of a spec's JSON result across runs: its file path when known, else its name."""
    return _key(spec.get("spec"), spec.get("name"))


def _key(path: Any, name: Any) -> str:
    key = path or name
    return str(key) if key is not None else "?"


def _flag(value: Any) -> bool | None:
    return value if isinstance(value, bool) else None


def _table_rows(table: GroupTable) -> dict[str, tuple[int, float | None]]:
    rms = json_numbers(table.rms)
    return {
        str(label): (int(n), value)
        for label, n, value in zip(table.labels, table.n.tolist(), rms, strict=True)
    }


def _json_rows(table: Any) -> dict[str, tuple[int, float | None]]:
    """A table's rows from JSON; none where its columns disagree in length or a count is not
    a number (a table edited by hand)."""
    if not isinstance(table, Mapping):
        return {}
    labels, counts, rms = (list(table.get(key) or []) for key in ("labels", "n", "rms"))
    if not len(labels) == len(counts) == len(rms):
        return {}
    rows: dict[str, tuple[int, float | None]] = {}
    for label, count, value in zip(labels, counts, rms, strict=True):
        samples = json_number(count)
        if samples is None:
            return {}
        rows[str(label)] = (int(samples), json_number(value))
    return rows


def _local_rows(local: LocalResult | None) -> dict[str, GroupRows]:
    if local is None:
        return {}
    tables = {"windows": local.windows, "phases": local.phases, "regions": local.regions}
    out: dict[str, GroupRows] = {
        name: _table_rows(table) for name, table in tables.items() if table is not None
    }
    out.update((str(name), _table_rows(table)) for name, table in local.conditions.items())
    return out


def _local_json(local: Any) -> dict[str, GroupRows]:
    if not isinstance(local, Mapping):
        return {}
    out: dict[str, GroupRows] = {
        name: _json_rows(local[name])
        for name in _LOCAL_TABLES
        if isinstance(local.get(name), Mapping)
    }
    for name, table in dict(local.get("conditions") or {}).items():
        if isinstance(table, Mapping):
            out[str(name)] = _json_rows(table)
    return out


@dataclass(frozen=True)
class RecordedSignal:
    """One signal of a recorded result: its λ, their intervals, its physical errors, its
    verdict and the RMS error of its windows, phases, conditions and cells."""

    path: str
    name: str
    unit: str | None
    #: λ by characteristic name; None where it was undefined.
    lambdas: Mapping[str, float | None]
    #: 95 % intervals (low, high) of λ by name, where recorded.
    intervals: Mapping[str, Interval]
    #: The physical errors (``PHYSICAL_ERRORS``) by name; None where undefined.
    errors: Mapping[str, float | None]
    passed: bool | None
    #: Local tables by grouping (``windows``, ``phases``, ``regions`` or a condition's name).
    local: Mapping[str, GroupRows] = field(default_factory=dict)

    @property
    def lag_s(self) -> float | None:
        return self.errors.get("lag_s")

    @classmethod
    def of(cls, signal: SignalResult) -> RecordedSignal:
        measured = signal.characteristics.as_dict()
        return cls(
            path=signal.path,
            name=signal.name,
            unit=signal.unit,
            lambdas={name: json_number(value) for name, value in signal.lambdas.items()},
            intervals={
                name: bounds
                for name, interval in signal.intervals.items()
                if (bounds := finite_bounds(interval.low, interval.high)) is not None
            },
            errors={name: json_number(measured[name]) for name in PHYSICAL_ERRORS},
            passed=signal.passed,
            local=_local_rows(signal.local),
        )

    @classmethod
    def from_json(cls, raw: Mapping[str, Any]) -> RecordedSignal:
        """A signal's JSON of any result schema (λ listed in paper order in schema 1)."""
        path = str(raw["path"])
        unit = raw.get("unit")
        return cls(
            path=path,
            name=str(raw.get("name", path.rsplit("/", 1)[-1])),
            unit=unit if isinstance(unit, str) else None,
            lambdas=lambdas_or_none(raw.get("lambdas")),
            intervals=interval_table(raw.get("intervals")),
            errors={name: json_number(raw.get(name)) for name in PHYSICAL_ERRORS},
            passed=_flag(raw.get("passed")),
            local=_local_json(raw.get("local")),
        )


@dataclass(frozen=True)
class RecordedSpec:
    """One spec (or campaign recording) of a recorded run."""

    #: The spec's identity across runs: its file path (with ``::recording``), else its name.
    key: str
    #: The spec's name; None where the result named none.
    name: str | None
    phi: float | None
    phi_interval: Interval | None
    passed: bool | None
    signals: tuple[RecordedSignal, ...]
    #: (hash algorithm, digest) of each data side the result names (``DATA_SIDES``); None for
    #: a side without a digest (a callable model). None where the result holds no data facts.
    data: Mapping[str, tuple[str, str] | None] | None = None
    runtime: ModelRuntime | None = None

    @property
    def title(self) -> str:
        """The spec's name, else its key."""
        return self.name if self.name else self.key

    @classmethod
    def of(cls, result: SpecResult) -> RecordedSpec:
        return cls(
            key=_key(result.spec, result.name),
            name=result.name or None,
            phi=json_number(result.phi),
            phi_interval=None
            if result.phi_interval is None
            else finite_bounds(result.phi_interval.low, result.phi_interval.high),
            passed=result.passed,
            signals=tuple(RecordedSignal.of(signal) for signal in result.signals),
            data={
                side: found.identity
                for side, found in zip(
                    DATA_SIDES, (result.data.reference, result.data.model), strict=True
                )
                if found is not None
            },
            runtime=result.runtime,
        )

    @classmethod
    def from_json(cls, raw: Mapping[str, Any]) -> RecordedSpec:
        """A spec result's JSON, as a run document, a report or a history record of any schema
        holds it."""
        name = raw.get("name")
        signals = raw.get("signals")
        data = raw.get("data")
        runtime = raw.get("runtime")
        return cls(
            key=spec_key(raw),
            name=name if isinstance(name, str) and name else None,
            phi=json_number(raw.get("phi")),
            phi_interval=interval_bounds(raw.get("phi_interval")),
            passed=_flag(raw.get("passed")),
            signals=tuple(
                RecordedSignal.from_json(signal)
                for signal in (signals if isinstance(signals, list) else [])
                if isinstance(signal, Mapping) and isinstance(signal.get("path"), str)
            ),
            data={
                side: data_identity(entry)
                for side in DATA_SIDES
                if isinstance(entry := data.get(side), Mapping)
            }
            if isinstance(data, Mapping)
            else None,
            runtime=ModelRuntime.from_dict(runtime) if isinstance(runtime, Mapping) else None,
        )


@dataclass(frozen=True)
class RecordedRun:
    """A recorded run: its model version, start and commit where known, and its results."""

    specs: tuple[RecordedSpec, ...]
    model_version: str | None = None
    started_utc: str | None = None
    commit: str | None = None

    @classmethod
    def of(cls, results: Iterable[SpecResult], model_version: str | None = None) -> RecordedRun:
        return cls(tuple(RecordedSpec.of(result) for result in results), model_version)

    @classmethod
    def from_json(
        cls, document: Mapping[str, Any], specs: Sequence[Mapping[str, Any]] | None = None
    ) -> RecordedRun:
        """A history record (migrated to the current schema) or a run document: its results
        (``specs``, where the caller picked them out already) and its facts."""
        raw = document.get("specs", []) if specs is None else specs
        version = document.get("model_version", document.get("version"))
        started = document.get("started_utc")
        commit = document.get("commit")
        return cls(
            specs=tuple(
                RecordedSpec.from_json(spec)
                for spec in (raw if isinstance(raw, Sequence) else [])
                if isinstance(spec, Mapping)
            ),
            model_version=version if isinstance(version, str) and version else None,
            started_utc=started if isinstance(started, str) else None,
            commit=commit if isinstance(commit, str) and commit else None,
        )

    def summary(self) -> dict[str, Any]:
        """What a record keeps of the baseline its run was compared with."""
        return {
            "model_version": self.model_version,
            "started_utc": self.started_utc,
            "commit": self.commit,
        }

    def describe(self) -> str:
        """The run in words, as a comparison names its baseline: ``v1.4 (commit 3f2a9c1d0e4b,
        2026-11-28 22:10 UTC)``."""
        started = self.started_utc or ""
        shown = f"commit {self.commit[:12]}, " if self.commit else ""
        return f"{self.model_version} ({shown}{started[:10]} {started[11:16]} UTC)"


#: A run to compare: a recorded run, or the results of the run in hand.
Side = RecordedRun | Sequence[RecordedSpec]


def recorded_specs(side: Side) -> Sequence[RecordedSpec]:
    """The spec results of a run to compare."""
    return side.specs if isinstance(side, RecordedRun) else side


@dataclass(frozen=True)
class RecordedPoint:
    """One run on a signal's trend: its model version, the spec's Φ and the signal's λ."""

    version: str
    phi: float | None
    lambdas: Mapping[str, float | None]

    @classmethod
    def from_json(cls, version: str, phi: Any, lambdas: Any) -> RecordedPoint:
        """A point from what the history's index holds (λ listed in paper order is read too;
        values it cannot place read as none)."""
        return cls(version, json_number(phi), lambdas_or_none(lambdas))

    @classmethod
    def of(cls, version: str, result: SpecResult, signal: SignalResult) -> RecordedPoint:
        return cls(
            version,
            json_number(result.phi),
            {name: json_number(value) for name, value in signal.lambdas.items()},
        )

    def to_dict(self) -> dict[str, Any]:
        return {"version": self.version, "phi": self.phi, "lambdas": dict(self.lambdas)}
