"""The data side of a spec: where the reference and the model come from and how they are read
(``reference``, ``model``), aligned (``alignment``), checked (``data_quality``) and, for a model
that runs here, timed (``runtime``).

A source is a file (or URL) with its reader options, a model callable, or an FMU with how it
runs; the model's inputs are checked so that it cannot pass by copying a signal it is scored
on.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from ..data.fmu import FMU_INTERFACES, tolerance_problem
from ..data.quality import QUALITY_ACTIONS, QualityLimits
from ..data.record import SourceOptions
from ..data.remote import is_url
from ..defaults import MAX_RUNTIME_REPEAT, RUNTIME_CLOCKS, RUNTIME_REPEAT
from .model import AlignmentSpec, FmuRun, RuntimeSpec, SourceSpec
from .validate import Context, column_list, join, plain_mapping, resolve, string_mapping
from .yaml_lines import LineDict, LineList

__all__ = [
    "alignment_of",
    "check_callable_inputs",
    "data_quality_of",
    "runtime_of",
    "source_of",
    "with_events",
]

_SOURCE_KEYS = (
    "path",
    "time",
    "format",
    "sep",
    "encoding",
    "decimal",
    "group",
    "time_scale",
    "check_time_unit",
    "dbc",
)
#: Keys that only an FMU model takes (docs/data.md#fmu-models).
_FMU_KEYS = ("interface", "start_time", "stop_time", "tolerance")
_MODEL_KEYS = (
    *_SOURCE_KEYS,
    "callable",
    "fmu",
    "params",
    "inputs",
    "driven_by",
    "outputs",
    "step_size",
    *_FMU_KEYS,
)
_ALIGN_KEYS = (
    "rate_hz",
    "window",
    "max_lag_s",
    "offset_s",
    "offset_from",
    "max_offset_s",
    "nan",
    "by",
)
_RUNTIME_KEYS = ("min_realtime_factor", "max_s", "repeat", "clock")


def runtime_of(context: Context, top: LineDict, model: SourceSpec) -> RuntimeSpec:
    """``runtime: {min_realtime_factor, max_s, repeat}`` for a model that runs itself."""
    mapping = context.section(top, "runtime", _RUNTIME_KEYS)
    if mapping is None:
        return RuntimeSpec()
    line = top.line_of("runtime")
    if model.kind == "file":
        raise context.error(
            line,
            "runtime",
            "the model is exported files, which ran elsewhere and carry no runtime to measure",
            hint="remove `runtime:`, or name the model's callable or FMU so that it runs here",
        )
    repeat = context.get(mapping, "repeat", "runtime", context.positive, float(RUNTIME_REPEAT))
    if repeat != int(repeat) or repeat > MAX_RUNTIME_REPEAT:
        raise context.error(
            mapping.line_of("repeat"),
            "runtime.repeat",
            f"must be a whole number of calls from 1 to {MAX_RUNTIME_REPEAT}",
            got=mapping["repeat"],
        )
    return RuntimeSpec(
        min_realtime_factor=context.get(
            mapping, "min_realtime_factor", "runtime", context.positive, None
        ),
        max_s=context.get(mapping, "max_s", "runtime", context.positive, None),
        repeat=int(repeat),
        clock=context.get(
            mapping, "clock", "runtime", context.choice(RUNTIME_CLOCKS), RUNTIME_CLOCKS[0]
        ),
        line=line,
    )


def _formats() -> tuple[str, ...]:
    """Every format `format:` accepts: each registered reader and its usual spellings."""
    from ..data.readers import format_names

    return format_names()


def source_of(
    context: Context,
    value: Any,
    line: int,
    key: str,
    base: Path,
    *,
    path_optional: bool = False,
) -> SourceSpec:
    """``reference`` or ``model``: a file path (or URL) and its reader options, a model
    callable, or an FMU."""
    if isinstance(value, str):
        # Shorthand: `reference: data/trip.csv`.
        mapping = LineDict(path=value)
        mapping.line = line
        mapping.key_lines = {"path": line}
        value = mapping
    mapping = context.mapping(value, line, key)
    allowed = _MODEL_KEYS if key == "model" else _SOURCE_KEYS
    context.check_keys(mapping, allowed, key)
    kinds = [k for k in ("path", "callable", "fmu") if k in mapping]
    if key == "model" and not kinds and path_optional:
        kinds = ["path"]  # each recording names its model output file
    if key == "model" and len(kinds) != 1:
        problem = "needs exactly one of path, callable or fmu"
        raise context.error(mapping.line, key, problem, got=kinds or None)
    if key == "reference" and not kinds:
        if not path_optional:
            raise context.error(mapping.line, key, "needs a path to the measured data file")
        kinds = ["path"]
    kind = kinds[0]
    fmt = context.get(mapping, "format", key, context.choice(_formats()), None)
    extra: dict[str, Any] = {}
    if "check_time_unit" in mapping:
        where = join(key, "check_time_unit")
        extra["check_time_unit"] = context.flag(
            mapping["check_time_unit"], mapping.line_of("check_time_unit"), where
        )
    if "dbc" in mapping:
        if kind != "path":
            raise context.error(
                mapping.line_of("dbc"),
                join(key, "dbc"),
                f"a signal database decodes a CAN log file, not a {kind} model",
                hint="remove `dbc:`",
            )
        fmt = _can_format(context, mapping, key, fmt)
        where = join(key, "dbc")
        database = context.text(mapping["dbc"], mapping.line_of("dbc"), where)
        extra["dbc"] = resolve(context, base, database, mapping.line_of("dbc"), where)
    options = SourceOptions(
        time=context.get(mapping, "time", key, context.text, None),
        format=fmt,
        sep=context.get(mapping, "sep", key, context.text, None),
        encoding=context.get(mapping, "encoding", key, context.text, None),
        decimal=context.get(mapping, "decimal", key, context.text, None),
        group=context.get(mapping, "group", key, context.text, None),
        time_scale=context.get(mapping, "time_scale", key, context.positive, None),
        extra=extra,
    )
    path: str | None = None
    if kind in ("path", "fmu") and kind in mapping:
        raw = context.text(mapping[kind], mapping.line_of(kind), join(key, kind))
        where = join(key, kind)
        path = raw if is_url(raw) else resolve(context, base, raw, mapping.line_of(kind), where)
    callable_ref = None
    if kind == "callable":
        callable_ref = context.text(mapping["callable"], mapping.line_of("callable"), key)
        module, sep, function = callable_ref.partition(":")
        if not sep or not module or not function:
            raise context.error(
                mapping.line_of("callable"),
                join(key, "callable"),
                "must look like 'package.module:function'",
                got=callable_ref,
            )
    no_params: dict[str, Any] = {}
    params = context.get(mapping, "params", key, plain_mapping(context), no_params)
    inputs: tuple[str, ...] = ()
    fmu_inputs: dict[str, str] = {}
    if "inputs" in mapping:
        raw_inputs = mapping["inputs"]
        input_key = join(key, "inputs")
        input_line = mapping.line_of("inputs")
        if kind == "fmu":
            fmu_inputs = string_mapping(context, raw_inputs, input_line, input_key)
        else:
            inputs = column_list(context, mapping, "inputs", key)
    driven_by = column_list(context, mapping, "driven_by", key) if "driven_by" in mapping else ()
    fmu_outputs: dict[str, str] = {}
    if "outputs" in mapping:
        fmu_outputs = string_mapping(
            context, mapping["outputs"], mapping.line_of("outputs"), join(key, "outputs")
        )
    return SourceSpec(
        kind="file" if kind == "path" else kind,  # type: ignore[arg-type]
        path=path,
        options=options,
        line=mapping.line,
        callable=callable_ref,
        params=params,
        inputs=inputs,
        fmu_inputs=fmu_inputs,
        driven_by=driven_by,
        fmu_outputs=fmu_outputs,
        step_size=context.get(mapping, "step_size", key, context.positive, None),
        fmu_run=_fmu_run(context, mapping, key, kind),
    )


def _fmu_run(context: Context, mapping: LineDict, key: str, kind: str) -> FmuRun:
    """How an FMU model runs: ``interface``, ``start_time``, ``stop_time``, ``tolerance``."""
    for name in _FMU_KEYS:
        if name in mapping and kind != "fmu":
            raise context.error(
                mapping.line_of(name),
                join(key, name),
                f"applies to an FMU model, not a {'file' if kind == 'path' else kind}",
                hint=f"remove `{name}:`",
            )
    interface = context.get(mapping, "interface", key, context.choice(tuple(FMU_INTERFACES)), None)
    start = context.get(mapping, "start_time", key, context.number, None)
    stop = context.get(mapping, "stop_time", key, context.number, None)
    if start is not None and stop is not None and stop <= start:
        raise context.error(
            mapping.line_of("stop_time"),
            join(key, "stop_time"),
            f"must be later than start_time ({start:g})",
            got=stop,
        )
    tolerance = context.get(mapping, "tolerance", key, context.number, None)
    problem = None if tolerance is None else tolerance_problem(tolerance)
    if problem is not None:
        raise context.error(
            mapping.line_of("tolerance"), join(key, "tolerance"), problem, got=tolerance
        )
    return FmuRun(interface=interface, start_time=start, stop_time=stop, tolerance=tolerance)


def with_events(source: SourceSpec) -> SourceSpec:
    """``source`` read with events: two rows at one time stamp (docs/data.md#fmu-models)."""
    options = dataclasses.replace(source.options, extra={**source.options.extra, "events": True})
    return dataclasses.replace(source, options=options)


def check_callable_inputs(context: Context, model: SourceSpec, scored: set[str]) -> None:
    """A model callable handed a signal it is scored on can pass by copying it: that takes
    saying so, under ``driven_by:``."""
    for i, name in enumerate(model.inputs):
        if name in scored and name not in model.driven_by:
            raise context.error(
                model.line,
                f"model.inputs[{i}]",
                f"{name!r} is a measured signal the spec scores; a model handed it can pass by "
                "copying it",
                hint=f"if the model is meant to be driven by it (a drive cycle's speed), list "
                f"{name!r} under `driven_by:` instead",
            )


def _can_format(context: Context, mapping: LineDict, key: str, fmt: str | None) -> str:
    """A source with a signal database is a CAN log, MDF4 bus logging included."""
    if fmt in (None, "can", "mdf"):
        return "can"
    raise context.error(
        mapping.line_of("dbc"),
        join(key, "dbc"),
        f"a signal database decodes CAN logs, not {fmt} files",
        hint="remove `dbc:`, or set `format: can` for a BLF, ASC, candump or MDF4 bus log",
    )


def alignment_of(context: Context, top: LineDict) -> AlignmentSpec:
    """``alignment: {rate_hz, window, max_lag_s, offset_s, offset_from, …}``."""
    mapping = context.section(top, "alignment", _ALIGN_KEYS)
    if mapping is None:
        return AlignmentSpec()
    key = "alignment"
    window = None
    if "window" in mapping:
        raw = mapping["window"]
        line = mapping.line_of("window")
        if not isinstance(raw, LineList) or len(raw) != 2:
            raise context.error(
                line, "alignment.window", "must be [start, stop] in seconds", got=raw
            )
        start = context.number(raw[0], line, "alignment.window[0]")
        stop = context.number(raw[1], line, "alignment.window[1]")
        if stop <= start:
            raise context.error(
                line, "alignment.window", "stop must be later than start", got=[start, stop]
            )
        window = (start, stop)
    offset_from = None
    if "offset_from" in mapping:
        raw = mapping["offset_from"]
        line = mapping.line_of("offset_from")
        if isinstance(raw, str):
            offset_from = (raw, raw)
        elif isinstance(raw, LineDict) and set(raw) == {"ref", "sim"}:
            offset_from = (
                context.text(raw["ref"], line, "alignment.offset_from.ref"),
                context.text(raw["sim"], line, "alignment.offset_from.sim"),
            )
        else:
            raise context.error(
                line,
                "alignment.offset_from",
                "must be a column name or {ref: column, sim: column}",
                got=raw,
            )
    return AlignmentSpec(
        rate_hz=context.get(mapping, "rate_hz", key, context.positive, None),
        window=window,
        max_lag_s=context.get(mapping, "max_lag_s", key, context.non_negative, None),
        offset_s=context.get(mapping, "offset_s", key, context.number, 0.0),
        offset_from=offset_from,
        max_offset_s=context.get(mapping, "max_offset_s", key, context.positive, 30.0),
        nan=context.get(mapping, "nan", key, context.choice(("raise", "omit")), "raise"),  # type: ignore[arg-type]
        by=context.get(mapping, "by", key, context.choice(("time", "clock")), "time"),  # type: ignore[arg-type]
    )


_QUALITY_KEYS = (
    "action",
    "max_gap_s",
    "straight_run_s",
    "flat_run_s",
    "saturation_run_s",
    "rate_limits",
)


def data_quality_of(context: Context, top: LineDict) -> QualityLimits:
    """``data_quality``: the action on a finding and the limits each check applies."""
    key = "data_quality"
    mapping = context.section(top, key, _QUALITY_KEYS)
    if mapping is None:
        return QualityLimits()
    defaults = QualityLimits()
    rate_limits: dict[str, float] = {}
    if "rate_limits" in mapping:
        where = join(key, "rate_limits")
        table = context.mapping(mapping["rate_limits"], mapping.line_of("rate_limits"), where)
        rate_limits = {
            str(name): context.positive(value, table.line_of(name), join(where, name))
            for name, value in table.items()
        }
    return QualityLimits(
        action=context.get(mapping, "action", key, context.choice(QUALITY_ACTIONS), "warn"),  # type: ignore[arg-type]
        max_gap_s=context.get(mapping, "max_gap_s", key, context.positive, defaults.max_gap_s),
        straight_run_s=context.get(
            mapping, "straight_run_s", key, context.positive, defaults.straight_run_s
        ),
        flat_run_s=context.get(mapping, "flat_run_s", key, context.positive, defaults.flat_run_s),
        saturation_run_s=context.get(
            mapping, "saturation_run_s", key, context.positive, defaults.saturation_run_s
        ),
        rate_limits=rate_limits,
    )
