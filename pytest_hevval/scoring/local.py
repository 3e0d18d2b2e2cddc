"""Where and when the model is wrong: a spec's ``local:`` and ``regions:`` scored and gated.

The samples of a spec's record are labelled once (time window × driving phase × conditions ×
region cell, one *fine* label per sample, shared by every signal) and sorted into the groups
they visit (:class:`pytest_hevval.core.groups.Grouping`); each signal's sums over them (windows,
phases, conditions, cells) come from one pass of :func:`pytest_hevval.core.groups.grouped_tables`
on its scoring thread (:func:`local_sums`), and the λ of every signal's tables from one
vectorised call after the pass (:func:`local_results`). The tables, the
concentration of the error and the window and cell gates end up in each signal's result; the
grid, the coverage and Φ per window and per cell in the spec's.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any

import numpy as np
import numpy.typing as npt

from ..core.groups import (
    LOCAL_CHARACTERISTICS,
    PHASES,
    Grouping,
    Sums,
    SumTable,
    concentration,
    driving_phases,
    grouped_tables,
    region_grid,
)
from ..core.tree import global_metric_arrays
from ..results.codec import json_numbers
from ..results.local_tables import GroupTable, LocalFailure, LocalResult, concentration_sentence
from ..results.spec_facts import LocalGrid, RegionGrid
from ..spec.model import LocalGate, SignalSpec, Spec

__all__ = [
    "Labels",
    "LocalSums",
    "label_samples",
    "local_failures",
    "local_phi",
    "local_results",
    "local_sums",
    "score_local",
    "spec_local_summary",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

#: A gated window takes a condition's thresholds when the condition holds for more than this
#: share of its samples.
CONDITION_MAJORITY = 0.5


# -- labelling the samples, once per spec ----------------------------------------------------


@dataclass(frozen=True)
class Labels:
    """How a spec's samples fall into windows, phases, conditions and region cells."""

    #: The samples' groups: a mixed-radix number over window, then phase, conditions and cell
    #: (0: outside the grid, else cell + 1), sorted once for every signal.
    grouping: Grouping
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
    region: RegionGrid | None = None

    @cached_property
    def tables(self) -> tuple[tuple[tuple[str, ...], ...], npt.NDArray[np.intp]]:
        """Each table's row labels (windows, then phases, conditions and cells, as
        :class:`LocalResult` holds them) and their rows in the grouping's stacked table, all
        tables' one after the other."""
        grouping = self.grouping
        parts: list[tuple[Sequence[str], npt.NDArray[np.intp]]] = [
            (self.window_labels, _axis_rows(grouping, 0))
        ]
        if self.phase_axis is not None:
            parts.append((PHASES, _axis_rows(grouping, self.phase_axis)))
        # The condition's bit is 1 where it holds: rows reversed give (holds, rest).
        for axis in self.condition_axes.values():
            parts.append((("holds", "rest"), _axis_rows(grouping, axis)[::-1]))
        if self.cell_axis is not None and self.region is not None:
            # Row 0 of the cell axis holds the samples outside the grid.
            parts.append((self.region.labels, _axis_rows(grouping, self.cell_axis)[1:]))
        names = tuple(tuple(labels) for labels, _ in parts)
        return names, np.concatenate([rows for _, rows in parts])


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
    region: RegionGrid | None = None
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
        region = RegionGrid(
            by=tuple(names),
            edges=tuple(tuple(e.tolist()) for e in grid.edges),
            shape=tuple(grid.shape),
            counts=tuple(grid.counts.reshape(-1).tolist()),
            labels=tuple(_cell_labels(names, grid.edges)),
            min_samples=spec.regions.min_samples,
            unvisited=tuple(tuple(index) for index in grid.unvisited()),
            outside=int((grid.cell < 0).sum()),
        )

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
        grouping=Grouping.of(fine, shape),
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


@dataclass(frozen=True)
class LocalSums:
    """One signal's sums over the rows of its labels' tables (:attr:`Labels.tables`), taken
    on its scoring thread; :func:`local_results` turns the sums of every signal into tables
    at once."""

    table: SumTable
    #: The signal's normalising range R, in its unit.
    reference_range: float


def local_sums(
    labels: Labels,
    ref: FloatArray,
    sim: FloatArray,
    reference_range: float,
    summed: FloatArray | None = None,
) -> LocalSums:
    """One signal's sums over every grouping of ``labels``; ``summed``: its groups' sums if the
    core's main pass took them (``SignalCharacteristics.group_sums``)."""
    stacked = grouped_tables(ref, sim, labels.grouping, summed=summed)
    return LocalSums(stacked.rows(labels.tables[1]), reference_range)


def local_results(
    labels: Labels, signals: Sequence[LocalSums], correlation: str
) -> list[LocalResult]:
    """The tables of every signal of a spec and where its error concentrates, from their
    :func:`local_sums`: their λ come from one vectorised call over all signals' rows (a call
    per signal spent more time in numpy's overhead, holding the interpreter, than in the
    arithmetic)."""
    if not signals:
        return []
    names, table_rows = labels.tables
    rows = table_rows.shape[0]
    shifts = np.array([s.table.shift for s in signals], dtype=np.float64)
    scales = np.array([s.table.scale for s in signals], dtype=np.float64)
    sums = Sums.of_table(np.concatenate([s.table.values for s in signals]), np.repeat(shifts, rows))
    # The windows' squared error of each signal: the share of it in each group.
    window_sq = sums.sq_error.reshape(len(signals), rows)[:, : labels.windows].sum(axis=1)
    ranges = np.array([s.reference_range for s in signals], dtype=np.float64)
    tables = GroupTable.many(
        names * len(signals),
        sums,
        np.repeat(ranges, rows),
        correlation,
        np.repeat(window_sq, rows),
        np.repeat(scales, rows),
    )
    out = []
    for k in range(len(signals)):
        signal_tables = iter(tables[k * len(names) : (k + 1) * len(names)])
        window_table = next(signal_tables)
        hot = concentration(
            sums.rows(slice(k * rows, k * rows + labels.windows)),
            labels.window_starts,
            labels.window_stops,
            labels.dt,
            labels.start_s,
        )
        out.append(
            LocalResult(
                windows=window_table,
                spans_s=labels.spans_s,
                concentration={
                    "sentence": concentration_sentence(hot),
                    "error_share": hot.error_share,
                    "time_share": hot.time_share,
                    "windows": hot.windows,
                    "spans_s": [list(span) for span in hot.spans_s],
                },
                phases=next(signal_tables) if labels.phase_axis is not None else None,
                conditions={name: next(signal_tables) for name in labels.condition_axes},
                regions=(
                    next(signal_tables)
                    if labels.cell_axis is not None and labels.region is not None
                    else None
                ),
            )
        )
    return out


def score_local(
    labels: Labels,
    ref: FloatArray,
    sim: FloatArray,
    reference_range: float,
    correlation: str,
    summed: FloatArray | None = None,
) -> LocalResult:
    """One signal's tables over every grouping of ``labels`` (:func:`local_sums` and
    :func:`local_results` of it alone)."""
    sums = local_sums(labels, ref, sim, reference_range, summed)
    return local_results(labels, [sums], correlation)[0]


def _axis_rows(grouping: Grouping, axis: int) -> npt.NDArray[np.intp]:
    rows = grouping.rows(axis)
    return np.arange(rows.start, rows.stop, dtype=np.intp)


def _gate(
    scope: str,
    table: GroupTable,
    thresholds_of: Callable[[int], Mapping[str, float]],
    gate: LocalGate,
    min_samples: int,
) -> list[LocalFailure]:
    judged = table.judged(min_samples)
    values = {name: column.tolist() for name, column in table.lambdas.items()}
    missed: dict[str, list[tuple[float, float, str]]] = {}
    failed_groups: set[int] = set()
    for k in judged:
        for name, limit in thresholds_of(k).items():
            value = values[name][k]
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
    rows: Sequence[tuple[float, Mapping[str, Sequence[float] | FloatArray]]],
    weights: Mapping[str, float],
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
    return json_numbers(np.atleast_1d(phi))


def spec_local_summary(
    spec: Spec,
    labels: Labels | None,
    signals: Sequence[tuple[float, LocalResult]],
    weights: Mapping[str, float],
) -> LocalGrid | None:
    """What the report draws for the whole spec: the grid, its coverage and Φ per group."""
    if labels is None:
        return None
    region = labels.region
    return LocalGrid(
        window_s=spec.local.window_s if spec.local else None,
        spans_s=labels.spans_s,
        phi_windows=tuple(local_phi([(a, r.windows.lambdas) for a, r in signals], weights)),
        window_conditions=tuple(labels.window_condition)
        if labels.window_condition and any(labels.window_condition)
        else (),
        regions=None
        if region is None
        else replace(
            region,
            phi=tuple(
                local_phi(
                    [(a, r.regions.lambdas) for a, r in signals if r.regions is not None],
                    weights,
                )
            ),
        ),
    )
