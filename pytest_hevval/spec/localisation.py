"""Where in a recording a model is judged: ``local`` (sliding windows, phases, named
conditions) and ``regions`` (cells of a map over one or two operating variables), each with
its optional gate.

Windows and cells are scored on λ1–λ6 only, so every threshold table they are given is checked
against those.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping

from ..defaults import LOCAL_WINDOW_S, REGION_BINS, REGION_MIN_SAMPLES
from .model import ConditionSpec, LocalGate, LocalSpec, RegionSpec, SignalSpec
from .thresholds import thresholds_of
from .validate import Context, join, parse_expression
from .yaml_lines import LineDict

__all__ = ["MAX_REGION_CELLS", "check_local_scored", "local_of", "regions_of"]

_LOCAL_KEYS = ("window_s", "phases", "conditions", "gate")
_REGION_KEYS = ("by", "bins", "min_samples", "gate")
_GATE_KEYS = ("thresholds", "share")
_CONDITION_KEYS = ("when", "thresholds")
#: The most cells a region map may have (its bins multiplied): each is scored per signal.
MAX_REGION_CELLS = 100_000


def check_local_scored(
    context: Context, table: Mapping[str, float], node: SignalSpec | None, key: str
) -> None:
    """Windows and cells are scored on λ1–λ6 only: λ7 and whole-record metrics have no part."""
    from ..core.groups import LOCAL_CHARACTERISTICS

    for name in table:
        if name not in LOCAL_CHARACTERISTICS:
            raise context.error(
                node.line if node else 1,
                join(join(node.key, key) if node else key, name),
                f"{name!r} is not scored over windows or region cells",
                hint="use one of " + ", ".join(LOCAL_CHARACTERISTICS),
            )


def _local_gate(context: Context, mapping: LineDict, key: str) -> LocalGate | None:
    if "gate" not in mapping or mapping["gate"] is None:
        return None
    where = join(key, "gate")
    gate = context.mapping(mapping["gate"], mapping.line_of("gate"), where)
    context.check_keys(gate, _GATE_KEYS, where)
    thresholds = thresholds_of(context, gate, "thresholds", join(where, "thresholds"))
    if not thresholds:
        raise context.error(
            gate.line,
            join(where, "thresholds"),
            "is required: the characteristics every window or cell must reach",
            hint="for example thresholds: {mae: 0.9}",
        )
    return LocalGate(
        thresholds=thresholds,
        share=context.get(gate, "share", where, context.unit_interval, 1.0),
        line=gate.line,
    )


def local_of(context: Context, top: LineDict) -> LocalSpec | None:
    """``local: {window_s, phases, conditions, gate}``, or None when the spec has none."""
    key = "local"
    mapping = context.section(top, key, _LOCAL_KEYS)
    if mapping is None:
        return None
    conditions: list[ConditionSpec] = []
    if mapping.get("conditions") is not None:
        where = join(key, "conditions")
        table = context.mapping(mapping["conditions"], mapping.line_of("conditions"), where)
        for name, value in table.items():
            line = table.line_of(name)
            entry = join(where, str(name))
            if isinstance(value, LineDict):
                context.check_keys(value, _CONDITION_KEYS, entry)
                if "when" not in value:
                    raise context.error(line, join(entry, "when"), "is required (an expression)")
                expression = parse_expression(
                    context, value["when"], value.line_of("when"), join(entry, "when")
                )
                thresholds = thresholds_of(context, value, "thresholds", join(entry, "thresholds"))
            else:
                expression = parse_expression(context, value, line, entry)
                thresholds = {}
            conditions.append(ConditionSpec(str(name), expression, line, thresholds))
    return LocalSpec(
        window_s=context.get(mapping, "window_s", key, context.positive, LOCAL_WINDOW_S),
        line=top.line_of(key),
        phases=context.get(
            mapping, "phases", key, lambda v, ln, k: parse_expression(context, v, ln, k), None
        ),
        conditions=tuple(conditions),
        gate=_local_gate(context, mapping, key),
    )


def _region_bins(
    context: Context, mapping: LineDict, key: str, variables: int
) -> tuple[tuple[float, ...] | int, ...]:
    if mapping.get("bins") is None:
        return (REGION_BINS,) * variables
    where = join(key, "bins")
    raw = mapping["bins"]
    line = mapping.line_of("bins")
    if isinstance(raw, int) and not isinstance(raw, bool):
        raw = [raw] * variables
    if not isinstance(raw, list) or len(raw) != variables:
        raise context.error(
            line,
            where,
            f"must give one entry per variable of by ({variables}): a bin count or a list of edges",
            got=raw,
        )
    bins: list[tuple[float, ...] | int] = []
    for i, item in enumerate(raw):
        entry = join(where, i)
        if isinstance(item, int) and not isinstance(item, bool):
            if item < 1:
                raise context.error(line, entry, "a bin count must be at least 1", got=item)
            bins.append(item)
            continue
        if isinstance(item, list) and len(item) > MAX_REGION_CELLS + 1:
            raise context.error(
                line, entry, f"may list at most {MAX_REGION_CELLS + 1} edges", got=len(item)
            )
        if not isinstance(item, list) or len(item) < 2:
            raise context.error(
                line, entry, "must be a bin count or a list of at least two edges", got=item
            )
        edges = tuple(context.number(x, line, join(entry, j)) for j, x in enumerate(item))
        if any(b <= a for a, b in itertools.pairwise(edges)):
            raise context.error(line, entry, "bin edges must increase", got=list(edges))
        bins.append(edges)
    cells = math.prod(b if isinstance(b, int) else len(b) - 1 for b in bins)
    if cells > MAX_REGION_CELLS:
        raise context.error(
            line,
            where,
            f"makes {cells:,} region cells, over the limit of {MAX_REGION_CELLS:,}",
            hint="use fewer bins: each cell needs samples of its own to be judged",
        )
    return tuple(bins)


def regions_of(context: Context, top: LineDict) -> RegionSpec | None:
    """``regions: {by, bins, min_samples, gate}``, or None when the spec has none."""
    key = "regions"
    mapping = context.section(top, key, _REGION_KEYS)
    if mapping is None:
        return None
    raw_by = mapping.get("by")
    line = mapping.line_of("by") if "by" in mapping else mapping.line
    if isinstance(raw_by, str):
        raw_by = [raw_by]
    if not isinstance(raw_by, list) or not 1 <= len(raw_by) <= 2:
        raise context.error(
            line,
            join(key, "by"),
            "must name one or two operating variables (columns or expressions of the reference)",
            got=raw_by,
        )
    by = tuple(
        parse_expression(context, item, line, join(join(key, "by"), i))
        for i, item in enumerate(raw_by)
    )
    min_samples = context.get(
        mapping, "min_samples", key, context.positive, float(REGION_MIN_SAMPLES)
    )
    return RegionSpec(
        by=by,
        bins=_region_bins(context, mapping, key, len(by)),
        min_samples=max(1, int(min_samples)),
        line=top.line_of(key),
        gate=_local_gate(context, mapping, key),
    )
