"""Where and when the model is wrong: a spec's ``local:`` and ``regions:`` scored and gated.

The samples of a spec's record are labelled once (time window × driving phase × conditions ×
region cell, one *fine* label per sample, shared by every signal); each signal's sums over the
fine labels come from one pass of :func:`pytest_hevval.core.local.labelled_table`, and every
table (windows, phases, conditions, cells) is a merge of that small fine table. The tables, the
concentration of the error and the window and cell gates end up in each signal's result; the
grid, the coverage and Φ per window and per cell in the spec's.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from .core.local import (
    LOCAL_CHARACTERISTICS,
    MIN_GROUP_SAMPLES,
    PHASES,
    CorrelationKind,
    GroupSums,
    concentration,
    driving_phases,
    group_lambdas,
    labelled_table,
    region_grid,
)
from .core.tree import global_metric_arrays
from .spec.model import LocalGate, SignalSpec, Spec

__all__ = [
    "GroupTable",
    "Labels",
    "LocalFailure",
    "LocalResult",
    "compact_local",
    "label_samples",
    "local_failures",
    "local_phi",
    "score_local",
    "spec_local_summary",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

#: A gated window takes a condition's thresholds when the condition holds for more than this
#: share of its samples.
CONDITION_MAJORITY = 0.5
#: The failure message names at most this many windows or cells, worst first.
NAMED_GROUPS = 3


def _json_float(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _float(value: float | None) -> float:
    return math.nan if value is None else float(value)


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
        kind: CorrelationKind = "pearson" if correlation == "pearson" else "xcorr"
        lambdas = group_lambdas(sums, reference_range * scale, kind)
        n = sums.n.astype(np.float64)
        judged = sums.n >= MIN_GROUP_SAMPLES
        safe = np.maximum(n, 1.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            rms = np.where(judged, np.sqrt(sums.sq_error / safe) / scale, np.nan)
            mean = np.where(judged, sums.error_sum / safe / scale, np.nan)
        share = sums.sq_error / total_sq if total_sq > 0 else np.zeros_like(n)
        return cls(
            labels=tuple(labels),
            n=tuple(int(v) for v in sums.n),
            lambdas={name: tuple(float(v) for v in lambdas[name]) for name in lambdas},
            error_share=tuple(float(v) for v in share),
            rms=tuple(float(v) for v in rms),
            mean_error=tuple(float(v) for v in mean),
        )

    def judged(self, index: int, min_samples: int = MIN_GROUP_SAMPLES) -> bool:
        return self.n[index] >= max(min_samples, MIN_GROUP_SAMPLES)

    def to_dict(self) -> dict[str, Any]:
        return {
            "labels": list(self.labels),
            "n": list(self.n),
            "lambdas": {k: [_json_float(v) for v in vs] for k, vs in self.lambdas.items()},
            "error_share": [_json_float(v) for v in self.error_share],
            "rms": [_json_float(v) for v in self.rms],
            "mean_error": [_json_float(v) for v in self.mean_error],
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> GroupTable:
        return cls(
            labels=tuple(data["labels"]),
            n=tuple(int(v) for v in data["n"]),
            lambdas={k: tuple(_float(v) for v in vs) for k, vs in data["lambdas"].items()},
            error_share=tuple(_float(v) for v in data["error_share"]),
            rms=tuple(_float(v) for v in data["rms"]),
            mean_error=tuple(_float(v) for v in data["mean_error"]),
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

    def sentence(self, title: str) -> str:
        noun = "windows" if self.scope == "windows" else "cells"
        named = ", ".join(self.where[:NAMED_GROUPS])
        more = (
            f" (+{len(self.where) - NAMED_GROUPS} more)" if len(self.where) > NAMED_GROUPS else ""
        )
        need = "every one" if self.required_share >= 1.0 else f"{self.required_share:.0%} needed"
        return (
            f"{title} ≥ {self.threshold:.4g} missed in {len(self.where)} of {self.judged} "
            f"{noun} ({self.passed}/{self.judged} pass, {need}): worst {self.value:.4f}; "
            f"{named}{more}"
        )

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


# -- labelling the samples, once per spec ----------------------------------------------------


@dataclass(frozen=True)
class Labels:
    """How a spec's samples fall into windows, phases, conditions and region cells."""

    fine: IntArray
    #: The fine label is a mixed-radix number: window, then phase, conditions and cell (0:
    #: outside the grid, else cell + 1), in this shape.
    shape: tuple[int, ...]
    windows: int
    spans_s: tuple[tuple[float, float], ...]
    window_starts: IntArray
    window_stops: IntArray
    window_labels: tuple[str, ...]
    dt: float
    start_s: float
    phase_axis: int | None = None
    condition_axes: Mapping[str, int] = field(default_factory=dict)
    #: Per window: the condition holding for most of it (None: none does).
    window_condition: tuple[str | None, ...] = ()
    cell_axis: int | None = None
    region: Mapping[str, Any] | None = None

    @property
    def fine_groups(self) -> int:
        return int(np.prod(self.shape))


def _window_label(span: tuple[float, float]) -> str:
    return f"{span[0]:.0f}–{span[1]:.0f} s"


def _format_edge(value: float) -> str:
    return f"{value:.4g}"


def _cell_labels(names: Sequence[str], edges: Sequence[FloatArray]) -> list[str]:
    axes = [
        [f"{name} {_format_edge(e[k])}–{_format_edge(e[k + 1])}" for k in range(e.shape[0] - 1)]
        for name, e in zip(names, edges, strict=True)
    ]
    if len(axes) == 1:
        return axes[0]
    return [f"{a} × {b}" for a in axes[0] for b in axes[1]]


def _edges(values: FloatArray, bins: tuple[float, ...] | int) -> FloatArray:
    if isinstance(bins, int):
        finite = values[np.isfinite(values)]
        low, high = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
        if high <= low:
            high = low + 1.0
        return np.linspace(low, high, bins + 1)
    return np.asarray(bins, dtype=np.float64)


def label_samples(
    spec: Spec,
    time: FloatArray,
    keep: BoolArray | None,
    evaluate: Callable[[Any, str], FloatArray],
) -> Labels | None:
    """Label every scored sample, or None when the spec asks for no localisation.

    ``time`` is the aligned grid; ``keep`` the samples that are scored (gaps removed);
    ``evaluate(expression, key)`` gives a reference expression on the grid.
    """
    if spec.local is None and spec.regions is None:
        return None
    n_grid = time.shape[0]
    dt = float(time[1] - time[0]) if n_grid > 1 else 1.0
    start_s = float(time[0]) if n_grid else 0.0
    window_s = spec.local.window_s if spec.local else None
    size = max(1, round(window_s / dt)) if window_s else max(1, n_grid)
    grid_window = np.arange(n_grid, dtype=np.int64) // size
    windows = int(grid_window[-1]) + 1 if n_grid else 0
    starts = np.arange(windows, dtype=np.int64) * size
    stops = np.minimum(starts + size, n_grid)
    spans = tuple(
        (start_s + float(a) * dt, start_s + float(b) * dt)
        for a, b in zip(starts.tolist(), stops.tolist(), strict=True)
    )

    def scored(values: npt.NDArray[Any]) -> npt.NDArray[Any]:
        return values[keep] if keep is not None else values

    fine = scored(grid_window)

    phase_digit: IntArray | None = None
    if spec.local and spec.local.phases is not None:
        speed = evaluate(spec.local.phases, "local.phases")
        phase_digit = scored(driving_phases(speed, dt).astype(np.int64))
        fine = fine * len(PHASES) + phase_digit

    condition_masks: dict[str, BoolArray] = {}
    for condition in spec.local.conditions if spec.local else ():
        values = evaluate(condition.expression, f"local.conditions.{condition.name}")
        mask = np.asarray(values, dtype=np.float64)
        condition_masks[condition.name] = scored(np.isfinite(mask) & (mask != 0))
        fine = fine * 2 + condition_masks[condition.name].astype(np.int64)

    cell: IntArray | None = None
    cells = 0
    region: dict[str, Any] | None = None
    if spec.regions is not None:
        variables = [
            scored(evaluate(expression, f"regions.by[{i}]"))
            for i, expression in enumerate(spec.regions.by)
        ]
        edges = [_edges(v, b) for v, b in zip(variables, spec.regions.bins, strict=True)]
        grid = region_grid(variables, edges)
        cell = grid.cell
        cells = int(np.prod(grid.shape))
        fine = fine * (cells + 1) + (cell + 1)
        names = [expression.source for expression in spec.regions.by]
        region = {
            "by": names,
            "edges": [e.tolist() for e in grid.edges],
            "shape": list(grid.shape),
            "counts": grid.counts.reshape(-1).tolist(),
            "labels": _cell_labels(names, grid.edges),
            "min_samples": spec.regions.min_samples,
            "unvisited": [list(index) for index in grid.unvisited()],
            "outside": int((grid.cell < 0).sum()),
        }

    shape = [windows]
    phase_axis = None
    if phase_digit is not None:
        phase_axis = len(shape)
        shape.append(len(PHASES))
    condition_axes: dict[str, int] = {}
    for name in condition_masks:
        condition_axes[name] = len(shape)
        shape.append(2)
    cell_axis = None
    if cell is not None:
        cell_axis = len(shape)
        shape.append(cells + 1)

    window_condition: list[str | None] = [None] * windows
    if condition_masks:
        scored_windows = scored(grid_window)
        samples = np.bincount(scored_windows, minlength=windows).astype(np.float64)
        for condition in spec.local.conditions if spec.local else ():
            holds = np.bincount(
                scored_windows, weights=condition_masks[condition.name], minlength=windows
            )
            with np.errstate(invalid="ignore", divide="ignore"):
                majority = holds / np.maximum(samples, 1.0) > CONDITION_MAJORITY
            for k in np.flatnonzero(majority).tolist():
                if window_condition[k] is None:
                    window_condition[k] = condition.name
    return Labels(
        fine=np.ascontiguousarray(fine, dtype=np.int64),
        shape=tuple(shape),
        windows=windows,
        spans_s=spans,
        window_starts=starts,
        window_stops=stops,
        window_labels=tuple(_window_label(span) for span in spans),
        dt=dt,
        start_s=start_s,
        phase_axis=phase_axis,
        condition_axes=condition_axes,
        window_condition=tuple(window_condition),
        cell_axis=cell_axis,
        region=region,
    )


# -- scoring one signal ----------------------------------------------------------------------


def score_local(
    labels: Labels,
    ref: FloatArray,
    sim: FloatArray,
    reference_range: float,
    correlation: str,
) -> LocalResult:
    """One signal's tables over every grouping of ``labels``."""
    fine = labelled_table(ref, sim, labels.fine, labels.fine_groups)
    total_sq = float(fine.sums().sq_error.sum())

    def table(axis: int, names: Sequence[str], rows: slice = slice(None)) -> GroupTable:
        merged = fine.merged(labels.shape, axis).rows(rows)
        return GroupTable.from_sums(
            names, merged.sums(), reference_range, correlation, total_sq, fine.scale
        )

    window_sums = fine.merged(labels.shape, 0).sums()
    windows = GroupTable.from_sums(
        labels.window_labels, window_sums, reference_range, correlation, total_sq, fine.scale
    )
    hot = concentration(
        window_sums, labels.window_starts, labels.window_stops, labels.dt, labels.start_s
    )
    return LocalResult(
        windows=windows,
        spans_s=labels.spans_s,
        concentration={
            "sentence": hot.sentence(),
            "error_share": hot.error_share,
            "time_share": hot.time_share,
            "windows": hot.windows,
            "spans_s": [list(span) for span in hot.spans_s],
        },
        phases=table(labels.phase_axis, PHASES) if labels.phase_axis is not None else None,
        # The condition's bit is 1 where it holds: rows reversed give (holds, rest).
        conditions={
            name: table(axis, ("holds", "rest"), slice(None, None, -1))
            for name, axis in labels.condition_axes.items()
        },
        # Row 0 of the cell axis holds the samples outside the grid.
        regions=(
            table(labels.cell_axis, labels.region["labels"], slice(1, None))
            if labels.cell_axis is not None and labels.region is not None
            else None
        ),
    )


def _gate(
    scope: str,
    table: GroupTable,
    thresholds_of: Callable[[int], Mapping[str, float]],
    gate: LocalGate,
    min_samples: int,
) -> list[LocalFailure]:
    judged = [k for k in range(len(table.n)) if table.judged(k, min_samples)]
    missed: dict[str, list[tuple[float, float, str]]] = {}
    failed_groups: set[int] = set()
    for k in judged:
        for name, limit in thresholds_of(k).items():
            value = table.lambdas[name][k]
            if math.isfinite(value) and value < limit:
                missed.setdefault(name, []).append((value - limit, value, table.labels[k]))
                failed_groups.add(k)
    passed = len(judged) - len(failed_groups)
    if not judged or passed >= gate.share * len(judged) - 1e-9:
        return []
    failures = []
    for name in LOCAL_CHARACTERISTICS:
        if name not in missed:
            continue
        rows = sorted(missed[name])
        worst_margin, worst, _ = rows[0]
        failures.append(
            LocalFailure(
                scope=scope,
                characteristic=name,
                value=worst,
                threshold=worst - worst_margin,
                where=tuple(label for _, _, label in rows),
                passed=passed,
                judged=len(judged),
                required_share=gate.share,
            )
        )
    return failures


def local_failures(
    spec: Spec, node: SignalSpec, labels: Labels | None, local: LocalResult | None
) -> list[LocalFailure]:
    """The window and cell gates of one node (thresholds: spec < node, conditions override)."""
    if labels is None or local is None:
        return []
    failures: list[LocalFailure] = []
    if spec.local and spec.local.gate:
        base = spec.local_thresholds_for(node)
        by_condition = {c.name: c.thresholds for c in spec.local.conditions}

        def window_thresholds(k: int) -> Mapping[str, float]:
            condition = labels.window_condition[k] if labels.window_condition else None
            return {**base, **by_condition.get(condition, {})} if condition else base

        failures += _gate("windows", local.windows, window_thresholds, spec.local.gate, 0)
    if spec.regions and spec.regions.gate and local.regions is not None:
        cell_limits = spec.region_thresholds_for(node)
        failures += _gate(
            "regions",
            local.regions,
            lambda _: cell_limits,
            spec.regions.gate,
            spec.regions.min_samples,
        )
    return failures


# -- the spec's view: coverage and Φ per window and per cell ---------------------------------


def local_phi(
    rows: Sequence[tuple[float, Mapping[str, tuple[float, ...]]]], weights: Mapping[str, float]
) -> list[float | None]:
    """Φ (eq. 14) per group from every signal's λ1–λ6 per group (NaN groups: None)."""
    if not rows:
        return []
    arrays = [
        (alpha, {name: np.asarray(values, dtype=np.float64) for name, values in lambdas.items()})
        for alpha, lambdas in rows
    ]
    beta = {name: weights.get(name, 1.0) for name in LOCAL_CHARACTERISTICS}
    try:
        phi = global_metric_arrays(arrays, beta)
    except ValueError:
        return []
    return [_json_float(float(v)) for v in np.atleast_1d(phi)]


def spec_local_summary(
    spec: Spec,
    labels: Labels | None,
    signals: Sequence[tuple[float, LocalResult]],
    weights: Mapping[str, float],
) -> dict[str, Any] | None:
    """What the report draws for the whole spec: the grid, its coverage and Φ per group."""
    if labels is None:
        return None
    out: dict[str, Any] = {
        "window_s": spec.local.window_s if spec.local else None,
        "spans_s": [list(s) for s in labels.spans_s],
        "phi_windows": local_phi([(a, r.windows.lambdas) for a, r in signals], weights),
    }
    if labels.window_condition and any(labels.window_condition):
        out["window_conditions"] = list(labels.window_condition)
    if labels.region is not None:
        out["regions"] = {
            **labels.region,
            "phi": local_phi(
                [(a, r.regions.lambdas) for a, r in signals if r.regions is not None], weights
            ),
        }
    return out


def compact_local(local: Mapping[str, Any]) -> dict[str, Any]:
    """A signal's ``local`` as history keeps it: every table, but windows without their λ.

    Per-window λ of every signal of every run would make a record as large as the report;
    the windows' samples, RMS and mean error are enough to say which stretches a model change
    improved or broke.
    """
    out = {key: value for key, value in local.items() if key != "windows"}
    windows = local.get("windows")
    if isinstance(windows, Mapping):
        out["windows"] = {
            key: windows[key] for key in ("labels", "n", "rms", "mean_error") if key in windows
        }
    return out
