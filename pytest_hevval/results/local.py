"""A signal scored over windows, driving phases, conditions and region cells, as results.

The scoring of :mod:`pytest_hevval.scoring.local` fills these; reports, history and the pytest
items read them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from ..core.local import (
    HOT_FACTOR,
    MIN_GROUP_SAMPLES,
    Concentration,
    CorrelationKind,
    GroupSums,
    group_lambdas,
)
from .codec import json_number, number_or_nan

__all__ = [
    "NAMED_GROUPS",
    "GroupTable",
    "LocalFailure",
    "LocalResult",
    "concentration_sentence",
]

FloatArray = npt.NDArray[np.float64]

#: The failure message names at most this many windows or cells, worst first.
NAMED_GROUPS = 3


@dataclass(frozen=True)
class GroupTable:
    """λ1–λ6 and the physical error of a set of groups (windows, phases, conditions, cells)."""

    labels: tuple[str, ...]
    n: tuple[int, ...]
    lambdas: Mapping[str, tuple[float, ...]]
    #: Share of the record's squared error that lies in each group.
    error_share: tuple[float, ...]
    #: RMS and mean error (reference − simulated) per group, in the signal's unit.
    rms: tuple[float, ...]
    mean_error: tuple[float, ...]

    @classmethod
    def from_sums(
        cls,
        labels: Sequence[str],
        sums: GroupSums,
        reference_range: float,
        correlation: str,
        total_sq: float,
        scale: float = 1.0,
    ) -> GroupTable:
        """``sums`` of samples times ``scale`` (see :class:`~pytest_hevval.core.local.SumTable`);
        ``reference_range`` and the errors kept are in the signal's unit."""
        return cls.many([labels], sums, reference_range, correlation, total_sq, scale)[0]

    @classmethod
    def many(
        cls,
        labels: Sequence[Sequence[str]],
        sums: GroupSums,
        reference_range: float | FloatArray,
        correlation: str,
        total_sq: float | FloatArray,
        scale: float | FloatArray = 1.0,
    ) -> list[GroupTable]:
        """One table per entry of ``labels``, whose rows follow each other in ``sums``, as
        :meth:`from_sums` of each: one vectorised call for them all. ``reference_range``,
        ``total_sq`` and ``scale``: one value, or one per row (the tables of several signals)."""
        kind: CorrelationKind = "pearson" if correlation == "pearson" else "xcorr"
        lambdas = group_lambdas(sums, np.multiply(reference_range, scale), kind)
        n = sums.n.astype(np.float64)
        judged = sums.n >= MIN_GROUP_SAMPLES
        safe = np.maximum(n, 1.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            rms = np.where(judged, np.sqrt(sums.sq_error / safe) / scale, np.nan)
            mean = np.where(judged, sums.error_sum / safe / scale, np.nan)
            share = np.where(np.greater(total_sq, 0.0), sums.sq_error / total_sq, 0.0)
        # tolist() makes Python numbers in one call (a float() per value costs a signal of
        # many cells milliseconds).
        columns = {
            "n": np.asarray(sums.n, dtype=np.int64).tolist(),
            "error_share": np.asarray(share, dtype=np.float64).tolist(),
            "rms": np.asarray(rms, dtype=np.float64).tolist(),
            "mean_error": np.asarray(mean, dtype=np.float64).tolist(),
        }
        values = {name: np.asarray(v, dtype=np.float64).tolist() for name, v in lambdas.items()}
        tables = []
        first = 0
        for names in labels:
            part = slice(first, first + len(names))
            first = part.stop
            tables.append(
                cls(
                    labels=tuple(names),
                    n=tuple(columns["n"][part]),
                    lambdas={name: tuple(v[part]) for name, v in values.items()},
                    error_share=tuple(columns["error_share"][part]),
                    rms=tuple(columns["rms"][part]),
                    mean_error=tuple(columns["mean_error"][part]),
                )
            )
        if first != n.shape[0]:
            raise ValueError(f"{first} labels for {n.shape[0]} groups")
        return tables

    def judged(self, index: int, min_samples: int = MIN_GROUP_SAMPLES) -> bool:
        return self.n[index] >= max(min_samples, MIN_GROUP_SAMPLES)

    def to_dict(self) -> dict[str, Any]:
        return {
            "labels": list(self.labels),
            "n": list(self.n),
            "lambdas": {k: [json_number(v) for v in vs] for k, vs in self.lambdas.items()},
            "error_share": [json_number(v) for v in self.error_share],
            "rms": [json_number(v) for v in self.rms],
            "mean_error": [json_number(v) for v in self.mean_error],
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> GroupTable:
        return cls(
            labels=tuple(data["labels"]),
            n=tuple(int(v) for v in data["n"]),
            lambdas={k: tuple(number_or_nan(v) for v in vs) for k, vs in data["lambdas"].items()},
            error_share=tuple(number_or_nan(v) for v in data["error_share"]),
            rms=tuple(number_or_nan(v) for v in data["rms"]),
            mean_error=tuple(number_or_nan(v) for v in data["mean_error"]),
        )


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
        """Indices of the windows holding the most squared error, worst first."""
        order = sorted(range(len(self.windows.n)), key=lambda k: -self.windows.error_share[k])
        return [k for k in order[:count] if self.windows.error_share[k] > 0]

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
            spans_s=tuple((float(a), float(b)) for a, b in windows["spans_s"]),
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
