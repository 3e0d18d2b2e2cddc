"""A spec's two records on one time grid: the columns its signals read, quality-checked and aligned.

Also the reference expressions that label samples into windows, phases, conditions and region
cells (:func:`labels_of`), read on the same grid.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from ..data.align import AlignedData, align_records
from ..data.quality import assess, fail_on, mask_on_grid
from ..data.record import Record
from ..errors import DegenerateSignalError, ExpressionError, SpecError, did_you_mean
from ..spec.expressions import Expression
from ..spec.model import SignalSpec, Spec
from .local import Labels, label_samples
from .model_runs import check_model_columns
from .signal_arrays import NodePath, columns_of
from .threads import per_item, scoring_threads

__all__ = ["align_spec", "labels_of"]

FloatArray = npt.NDArray[np.float64]


def _check_rate_limits(spec: Spec, examined: set[str]) -> None:
    """A rate limit on a channel the quality check does not examine would never run: a
    misspelt channel, most likely, which the spec must hear of."""
    for channel in spec.data_quality.rate_limits:
        if channel not in examined:
            suggestion = did_you_mean(channel, sorted(examined))
            raise SpecError(
                "no signal of the spec reads this measured channel, so its rate limit "
                "would never be checked",
                file=str(spec.path),
                key=f"data_quality.rate_limits.{channel}",
                hint=suggestion
                or "name a measured channel the spec reads: "
                + ", ".join(repr(c) for c in sorted(examined)[:12]),
            )


def align_spec(
    spec: Spec,
    nodes: list[tuple[int, NodePath, SignalSpec]],
    reference: Record,
    model_record: Record,
    workers: int | None = None,
) -> AlignedData:
    """Both records on one time grid, with the columns every signal reads."""
    ref_columns: set[str] = set()
    model_columns: set[str] = set()
    for _, _, node in nodes:
        ref_columns.update(columns_of(node.ref, reference))
        model_columns.update(check_model_columns(node, model_record))
    for expression in _local_expressions(spec):
        ref_columns.update(columns_of(expression, reference))
    alignment = spec.alignment
    _check_rate_limits(spec, ref_columns)
    # On the scoring threads: the channels' values are examined side by side.
    findings = assess(
        reference, sorted(ref_columns), spec.data_quality, threads=scoring_threads(workers)
    )
    if spec.data_quality.action == "error":
        fail_on(findings, reference.source)
    # Whether each model column is finite, found side by side before the alignment asks column
    # by column (the checks above found the reference's).
    per_item(
        lambda channel: channel.finite,
        [model_record.channels[n] for n in sorted(model_columns) if n in model_record.channels],
        scoring_threads(workers),
    )
    aligned = align_records(
        reference,
        model_record,
        reference_columns=sorted(ref_columns),
        model_columns=sorted(model_columns),
        rate_hz=alignment.rate_hz,
        window=alignment.window,
        offset_s=alignment.offset_s,
        offset_from=alignment.offset_from,
        max_offset_s=alignment.max_offset_s,
        # Scoring around bad stretches includes stretches of NaN.
        nan_policy="omit" if spec.data_quality.action == "omit" else alignment.nan,
        by=alignment.by,
    )
    aligned.quality = findings
    if findings and spec.data_quality.action == "omit":
        bad = mask_on_grid(findings, aligned.time)
        aligned.gap_mask = bad if aligned.gap_mask is None else aligned.gap_mask | bad
    return aligned


def _local_expressions(spec: Spec) -> list[Expression]:
    """The reference expressions that cut a record into phases, conditions and cells."""
    expressions: list[Expression] = []
    if spec.local is not None:
        if spec.local.phases is not None:
            expressions.append(spec.local.phases)
        expressions.extend(c.expression for c in spec.local.conditions)
    if spec.regions is not None:
        expressions.extend(spec.regions.by)
    return expressions


def _reference_values(aligned: AlignedData, expression: Expression, key: str) -> FloatArray:
    """A reference column or expression on the grid (phases, conditions, region variables)."""
    record = aligned.reference
    names = columns_of(expression, record)
    method = record.meta.get("interpolation", "linear")
    try:
        columns = aligned.columns("reference", names, method)
        if expression.is_column or names == (expression.source,):
            return np.asarray(columns[names[0]], dtype=np.float64)
        return np.asarray(expression.evaluate(columns, aligned.time), dtype=np.float64)
    except ExpressionError as exc:
        raise exc.with_context(key=key) from None


def labels_of(spec: Spec, aligned: AlignedData) -> Labels | None:
    keep = None
    if aligned.gap_mask is not None and aligned.gap_mask.any():
        keep = ~aligned.gap_mask
    try:
        return label_samples(
            spec,
            aligned.time,
            keep,
            lambda expression, key: _reference_values(aligned, expression, key),
        )
    except DegenerateSignalError as exc:
        raise exc.with_context(key="regions") from None
