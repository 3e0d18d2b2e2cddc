"""A signal scored over windows, driving phases, conditions and region cells, as results.

The scoring of :mod:`pytest_hevval.scoring.local` fills these; reports, history and the pytest
items read them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from ..core.groups import (
    HOT_FACTOR,
    MIN_GROUP_SAMPLES,
    Concentration,
    CorrelationKind,
    Sums,
    group_lambdas,
)
from .codec import json_numbers, number_or_nan

__all__ = [
    "NAMED_GROUPS",
    "GroupTable",
    "LocalFailure",
    "LocalResult",
    "concentration_sentence",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

#: The failure message names at most this many windows or cells, worst first.
NAMED_GROUPS = 3


def _column(values: Sequence[float], dtype: type = np.float64) -> npt.NDArray[Any]:
    """A table's column as a new read-only array: tables share their rows with the arrays
    they were computed in, and no reader may change them under another."""
    column: npt.NDArray[Any] = np.array(values, dtype=dtype)
    column.flags.writeable = False
    return column


@dataclass(frozen=True, eq=False)
class GroupTable:
    """λ1–λ6 and the physical error of a set of groups (windows, phases, conditions, cells).

    The columns are read-only numpy arrays, one value per group (:meth:`many` and
    :meth:`from_dict` make them so): the tables of a spec of many signals hold hundreds of
    thousands of values, which as Python numbers cost more time to make (and memory to keep)
    than scoring them did.
    """

    labels: tuple[str, ...]
    n: IntArray
    lambdas: Mapping[str, FloatArray]
    #: Share of the record's squared error that lies in each group.
    error_share: FloatArray
    #: RMS and mean error (reference − simulated) per group, in the signal's unit.
    rms: FloatArray
    mean_error: FloatArray

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, GroupTable):
            return NotImplemented
        return (
            self.labels == other.labels
            and np.array_equal(self.n, other.n)
            and self.lambdas.keys() == other.lambdas.keys()
            and all(_same(v, other.lambdas[k]) for k, v in self.lambdas.items())
            and _same(self.error_share, other.error_share)
            and _same(self.rms, other.rms)
            and _same(self.mean_error, other.mean_error)
        )

    __hash__ = None  # type: ignore[assignment]

    @classmethod
    def from_sums(
        cls,
        labels: Sequence[str],
        sums: Sums[FloatArray],
        reference_range: float,
        correlation: str,
        total_sq: float,
        scale: float = 1.0,
    ) -> GroupTable:
        """``sums`` of samples times ``scale`` (see :class:`~pytest_hevval.core.groups.SumTable`);
        ``reference_range`` and the errors kept are in the signal's unit."""
        return cls.many([labels], sums, reference_range, correlation, total_sq, scale)[0]

    @classmethod
    def many(
        cls,
        labels: Sequence[Sequence[str]],
        sums: Sums[FloatArray],
        reference_range: float | FloatArray,
        correlation: str,
        total_sq: float | FloatArray,
        scale: float | FloatArray = 1.0,
    ) -> list[GroupTable]:
        """One table per entry of ``labels``, whose rows follow each other in ``sums``, as
        :meth:`from_sums` of each: one vectorised call for them all, whose arrays the tables
        share. ``reference_range``, ``total_sq`` and ``scale``: one value, or one per row
        (the tables of several signals)."""
        kind: CorrelationKind = "pearson" if correlation == "pearson" else "xcorr"
        lambdas = group_lambdas(sums, np.multiply(reference_range, scale), kind)
        # A copy: the columns are made read-only below, and ``sums`` is the caller's.
        count = np.array(sums.n, dtype=np.int64)
        judged = count >= MIN_GROUP_SAMPLES
        safe = np.maximum(count, 1).astype(np.float64)
        with np.errstate(invalid="ignore", divide="ignore"):
            rms = np.where(judged, np.sqrt(sums.sq_error / safe) / scale, np.nan)
            mean = np.where(judged, sums.error_sum / safe / scale, np.nan)
            share = np.where(np.greater(total_sq, 0.0), sums.sq_error / total_sq, 0.0)
        columns = [count, share, rms, mean, *lambdas.values()]
        for column in columns:
            column.flags.writeable = False
        total = sum(len(names) for names in labels)
        if total != count.shape[0]:
            raise ValueError(f"{total} labels for {count.shape[0]} groups")
        tables = []
        first = 0
        for names in labels:
            part = slice(first, first + len(names))
            first = part.stop
            tables.append(
                cls(
                    labels=tuple(names),
                    n=count[part],
                    lambdas={name: v[part] for name, v in lambdas.items()},
                    error_share=share[part],
                    rms=rms[part],
                    mean_error=mean[part],
                )
            )
        return tables

    def judged(self, min_samples: int = MIN_GROUP_SAMPLES) -> list[int]:
        """The groups with enough samples to be judged (never fewer than
        :data:`~pytest_hevval.core.groups.MIN_GROUP_SAMPLES`), in order."""
        return [int(k) for k in np.flatnonzero(self.n >= max(min_samples, MIN_GROUP_SAMPLES))]

    def to_dict(self) -> dict[str, Any]:
        return {
            "labels": list(self.labels),
            "n": self.n.tolist(),
            "lambdas": {k: json_numbers(vs) for k, vs in self.lambdas.items()},
            "error_share": json_numbers(self.error_share),
            "rms": json_numbers(self.rms),
            "mean_error": json_numbers(self.mean_error),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> GroupTable:
        """The inverse of :meth:`to_dict`. A history record keeps the windows without their λ
        and error shares (:func:`~pytest_hevval.results.record_schema.normalised_spec`): a
        column missing reads as none (λ) or undefined (NaN)."""
        labels = tuple(data["labels"])

        def numbers(key: str) -> npt.NDArray[Any]:
            values = data.get(key)
            if values is None:
                return _column([math.nan] * len(labels))
            return _column([number_or_nan(v) for v in values])

        return cls(
            labels=labels,
            n=_column([int(v) for v in data["n"]], np.int64),
            lambdas={
                k: _column([number_or_nan(v) for v in vs])
                for k, vs in dict(data.get("lambdas") or {}).items()
            },
            error_share=numbers("error_share"),
            rms=numbers("rms"),
            mean_error=numbers("mean_error"),
        )


def _same(a: FloatArray, b: FloatArray) -> bool:
    return a.shape == b.shape and bool(np.array_equal(a, b, equal_nan=True))


@dataclass(frozen=True)
class LocalResult:
    """One signal over windows, phases, conditions and region cells."""

    windows: GroupTable
    #: (start, stop) of every window in seconds on the record's clock.
    spans_s: tuple[tuple[float, float], ...]
    concentration: Mapping[str, Any]
    phases: GroupTable | None = None
    #: Per condition: the groups "holds" and "rest".
    conditions: Mapping[str, GroupTable] = field(default_factory=dict)
    regions: GroupTable | None = None

    def worst_windows(self, count: int = NAMED_GROUPS) -> list[int]:
        """Indices of the windows holding the most squared error, worst first (the earlier of
        two equal ones first)."""
        share = self.windows.error_share
        order = np.argsort(-share, kind="stable")[:count]
        return [int(k) for k in order if share[k] > 0]

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "windows": {**self.windows.to_dict(), "spans_s": [list(s) for s in self.spans_s]},
            "concentration": dict(self.concentration),
        }
        if self.phases is not None:
            out["phases"] = self.phases.to_dict()
        if self.conditions:
            out["conditions"] = {k: v.to_dict() for k, v in self.conditions.items()}
        if self.regions is not None:
            out["regions"] = self.regions.to_dict()
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> LocalResult:
        windows = data["windows"]
        return cls(
            windows=GroupTable.from_dict(windows),
            spans_s=tuple((float(a), float(b)) for a, b in windows.get("spans_s") or ()),
            concentration=dict(data.get("concentration", {})),
            phases=GroupTable.from_dict(data["phases"]) if data.get("phases") else None,
            conditions={
                k: GroupTable.from_dict(v) for k, v in dict(data.get("conditions") or {}).items()
            },
            regions=GroupTable.from_dict(data["regions"]) if data.get("regions") else None,
        )


@dataclass(frozen=True)
class LocalFailure:
    """A window or cell gate missed: which characteristic, where, and by how much."""

    scope: str  # "windows" or "regions"
    characteristic: str
    #: The worst value among the groups that missed, and its threshold.
    value: float
    threshold: float
    #: Labels of the groups that missed, worst first.
    where: tuple[str, ...]
    passed: int
    judged: int
    required_share: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "scope": self.scope,
            "characteristic": self.characteristic,
            "value": self.value,
            "threshold": self.threshold,
            "where": list(self.where),
            "passed": self.passed,
            "judged": self.judged,
            "required_share": self.required_share,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> LocalFailure:
        return cls(
            scope=str(data["scope"]),
            characteristic=str(data["characteristic"]),
            value=float(data["value"]),
            threshold=float(data["threshold"]),
            where=tuple(data.get("where", ())),
            passed=int(data["passed"]),
            judged=int(data["judged"]),
            required_share=float(data["required_share"]),
        )


def concentration_sentence(found: Concentration) -> str:
    """How concentrated the error is, in words; results carry it as ``concentration.sentence``."""
    if not found.windows:
        return f"the error is spread out: no window above {HOT_FACTOR:g}× the mean square"
    spans = ", ".join(f"{a:.0f}–{b:.0f} s" for a, b in found.spans_s[:3])
    more = f" (+{len(found.spans_s) - 3} more)" if len(found.spans_s) > 3 else ""
    return (
        f"{found.error_share:.0%} of the squared error lies in {found.time_share:.0%} of the "
        f"time, in {found.windows} window{'s' if found.windows != 1 else ''}: {spans}{more}"
    )
