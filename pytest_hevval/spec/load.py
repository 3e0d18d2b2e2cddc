"""Validation spec files → :class:`~pytest_hevval.spec.model.Spec`.

Every problem becomes a :class:`~pytest_hevval.errors.SpecError` of the form
``file:line: key.path: problem (got …); did you mean …?``. All spec error messages live here.
"""

from __future__ import annotations

import dataclasses
import glob
import hashlib
import itertools
import math
import os
import re
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple, TypeVar, cast

import yaml

from ..core.measurement import MeasurementUncertainty
from ..core.registry import (
    LAMBDA_ALIASES,
    is_registered,
    registered_characteristics,
    select_characteristics,
)
from ..data.fmu import FMU_INTERFACES, tolerance_problem
from ..data.quality import QUALITY_ACTIONS, QualityLimits
from ..data.record import SourceOptions
from ..data.remote import is_url
from ..defaults import (
    LOCAL_WINDOW_S,
    MAX_RUNTIME_REPEAT,
    REGION_BINS,
    REGION_MIN_SAMPLES,
    RUNTIME_CLOCKS,
    RUNTIME_REPEAT,
    UNCERTAINTY_SIGMA,
    WITHIN_UNCERTAINTY,
    requirement_id_problem,
)
from ..errors import ExpressionError, SpecError, did_you_mean
from ..files import read_input, unreadable
from .expressions import Expression, parse_signal
from .model import (
    ID_FIELD,
    ROLES,
    AlignmentSpec,
    CampaignSpec,
    ConditionSpec,
    DiagnosisSpec,
    FmuRun,
    Interpolation,
    LocalGate,
    LocalSpec,
    MeasurementSpec,
    RecordingSpec,
    RegionSpec,
    Role,
    RuntimeSpec,
    SignalSpec,
    SourceSpec,
    Spec,
    model_output_path,
    split_key,
)
from .sidecar import load_sidecar
from .yaml_lines import LineDict, LineList, load_yaml_with_lines

__all__ = [
    "THRESHOLD_ALIASES",
    "characteristic_name",
    "load_spec",
    "load_specs",
    "parse_spec_text",
]

#: ``lambda1`` … ``lambda7`` name the seven characteristics in paper order.
THRESHOLD_ALIASES: dict[str, str] = LAMBDA_ALIASES

_TOP_KEYS = (
    "name",
    "description",
    "reference",
    "model",
    "alignment",
    "thresholds",
    "weights",
    "metrics",
    "min_phi",
    "correlation",
    "emergent",
    "candidates",
    "diagnosis",
    "data_quality",
    "local",
    "regions",
    "recordings",
    "campaign",
    "measurement",
    "requirements",
    "runtime",
    "sets",
)
_DIAGNOSIS_KEYS = ("min_share", "responses", "causes", "groups")
_RECORDING_KEYS = ("id", "path", "model", "role", "params")
_CAMPAIGN_KEYS = ("min_pass_rate", "phi_quantile")
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
_SIGNAL_KEYS = (
    "signal",
    "ref",
    "sim",
    "alpha",
    "unit",
    "description",
    "interpolation",
    "reference_range",
    "thresholds",
    "ref_unit",
    "sim_unit",
    "ref_scale",
    "ref_offset",
    "sim_scale",
    "sim_offset",
    "local_thresholds",
    "region_thresholds",
    "uncertainty",
    "requirements",
    "children",
)
_LOCAL_KEYS = ("window_s", "phases", "conditions", "gate")
_REGION_KEYS = ("by", "bins", "min_samples", "gate")
_GATE_KEYS = ("thresholds", "share")
_MIN_PHI_KEYS = ("value", "on")
#: What ``min_phi: {on: …}`` may judge: Φ itself or a bound of its confidence interval.
_MIN_PHI_ON = ("value", "lower", "upper")
_CONDITION_KEYS = ("when", "thresholds")
_UNCERTAINTY_KEYS = ("abs", "rel", "sigma")
_MEASUREMENT_KEYS = ("within_uncertainty",)
_RUNTIME_KEYS = ("min_realtime_factor", "max_s", "repeat", "clock")
#: The settings of ``measurement.within_uncertainty``, the default first.
_WITHIN_UNCERTAINTY = (WITHIN_UNCERTAINTY, *sorted({"fail", "pass"} - {WITHIN_UNCERTAINTY}))

T = TypeVar("T")


def characteristic_name(name: str) -> str | None:
    """Canonical characteristic name for a name or alias, or None."""
    if is_registered(name):
        return name
    return THRESHOLD_ALIASES.get(name)


def _registered_names() -> tuple[str, ...]:
    return tuple(c.name for c in registered_characteristics())


class _Context:
    """Location bookkeeping while walking the YAML tree."""

    def __init__(self, file: str) -> None:
        self.file = file

    def error(
        self, line: int, key: str, problem: str, *, got: Any = None, hint: str | None = None
    ) -> SpecError:
        text = problem if got is None else f"{problem} (got {_show(got)})"
        return SpecError(text, file=self.file, line=line, key=key or None, hint=hint)

    def mapping(self, value: Any, line: int, key: str) -> LineDict:
        if not isinstance(value, LineDict):
            raise self.error(line, key, "must be a mapping of keys to values", got=value)
        return value

    def check_keys(self, mapping: LineDict, allowed: tuple[str, ...], key: str) -> None:
        for name in mapping:
            if name not in allowed:
                suggestion = did_you_mean(name, allowed)
                raise self.error(
                    mapping.line_of(name),
                    _join(key, name),
                    "unknown key",
                    hint=suggestion or "allowed keys: " + ", ".join(allowed),
                )

    def get(
        self,
        mapping: LineDict,
        name: str,
        key: str,
        convert: Callable[[Any, int, str], T],
        default: T,
    ) -> T:
        if name not in mapping or mapping[name] is None:
            return default
        return convert(mapping[name], mapping.line_of(name), _join(key, name))

    # Converters -----------------------------------------------------------------------------
    def text(self, value: Any, line: int, key: str) -> str:
        if isinstance(value, bool) or not isinstance(value, (str, int, float)):
            raise self.error(line, key, "must be text", got=value)
        return str(value)

    def number(self, value: Any, line: int, key: str) -> float:
        if isinstance(value, str) and _EXPONENT_NUMBER.fullmatch(value.strip()):
            # YAML 1.1 reads 1e3 (no dot) as text; YAML 1.2, and every user, as a thousand.
            value = float(value)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.error(line, key, "must be a number", got=value)
        try:
            number = float(value)
        except OverflowError:
            # An integer written with hundreds of digits is beyond float range.
            number = math.inf
        if not math.isfinite(number):
            raise self.error(line, key, "must be a finite number", got=value)
        return number

    def positive(self, value: Any, line: int, key: str) -> float:
        number = self.number(value, line, key)
        if number <= 0:
            raise self.error(line, key, "must be greater than 0", got=value)
        return number

    def non_negative(self, value: Any, line: int, key: str) -> float:
        number = self.number(value, line, key)
        if number < 0:
            raise self.error(line, key, "must be 0 or more", got=value)
        return number

    def weight(self, value: Any, line: int, key: str) -> float:
        """A weight (β, α): only ratios count, so bounded far below where Σ α·β overflows."""
        number = self.non_negative(value, line, key)
        if number > MAX_WEIGHT:
            raise self.error(
                line,
                key,
                f"must be at most {MAX_WEIGHT:g} (only the ratios of weights count)",
                got=value,
            )
        return number

    def unit_text(self, value: Any, line: int, key: str) -> str:
        """A unit as pint reads it, bounded before pint sees it: pint evaluates powers with
        Python's integers, so ``m * 9**9**9`` would compute for ever."""
        text = self.text(value, line, key)
        problem = None
        if len(text) > _MAX_UNIT_TEXT:
            problem = f"is longer than {_MAX_UNIT_TEXT} characters"
        elif not text.isprintable():
            problem = "must be one line of printable characters"
        elif _CHAINED_POWER.search(text) or any(
            abs(float(power)) > _MAX_UNIT_POWER for power in _POWER.findall(text)
        ):
            problem = f"may raise a unit only to a power of at most {_MAX_UNIT_POWER}, once"
        elif text.count("(") != text.count(")"):
            problem = "has unbalanced parentheses"
        if problem is not None:
            raise self.error(line, key, problem, got=text)
        return text

    def unit_interval(self, value: Any, line: int, key: str) -> float:
        number = self.number(value, line, key)
        if not 0.0 <= number <= 1.0:
            raise self.error(line, key, "must lie between 0 and 1", got=value)
        return number

    def flag(self, value: Any, line: int, key: str) -> bool:
        if not isinstance(value, bool):
            raise self.error(line, key, "must be true or false", got=value)
        return value

    def choice(self, options: tuple[str, ...]) -> Callable[[Any, int, str], str]:
        def convert(value: Any, line: int, key: str) -> str:
            text = self.text(value, line, key)
            if text not in options:
                raise self.error(
                    line,
                    key,
                    "must be one of " + ", ".join(options),
                    got=value,
                    hint=did_you_mean(text, options) or None,
                )
            return text

        return convert


def _show(value: Any) -> str:
    if isinstance(value, LineDict):
        return "a mapping"
    if isinstance(value, LineList):
        return "a list"
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


#: The most cells a region map may have (its bins multiplied): each is scored per signal.
MAX_REGION_CELLS = 100_000
#: The largest weight β or α: weights are relative, and Σ α·β must stay far from overflow.
MAX_WEIGHT = 1e6
#: A number in exponent form without a dot, which YAML 1.1 reads as text (``1e3``).
_EXPONENT_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)[eE][+-]?\d+")
#: Bounds on a unit's text (``ref_unit``, ``sim_unit``, ``unit``).
_MAX_UNIT_TEXT = 64
_MAX_UNIT_POWER = 12
_POWER = re.compile(r"(?:\*\*|\^)\s*\(?\s*([+-]?\d+(?:\.\d*)?)")
_CHAINED_POWER = re.compile(r"(?:\*\*|\^)\s*\(?\s*[+-]?[\d.]+\s*\)?\s*(?:\*\*|\^)")


def _join(key: str, name: str | int) -> str:
    if isinstance(name, int):
        return f"{key}[{name}]"
    return f"{key}.{name}" if key else name


def load_spec(path: str | Path) -> Spec:
    """Read and validate one spec file."""
    spec_path = Path(path)
    try:
        raw = read_input(spec_path)
    except OSError as exc:
        raise SpecError(
            f"cannot read the spec file ({unreadable(spec_path, exc)})", file=str(spec_path)
        ) from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SpecError(
            f"the spec file is not UTF-8 text (byte {exc.start})",
            file=str(spec_path),
            hint="save it as UTF-8",
        ) from None
    spec = parse_spec_text(text, spec_path, hashlib.sha256(raw).hexdigest())
    # Thresholds tightened by --hevval-ratchet live beside the spec; only stricter ones apply.
    sidecar = load_sidecar(spec_path)
    return dataclasses.replace(spec, ratchet=sidecar) if sidecar else spec


def load_specs(target: str | Path) -> tuple[Spec, ...]:
    """The specs a command-line target names: a spec file (every recording of a campaign), or
    ``file::recording`` for one recording of a campaign."""
    path, recording = split_key(str(target))
    specs = load_spec(path).per_recording()
    if recording is None:
        return specs
    chosen = [s for s in specs if s.recording == recording]
    if not chosen:
        known = tuple(str(s.recording) for s in specs if s.recording is not None)
        raise SpecError(
            f"no recording {recording!r} in this spec"
            + ("" if known else " (it is not a campaign)"),
            file=path,
            hint=did_you_mean(recording, known)
            or ("its recordings: " + ", ".join(known) if known else "name the spec file alone"),
        )
    return tuple(chosen)


def parse_spec_text(text: str, path: Path, text_hash: str | None = None) -> Spec:
    """Validate spec text as if it were the file ``path`` (relative paths resolve from it)."""
    file = str(path)
    context = _Context(file)
    try:
        document = load_yaml_with_lines(text)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = mark.line + 1 if mark is not None else None
        problem = (exc.problem or "malformed YAML").strip()
        # An unquoted expression or column name with `*`, `:`, `[` or `&` in it reads as YAML
        # syntax; saying so is worth more than the parser's own words.
        hint = (
            'quote a value that holds *, :, [, ], & or # (ref: "`Motor Torque [Nm]` * 1")'
            if "alphabetic or numeric" in problem or "mapping values are not allowed" in problem
            else None
        )
        raise SpecError(f"invalid YAML: {problem}", file=file, line=line, hint=hint) from None
    except yaml.YAMLError as exc:
        raise SpecError(f"invalid YAML: {exc}", file=file) from None
    except RecursionError:
        raise SpecError(
            "invalid YAML: nested too deeply",
            file=file,
            hint="a spec needs a few levels of nesting; check for runaway brackets or indentation",
        ) from None
    if document is None:
        raise SpecError(
            "the spec file is empty", file=file, line=1, hint="see docs/spec.md for the format"
        )
    top = context.mapping(document, 1, "")
    context.check_keys(top, _TOP_KEYS, "")
    for required in ("reference", "model", "sets"):
        if required not in top:
            raise context.error(
                top.line,
                required,
                "is required",
                hint="see docs/spec.md for the format",
            )
    base = path.parent
    table = "recordings" in top and not _is_pattern(top["reference"], base)
    reference = _source(
        context, top["reference"], top.line_of("reference"), "reference", base, path_optional=table
    )
    model = _source(
        context,
        top["model"],
        top.line_of("model"),
        "model",
        base,
        path_optional=_rows_name_models(top),
    )
    if model.kind == "fmu":
        # An FMU reads inputs in the FMI event convention: two rows at one time stamp.
        reference = _with_events(reference)
    campaign = _campaign(context, top, reference, model, base)
    alignment = _alignment(context, top)
    metrics = _metrics(context, top)
    scored = {c.name for c in select_characteristics(metrics)}
    thresholds = _thresholds(context, top, "thresholds", "thresholds")
    _check_scored(context, thresholds, scored, top.line_of("thresholds"), "thresholds")
    weights = _weights(context, top, scored)
    min_phi, min_phi_on = _min_phi(context, top)
    correlation = context.get(top, "correlation", "", context.choice(("xcorr", "pearson")), "xcorr")
    emergent = context.get(top, "emergent", "", context.choice(("V2", "V1")), "V2")
    candidates = _candidates(context, top)
    diagnosis = _diagnosis(context, top)
    data_quality = _data_quality(context, top)
    sets_value = top["sets"]
    sets_line = top.line_of("sets")
    if not isinstance(sets_value, LineList) or not sets_value:
        raise context.error(
            sets_line, "sets", "must be a non-empty list of signals", got=sets_value
        )
    requirements = _requirements(context, top, "", {})
    roots = tuple(
        _signal(context, item, sets_value.line_of(i), f"sets[{i}]", requirements)
        for i, item in enumerate(sets_value)
    )
    _check_unique_paths(context, roots)
    local = _local(context, top)
    regions = _regions(context, top)
    for _, node in _all_nodes(roots):
        _check_scored(context, node.thresholds, scored, node.line, _join(node.key, "thresholds"))
        _check_local_scored(context, node.local_thresholds, node, "local_thresholds")
        _check_local_scored(context, node.region_thresholds, node, "region_thresholds")
    if local and local.gate:
        _check_local_scored(context, local.gate.thresholds, None, "local.gate.thresholds")
    for condition in local.conditions if local else ():
        _check_local_scored(
            context, condition.thresholds, None, f"local.conditions.{condition.name}.thresholds"
        )
    if regions and regions.gate:
        _check_local_scored(context, regions.gate.thresholds, None, "regions.gate.thresholds")
    _check_phi_defined(context, roots, sets_line)
    if model.kind == "callable":
        _check_callable_inputs(
            context, model, {c for _, node in _all_nodes(roots) for c in node.ref.columns}
        )
    name = context.get(top, "name", "", context.text, _default_name(path))
    if not name.isprintable():
        raise context.error(
            top.line_of("name"), "name", "must be one line of printable characters", got=name
        )
    return Spec(
        path=path,
        name=name,
        text_hash=text_hash or hashlib.sha256(text.encode()).hexdigest(),
        reference=reference,
        model=model,
        sets=roots,
        alignment=alignment,
        description=context.get(top, "description", "", context.text, None),
        thresholds=thresholds,
        weights=weights,
        metrics=metrics,
        min_phi=min_phi,
        min_phi_line=top.line_of("min_phi"),
        min_phi_on=min_phi_on,  # type: ignore[arg-type]
        correlation=correlation,  # type: ignore[arg-type]
        emergent=emergent,  # type: ignore[arg-type]
        candidates=candidates,
        diagnosis=diagnosis,
        data_quality=data_quality,
        local=local,
        regions=regions,
        campaign=campaign,
        measurement=_measurement(context, top),
        requirements=tuple(requirements),
        runtime=_runtime(context, top, model),
    )


def _runtime(context: _Context, top: LineDict, model: SourceSpec) -> RuntimeSpec:
    """``runtime: {min_realtime_factor, max_s, repeat}`` for a model that runs itself."""
    if "runtime" not in top or top["runtime"] is None:
        return RuntimeSpec()
    line = top.line_of("runtime")
    mapping = context.mapping(top["runtime"], line, "runtime")
    context.check_keys(mapping, _RUNTIME_KEYS, "runtime")
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


def _check_phi_defined(context: _Context, roots: Sequence[SignalSpec], line: int) -> None:
    """Φ (eq. 14) divides by Σ α·β; with every α zero it can never be scored (β: _weights)."""
    if not any(node.alpha > 0 for _, node in _all_nodes(roots)):
        raise context.error(
            line,
            "sets",
            "every signal's alpha is zero, so Φ is undefined",
            hint="give at least one signal an alpha above 0",
        )


def _all_nodes(roots: Sequence[SignalSpec]) -> Iterator[tuple[int, SignalSpec]]:
    stack = [(1, root) for root in roots]
    while stack:
        level, node = stack.pop()
        yield level, node
        stack.extend((level + 1, child) for child in node.children)


def _default_name(path: Path) -> str:
    name = path.name
    for suffix in (".hevval.yaml", ".hevval.yml", ".yaml", ".yml"):
        if name.endswith(suffix):
            return name[: -len(suffix)]
    return name


def _formats() -> tuple[str, ...]:
    """Every format `format:` accepts: each registered reader and its usual spellings."""
    from ..data.readers import format_names

    return format_names()


def _source(
    context: _Context,
    value: Any,
    line: int,
    key: str,
    base: Path,
    *,
    path_optional: bool = False,
) -> SourceSpec:
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
        where = _join(key, "check_time_unit")
        extra["check_time_unit"] = context.flag(
            mapping["check_time_unit"], mapping.line_of("check_time_unit"), where
        )
    if "dbc" in mapping:
        if kind != "path":
            raise context.error(
                mapping.line_of("dbc"),
                _join(key, "dbc"),
                f"a signal database decodes a CAN log file, not a {kind} model",
                hint="remove `dbc:`",
            )
        fmt = _can_format(context, mapping, key, fmt)
        where = _join(key, "dbc")
        database = context.text(mapping["dbc"], mapping.line_of("dbc"), where)
        extra["dbc"] = _resolve(context, base, database, mapping.line_of("dbc"), where)
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
        raw = context.text(mapping[kind], mapping.line_of(kind), _join(key, kind))
        where = _join(key, kind)
        path = raw if is_url(raw) else _resolve(context, base, raw, mapping.line_of(kind), where)
    callable_ref = None
    if kind == "callable":
        callable_ref = context.text(mapping["callable"], mapping.line_of("callable"), key)
        module, sep, function = callable_ref.partition(":")
        if not sep or not module or not function:
            raise context.error(
                mapping.line_of("callable"),
                _join(key, "callable"),
                "must look like 'package.module:function'",
                got=callable_ref,
            )
    no_params: dict[str, Any] = {}
    params = context.get(mapping, "params", key, _plain_mapping(context), no_params)
    inputs: tuple[str, ...] = ()
    fmu_inputs: dict[str, str] = {}
    if "inputs" in mapping:
        raw_inputs = mapping["inputs"]
        input_key = _join(key, "inputs")
        input_line = mapping.line_of("inputs")
        if kind == "fmu":
            fmu_inputs = _string_mapping(context, raw_inputs, input_line, input_key)
        else:
            inputs = _column_list(context, mapping, "inputs", key)
    driven_by = _column_list(context, mapping, "driven_by", key) if "driven_by" in mapping else ()
    fmu_outputs: dict[str, str] = {}
    if "outputs" in mapping:
        fmu_outputs = _string_mapping(
            context, mapping["outputs"], mapping.line_of("outputs"), _join(key, "outputs")
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


def _fmu_run(context: _Context, mapping: LineDict, key: str, kind: str) -> FmuRun:
    """How an FMU model runs: ``interface``, ``start_time``, ``stop_time``, ``tolerance``."""
    for name in _FMU_KEYS:
        if name in mapping and kind != "fmu":
            raise context.error(
                mapping.line_of(name),
                _join(key, name),
                f"applies to an FMU model, not a {'file' if kind == 'path' else kind}",
                hint=f"remove `{name}:`",
            )
    interface = context.get(mapping, "interface", key, context.choice(tuple(FMU_INTERFACES)), None)
    start = context.get(mapping, "start_time", key, context.number, None)
    stop = context.get(mapping, "stop_time", key, context.number, None)
    if start is not None and stop is not None and stop <= start:
        raise context.error(
            mapping.line_of("stop_time"),
            _join(key, "stop_time"),
            f"must be later than start_time ({start:g})",
            got=stop,
        )
    tolerance = context.get(mapping, "tolerance", key, context.number, None)
    problem = None if tolerance is None else tolerance_problem(tolerance)
    if problem is not None:
        raise context.error(
            mapping.line_of("tolerance"), _join(key, "tolerance"), problem, got=tolerance
        )
    return FmuRun(interface=interface, start_time=start, stop_time=stop, tolerance=tolerance)


def _with_events(source: SourceSpec) -> SourceSpec:
    """``source`` read with events: two rows at one time stamp (docs/data.md#fmu-models)."""
    options = dataclasses.replace(source.options, extra={**source.options.extra, "events": True})
    return dataclasses.replace(source, options=options)


def _column_list(context: _Context, mapping: LineDict, name: str, key: str) -> tuple[str, ...]:
    raw = mapping[name]
    where = _join(key, name)
    if not isinstance(raw, LineList):
        raise context.error(mapping.line_of(name), where, "must be a list of column names", got=raw)
    return tuple(context.text(v, raw.line_of(i), _join(where, i)) for i, v in enumerate(raw))


def _check_callable_inputs(context: _Context, model: SourceSpec, scored: set[str]) -> None:
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


def _can_format(context: _Context, mapping: LineDict, key: str, fmt: str | None) -> str:
    """A source with a signal database is a CAN log, MDF4 bus logging included."""
    if fmt in (None, "can", "mdf"):
        return "can"
    raise context.error(
        mapping.line_of("dbc"),
        _join(key, "dbc"),
        f"a signal database decodes CAN logs, not {fmt} files",
        hint="remove `dbc:`, or set `format: can` for a BLF, ASC, candump or MDF4 bus log",
    )


def _resolve(context: _Context, base: Path, raw: str, line: int, key: str) -> str:
    if "\x00" in raw:
        raise context.error(line, key, "a file path cannot contain a NUL character", got=raw)
    try:
        # strict=True on 3.13+ reports a symlink loop as OSError (non-strict resolve no longer
        # raises there); earlier versions raise RuntimeError even when not strict. A missing
        # file is not an error here: the reader reports it with what to do.
        return str((base / raw).resolve(strict=True))
    except FileNotFoundError:
        return str((base / raw).resolve())
    except (OSError, RuntimeError) as exc:
        raise context.error(line, key, f"cannot resolve the path ({exc})", got=raw) from None


def _plain_mapping(context: _Context) -> Callable[[Any, int, str], dict[str, Any]]:
    def convert(value: Any, line: int, key: str) -> dict[str, Any]:
        return dict(context.mapping(value, line, key))

    return convert


def _string_mapping(context: _Context, value: Any, line: int, key: str) -> dict[str, str]:
    mapping = context.mapping(value, line, key)
    return {
        str(k): context.text(v, mapping.line_of(k), _join(key, str(k))) for k, v in mapping.items()
    }


def _alignment(context: _Context, top: LineDict) -> AlignmentSpec:
    if "alignment" not in top or top["alignment"] is None:
        return AlignmentSpec()
    mapping = context.mapping(top["alignment"], top.line_of("alignment"), "alignment")
    context.check_keys(mapping, _ALIGN_KEYS, "alignment")
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


def _thresholds(context: _Context, mapping: LineDict, name: str, key: str) -> dict[str, float]:
    if name not in mapping or mapping[name] is None:
        return {}
    table = context.mapping(mapping[name], mapping.line_of(name), key)
    out: dict[str, float] = {}
    allowed = (*_registered_names(), *THRESHOLD_ALIASES)
    for raw_name, value in table.items():
        canonical = characteristic_name(raw_name)
        line = table.line_of(raw_name)
        if canonical is None:
            raise context.error(
                line,
                _join(key, raw_name),
                "unknown characteristic",
                hint=did_you_mean(raw_name, allowed)
                or "use one of " + ", ".join(_registered_names()) + " (or lambda1…lambda7)",
            )
        if canonical in out:
            raise context.error(line, _join(key, raw_name), f"repeats {canonical}")
        out[canonical] = context.unit_interval(value, line, _join(key, raw_name))
    return out


def _metrics(context: _Context, top: LineDict) -> tuple[str, ...]:
    if "metrics" not in top or top["metrics"] is None:
        return ()
    value = top["metrics"]
    line = top.line_of("metrics")
    if not isinstance(value, LineList):
        raise context.error(line, "metrics", "must be a list of characteristic names", got=value)
    names: list[str] = []
    for i, item in enumerate(value):
        key = f"metrics[{i}]"
        name = context.text(item, value.line_of(i), key)
        canonical = characteristic_name(name)
        if canonical is None:
            raise context.error(
                value.line_of(i),
                key,
                f"unknown characteristic {name!r}",
                hint=did_you_mean(name, _registered_names())
                or "registered: " + ", ".join(_registered_names()),
            )
        if canonical not in names:
            names.append(canonical)
    return tuple(names)


def _check_scored(
    context: _Context,
    table: Mapping[str, float],
    scored: set[str],
    line: int,
    key: str,
) -> None:
    for name in table:
        if name not in scored:
            raise context.error(
                line,
                _join(key, name),
                f"characteristic {name!r} is not scored by this spec",
                hint=f"add it to the spec's metrics: [{name}]",
            )


def _weights(context: _Context, top: LineDict, scored: set[str]) -> dict[str, float]:
    if "weights" not in top or top["weights"] is None:
        return {}
    table = context.mapping(top["weights"], top.line_of("weights"), "weights")
    values: dict[str, float] = {}
    for raw_name, value in table.items():
        canonical = characteristic_name(raw_name)
        line = table.line_of(raw_name)
        if canonical is None:
            raise context.error(
                line,
                _join("weights", raw_name),
                "unknown characteristic",
                hint=did_you_mean(raw_name, (*_registered_names(), *THRESHOLD_ALIASES)) or None,
            )
        values[canonical] = context.weight(value, line, _join("weights", raw_name))
    _check_scored(context, values, scored, top.line_of("weights"), "weights")
    effective = [
        values.get(c.name, c.default_weight)
        for c in registered_characteristics()
        if c.name in scored
    ]
    if not any(effective):
        raise context.error(top.line_of("weights"), "weights", "cannot all be 0")
    return values


def _expression(context: _Context, value: Any, line: int, key: str) -> Expression:
    text = context.text(value, line, key)
    try:
        return parse_signal(text)
    except ExpressionError as exc:
        raise SpecError(
            f"{exc.problem} (got {text!r})", file=context.file, line=line, key=key, hint=exc.hint
        ) from None


_QUALITY_KEYS = (
    "action",
    "max_gap_s",
    "straight_run_s",
    "flat_run_s",
    "saturation_run_s",
    "rate_limits",
)


def _data_quality(context: _Context, top: LineDict) -> QualityLimits:
    if "data_quality" not in top or top["data_quality"] is None:
        return QualityLimits()
    key = "data_quality"
    mapping = context.mapping(top[key], top.line_of(key), key)
    context.check_keys(mapping, _QUALITY_KEYS, key)
    defaults = QualityLimits()
    rate_limits: dict[str, float] = {}
    if "rate_limits" in mapping:
        where = _join(key, "rate_limits")
        table = context.mapping(mapping["rate_limits"], mapping.line_of("rate_limits"), where)
        rate_limits = {
            str(name): context.positive(value, table.line_of(name), _join(where, name))
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


def _candidates(context: _Context, top: LineDict) -> dict[str, Expression]:
    if "candidates" not in top or top["candidates"] is None:
        return {}
    table = context.mapping(top["candidates"], top.line_of("candidates"), "candidates")
    return {
        str(name): _expression(context, value, table.line_of(name), _join("candidates", name))
        for name, value in table.items()
    }


def _diagnosis(context: _Context, top: LineDict) -> DiagnosisSpec:
    if "diagnosis" not in top or top["diagnosis"] is None:
        return DiagnosisSpec()
    mapping = context.mapping(top["diagnosis"], top.line_of("diagnosis"), "diagnosis")
    context.check_keys(mapping, _DIAGNOSIS_KEYS, "diagnosis")
    min_share = context.get(mapping, "min_share", "diagnosis", context.unit_interval, None)
    if min_share is not None and min_share >= 1.0:
        raise context.error(
            mapping.line_of("min_share"),
            "diagnosis.min_share",
            "must be below 1 (the share of the residual a relevant effect explains)",
            got=min_share,
            hint="0.05, the default, lists effects that remove at least 5 % of the residual",
        )
    names: dict[str, tuple[str, ...]] = {}
    for key in ("responses", "causes"):
        value = mapping.get(key)
        line = mapping.line_of(key)
        if value is None:
            names[key] = ()
            continue
        if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
            raise context.error(
                line,
                f"diagnosis.{key}",
                "must be a list of channel or candidate names",
                got=value,
                hint=f'write e.g. {key}: ["Battery Temperature [°C]"]',
            )
        names[key] = tuple(value)
    both = sorted(set(names["responses"]) & set(names["causes"]))
    if both:
        raise context.error(
            mapping.line_of("causes"),
            "diagnosis.causes",
            f"{both[0]!r} is declared both a response and a cause",
            hint="keep it in one of the two lists",
        )
    return DiagnosisSpec(
        min_share=min_share,
        responses=names["responses"],
        causes=names["causes"],
        groups=_diagnosis_groups(context, mapping, set(names["responses"])),
    )


def _diagnosis_groups(
    context: _Context, mapping: LineDict, responses: set[str]
) -> tuple[tuple[str, tuple[str, ...]], ...]:
    """``diagnosis.groups``: name → at least two candidate names, each in one group only."""
    value = mapping.get("groups")
    if value is None:
        return ()
    line = mapping.line_of("groups")
    table = context.mapping(value, line, "diagnosis.groups")
    hint = 'write e.g. groups: {heater: ["Heating Power CAN [kW]", "Heater Current [A]"]}'
    seen: dict[str, str] = {}
    groups: list[tuple[str, tuple[str, ...]]] = []
    for name, members in table.items():
        key = f"diagnosis.groups.{name}"
        at = table.line_of(name)
        if not (
            isinstance(members, list)
            and len(members) >= 2
            and all(isinstance(m, str) and m for m in members)
        ):
            problem = "must be a list of at least two channel or candidate names"
            if isinstance(members, list):
                problem += f" (got {len(members)} item{'s' if len(members) != 1 else ''})"
            raise context.error(
                at, key, problem, got=None if isinstance(members, list) else members, hint=hint
            )
        for member in members:
            if member in seen:
                raise context.error(
                    at,
                    key,
                    f"{member!r} is already in group {seen[member]!r}",
                    hint="a candidate measures one effect: keep it in one group",
                )
            if member in responses:
                raise context.error(
                    at,
                    key,
                    f"{member!r} is declared a response",
                    hint="a response is never offered as an effect; drop it from the group",
                )
            seen[member] = str(name)
        groups.append((str(name), tuple(members)))
    return tuple(groups)


def _item_name(context: _Context, name: str, line: int, key: str) -> str:
    """A name that becomes part of a test item's id: one printable line without '/' or '::'
    (a line break in it could print a forged line, such as a PASSED, into a CI log)."""
    if not name.strip() or "/" in name or "::" in name or not name.isprintable():
        raise context.error(
            line,
            key,
            "must be a non-empty name on one line, of printable characters, without '/' or '::'",
            got=name,
        )
    return name


def _requirements(
    context: _Context, mapping: LineDict, key: str, inherited: Mapping[str, int]
) -> dict[str, int]:
    """``requirements: [ID, ...]`` of a spec or a signal, merged after ``inherited`` (the
    spec's and the ancestors' IDs, each with the line that gave it): ID → its line.

    An ID given twice, here or already above, is an error.
    """
    merged = dict(inherited)
    if "requirements" not in mapping or mapping["requirements"] is None:
        return merged
    where = _join(key, "requirements")
    raw = mapping["requirements"]
    line = mapping.line_of("requirements")
    if isinstance(raw, str):
        raw = LineList([raw])
        raw.line, raw.item_lines = line, [line]
    if not isinstance(raw, LineList):
        raise context.error(
            line,
            where,
            "must be a list of requirement IDs",
            got=raw,
            hint="write e.g. requirements: [BATT-012, BATT-013]",
        )
    for index, item in enumerate(raw):
        item_line = raw.line_of(index)
        entry = _join(where, index)
        text = context.text(item, item_line, entry)
        problem = requirement_id_problem(text)
        if problem is not None:
            raise context.error(
                item_line,
                entry,
                problem,
                got=text,
                hint="give the ID as your requirements tool shows it, e.g. BATT-012",
            )
        if text in merged:
            first = merged[text]
            above = first not in (raw.line_of(i) for i in range(index))
            raise context.error(
                item_line,
                entry,
                f"duplicate requirement {text!r} (first given at line {first}"
                + (", and inherited here" if above else "")
                + ")",
                hint="a signal verifies the requirements of the spec and of the signals above "
                "it already; list each ID once",
            )
        merged[text] = item_line
    return merged


def _signal(
    context: _Context, value: Any, line: int, key: str, inherited: Mapping[str, int]
) -> SignalSpec:
    mapping = context.mapping(value, line, key)
    context.check_keys(mapping, _SIGNAL_KEYS, key)
    if "signal" not in mapping:
        raise context.error(mapping.line, _join(key, "signal"), "is required (the signal's name)")
    name = _item_name(
        context,
        context.text(mapping["signal"], mapping.line_of("signal"), _join(key, "signal")),
        mapping.line_of("signal"),
        _join(key, "signal"),
    )
    requirements = _requirements(context, mapping, key, inherited)
    ref = _expression(context, mapping.get("ref", name), mapping.line_of("ref"), _join(key, "ref"))
    sim = _expression(context, mapping.get("sim", name), mapping.line_of("sim"), _join(key, "sim"))
    children_value = mapping.get("children")
    children: tuple[SignalSpec, ...] = ()
    if children_value is not None:
        children_line = mapping.line_of("children")
        if not isinstance(children_value, LineList):
            raise context.error(
                children_line,
                _join(key, "children"),
                "must be a list of signals",
                got=children_value,
            )
        children = tuple(
            _signal(context, item, children_value.line_of(i), f"{key}.children[{i}]", requirements)
            for i, item in enumerate(children_value)
        )
    ref_unit = context.get(mapping, "ref_unit", key, context.unit_text, None)
    sim_unit = context.get(mapping, "sim_unit", key, context.unit_text, None)
    return SignalSpec(
        name=name,
        ref=ref,
        sim=sim,
        line=mapping.line,
        key=key,
        alpha=context.get(mapping, "alpha", key, context.weight, 1.0),
        # A side's unit given alone still converts: the signal is scored in the reference's
        # unit (or the model's, when only that is given).
        unit=context.get(mapping, "unit", key, context.unit_text, None) or ref_unit or sim_unit,
        description=context.get(mapping, "description", key, context.text, None),
        interpolation=cast(
            "Interpolation | None",
            context.get(
                mapping, "interpolation", key, context.choice(("linear", "previous")), None
            ),
        ),
        reference_range=context.get(mapping, "reference_range", key, context.positive, None),
        thresholds=_thresholds(context, mapping, "thresholds", _join(key, "thresholds")),
        ref_unit=ref_unit,
        sim_unit=sim_unit,
        ref_scale=context.get(mapping, "ref_scale", key, context.number, 1.0),
        ref_offset=context.get(mapping, "ref_offset", key, context.number, 0.0),
        sim_scale=context.get(mapping, "sim_scale", key, context.number, 1.0),
        sim_offset=context.get(mapping, "sim_offset", key, context.number, 0.0),
        children=children,
        local_thresholds=_thresholds(
            context, mapping, "local_thresholds", _join(key, "local_thresholds")
        ),
        region_thresholds=_thresholds(
            context, mapping, "region_thresholds", _join(key, "region_thresholds")
        ),
        uncertainty=_uncertainty(context, mapping, key),
        requirements=tuple(requirements),
    )


def _uncertainty(
    context: _Context, signal: LineDict, signal_key: str
) -> MeasurementUncertainty | None:
    """A signal's ``uncertainty: {abs, rel, sigma}``: its sensor's declared accuracy."""
    if "uncertainty" not in signal or signal["uncertainty"] is None:
        return None
    key = _join(signal_key, "uncertainty")
    line = signal.line_of("uncertainty")
    mapping = context.mapping(signal["uncertainty"], line, key)
    context.check_keys(mapping, _UNCERTAINTY_KEYS, key)
    if "abs" not in mapping and "rel" not in mapping:
        raise context.error(
            mapping.line if mapping else line,
            key,
            "needs abs (in the signal's unit), rel (a fraction of the reading) or both",
            hint="write e.g. uncertainty: {abs: 0.5, rel: 0.01, sigma: 2} for ±(0.5 + 1 %) at 2σ",
        )
    hints = {
        "abs": "give the sensor's absolute accuracy in the signal's unit, e.g. abs: 0.5",
        "rel": "give the accuracy as a fraction of the reading, e.g. rel: 0.01 for 1 %",
        "sigma": "give the coverage factor the figures are stated at, e.g. sigma: 2 for ±2σ",
    }

    def figure(name: str, convert: Callable[[Any, int, str], float], default: float) -> float:
        try:
            return context.get(mapping, name, key, convert, default)
        except SpecError as exc:
            raise exc.with_context(hint=hints[name]) from None

    rel = figure("rel", context.non_negative, 0.0)
    if rel >= 1.0:
        raise context.error(
            mapping.line_of("rel"),
            _join(key, "rel"),
            "must be a fraction of the reading below 1",
            got=rel,
            hint="write 1 % as rel: 0.01",
        )
    return MeasurementUncertainty(
        abs=figure("abs", context.non_negative, 0.0),
        rel=rel,
        sigma=figure("sigma", context.positive, UNCERTAINTY_SIGMA),
        line=line,
    )


def _measurement(context: _Context, top: LineDict) -> MeasurementSpec:
    """``measurement: {within_uncertainty: fail | pass}``."""
    if "measurement" not in top or top["measurement"] is None:
        return MeasurementSpec()
    line = top.line_of("measurement")
    mapping = context.mapping(top["measurement"], line, "measurement")
    context.check_keys(mapping, _MEASUREMENT_KEYS, "measurement")
    within = context.get(
        mapping,
        "within_uncertainty",
        "measurement",
        context.choice(_WITHIN_UNCERTAINTY),
        WITHIN_UNCERTAINTY,
    )
    return MeasurementSpec(within_uncertainty=within, line=line)  # type: ignore[arg-type]


def _check_local_scored(
    context: _Context, table: Mapping[str, float], node: SignalSpec | None, key: str
) -> None:
    """Windows and cells are scored on λ1–λ6 only: λ7 and whole-record metrics have no part."""
    from ..core.local import LOCAL_CHARACTERISTICS

    for name in table:
        if name not in LOCAL_CHARACTERISTICS:
            raise context.error(
                node.line if node else 1,
                _join(_join(node.key, key) if node else key, name),
                f"{name!r} is not scored over windows or region cells",
                hint="use one of " + ", ".join(LOCAL_CHARACTERISTICS),
            )


def _min_phi(context: _Context, top: LineDict) -> tuple[float | None, str]:
    """``min_phi: 0.9`` or ``min_phi: {value: 0.9, on: lower}``."""
    if "min_phi" not in top or top["min_phi"] is None:
        return None, "value"
    if not isinstance(top["min_phi"], dict):
        return context.get(top, "min_phi", "", context.unit_interval, None), "value"
    gate = context.mapping(top["min_phi"], top.line_of("min_phi"), "min_phi")
    context.check_keys(gate, _MIN_PHI_KEYS, "min_phi")
    if gate.get("value") is None:
        raise context.error(
            gate.line,
            "min_phi.value",
            "is required: the lowest acceptable Φ",
            hint="for example min_phi: {value: 0.9, on: lower}",
        )
    value = context.get(gate, "value", "min_phi", context.unit_interval, None)
    on = context.get(gate, "on", "min_phi", context.choice(_MIN_PHI_ON), "value")
    return value, on


def _local_gate(context: _Context, mapping: LineDict, key: str) -> LocalGate | None:
    if "gate" not in mapping or mapping["gate"] is None:
        return None
    where = _join(key, "gate")
    gate = context.mapping(mapping["gate"], mapping.line_of("gate"), where)
    context.check_keys(gate, _GATE_KEYS, where)
    thresholds = _thresholds(context, gate, "thresholds", _join(where, "thresholds"))
    if not thresholds:
        raise context.error(
            gate.line,
            _join(where, "thresholds"),
            "is required: the characteristics every window or cell must reach",
            hint="for example thresholds: {mae: 0.9}",
        )
    return LocalGate(
        thresholds=thresholds,
        share=context.get(gate, "share", where, context.unit_interval, 1.0),
        line=gate.line,
    )


def _local(context: _Context, top: LineDict) -> LocalSpec | None:
    if "local" not in top or top["local"] is None:
        return None
    key = "local"
    mapping = context.mapping(top[key], top.line_of(key), key)
    context.check_keys(mapping, _LOCAL_KEYS, key)
    conditions: list[ConditionSpec] = []
    if mapping.get("conditions") is not None:
        where = _join(key, "conditions")
        table = context.mapping(mapping["conditions"], mapping.line_of("conditions"), where)
        for name, value in table.items():
            line = table.line_of(name)
            entry = _join(where, str(name))
            if isinstance(value, LineDict):
                context.check_keys(value, _CONDITION_KEYS, entry)
                if "when" not in value:
                    raise context.error(line, _join(entry, "when"), "is required (an expression)")
                expression = _expression(
                    context, value["when"], value.line_of("when"), _join(entry, "when")
                )
                thresholds = _thresholds(context, value, "thresholds", _join(entry, "thresholds"))
            else:
                expression = _expression(context, value, line, entry)
                thresholds = {}
            conditions.append(ConditionSpec(str(name), expression, line, thresholds))
    return LocalSpec(
        window_s=context.get(mapping, "window_s", key, context.positive, LOCAL_WINDOW_S),
        line=top.line_of(key),
        phases=context.get(
            mapping, "phases", key, lambda v, ln, k: _expression(context, v, ln, k), None
        ),
        conditions=tuple(conditions),
        gate=_local_gate(context, mapping, key),
    )


def _region_bins(
    context: _Context, mapping: LineDict, key: str, variables: int
) -> tuple[tuple[float, ...] | int, ...]:
    if mapping.get("bins") is None:
        return (REGION_BINS,) * variables
    where = _join(key, "bins")
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
        entry = _join(where, i)
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
        edges = tuple(context.number(x, line, _join(entry, j)) for j, x in enumerate(item))
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


def _regions(context: _Context, top: LineDict) -> RegionSpec | None:
    if "regions" not in top or top["regions"] is None:
        return None
    key = "regions"
    mapping = context.mapping(top[key], top.line_of(key), key)
    context.check_keys(mapping, _REGION_KEYS, key)
    raw_by = mapping.get("by")
    line = mapping.line_of("by") if "by" in mapping else mapping.line
    if isinstance(raw_by, str):
        raw_by = [raw_by]
    if not isinstance(raw_by, list) or not 1 <= len(raw_by) <= 2:
        raise context.error(
            line,
            _join(key, "by"),
            "must name one or two operating variables (columns or expressions of the reference)",
            got=raw_by,
        )
    by = tuple(
        _expression(context, item, line, _join(_join(key, "by"), i))
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


def _check_unique_paths(context: _Context, roots: tuple[SignalSpec, ...]) -> None:
    """Item ids are signal paths, so two siblings (or two set roots) may not share a name."""
    seen: dict[str, SignalSpec] = {}

    def visit(node: SignalSpec, path: str) -> None:
        if path in seen:
            first = seen[path]
            raise context.error(
                node.line,
                node.key,
                f"duplicate signal path {path!r} (first defined at line {first.line})",
                hint="give it another name",
            )
        seen[path] = node
        for child in node.children:
            visit(child, f"{path}/{child.name}")

    for root in roots:
        visit(root, root.name)


def thresholds_mapping(values: Mapping[str, float]) -> dict[str, float]:
    """Canonicalise a name→value mapping that may use lambda1…lambda7 aliases."""
    out: dict[str, float] = {}
    for name, value in values.items():
        canonical = characteristic_name(name)
        if canonical is not None:
            out[canonical] = float(value)
    return out


def _is_pattern(reference: Any, base: Path) -> bool:
    """A reference path with glob wildcards names a campaign's recordings, unless it names an
    existing file: ``trip[1].csv`` is that file, not ``trip1.csv``."""
    raw = _raw_path(reference)
    return (
        isinstance(raw, str)
        and not is_url(raw)
        and glob.has_magic(raw)
        and not os.path.exists(base / raw)
    )


def _raw_path(reference: Any) -> Any:
    return reference.get("path") if isinstance(reference, LineDict) else reference


def _matches(raw: str, base: Path) -> list[str]:
    """The files a pattern matches, relative to ``base``, whose own name is never a pattern
    (a spec in a folder named ``camp[abc]``)."""
    return sorted(glob.glob(os.path.join(glob.escape(str(base)), raw)))


def _campaign(
    context: _Context, top: LineDict, reference: SourceSpec, model: SourceSpec, base: Path
) -> CampaignSpec | None:
    """The recordings of a campaign: the files a reference pattern matches, or a table."""
    pattern = _is_pattern(top["reference"], base)
    if not pattern and "recordings" not in top:
        if model.kind == "file" and model.path is not None and ID_FIELD in model.path:
            raise context.error(
                model.line,
                "model.path",
                f"has {ID_FIELD}, which each recording of a campaign fills in, but the spec "
                "names a single recording",
                hint="give reference.path a pattern (data/Trip*.parquet) or list `recordings:`; "
                f"or name the model's one file without {ID_FIELD}",
            )
        if "campaign" in top:
            raise context.error(
                top.line_of("campaign"),
                "campaign",
                "gates a campaign, but the spec names a single recording",
                hint="give reference.path a pattern (data/Trip*.parquet) or list `recordings:`",
            )
        return None
    reference_value = top["reference"]
    reference_line = (
        reference_value.line_of("path")
        if isinstance(reference_value, LineDict)
        else top.line_of("reference")
    )
    matched: dict[str, str] = {}
    if pattern:
        assert reference.path is not None
        for found in _matches(str(_raw_path(top["reference"])), base):
            matched.setdefault(_recording_id(found), found)
        if not matched:
            raise context.error(
                reference_line,
                "reference.path",
                "the pattern matches no file",
                got=_relative_pattern(reference.path, base),
                hint="check the folder and the wildcards; the pattern is relative to the spec file",
            )
    elif reference.path is not None:
        raise context.error(
            reference_line,
            "reference.path",
            "names one file, but the spec lists its recordings",
            hint="give the path of each recording in `recordings:`, or make reference.path a "
            "pattern such as data/Trip*.parquet",
        )
    entries = _recording_entries(context, top, base, matched)
    recordings = [
        RecordingSpec(
            id=recording_id,
            path=entries[recording_id].path if recording_id in entries else file,
            role=entries[recording_id].role if recording_id in entries else "validation",
            params=entries[recording_id].params if recording_id in entries else {},
            line=entries[recording_id].line if recording_id in entries else reference_line,
            model_path=entries[recording_id].model if recording_id in entries else None,
        )
        for recording_id, file in {**matched, **{k: v.path for k, v in entries.items()}}.items()
    ]
    recordings, unused = _model_outputs(context, model, recordings, top)
    min_pass_rate: float | None = None
    phi_quantile: tuple[float, float] | None = None
    if top.get("campaign") is not None:
        gate = context.mapping(top["campaign"], top.line_of("campaign"), "campaign")
        context.check_keys(gate, _CAMPAIGN_KEYS, "campaign")
        min_pass_rate = context.get(gate, "min_pass_rate", "campaign", context.unit_interval, None)
        if "phi_quantile" in gate:
            phi_quantile = _phi_quantile(context, gate)
    return CampaignSpec(
        unused_models=unused,
        recordings=tuple(recordings),
        line=top.line_of("campaign") if "campaign" in top else reference_line,
        min_pass_rate=min_pass_rate,
        phi_quantile=phi_quantile,
    )


def _recording_id(path: str) -> str:
    """``TripB03`` for ``…/TripB03.parquet``: the file name without its suffixes."""
    return Path(path).name.split(".", 1)[0]


def _relative_pattern(path: str, base: Path) -> str:
    try:
        return str(Path(path).relative_to(base.resolve()))
    except ValueError:
        return path


class _Row(NamedTuple):
    """One row of `recordings:`."""

    path: str
    role: Role
    params: dict[str, Any]
    line: int
    #: The row's own model output file (absolute, or a URL), if it names one.
    model: str | None


def _rows_name_models(top: LineDict) -> bool:
    """Whether every row of a `recordings:` table names its own model output file."""
    rows = top.get("recordings")
    return (
        isinstance(rows, LineList)
        and bool(rows)
        and all(isinstance(row, LineDict) and "model" in row for row in rows)
    )


def _model_outputs(
    context: _Context, model: SourceSpec, recordings: list[RecordingSpec], top: LineDict
) -> tuple[list[RecordingSpec], tuple[str, ...]]:
    """Each recording's model output file, when the model is files rather than a callable or
    an FMU, and the files that follow ``model.path``'s pattern but no recording's id."""
    given = [r for r in recordings if r.model_path is not None]
    if model.kind != "file":
        if given:
            raise context.error(
                given[0].line,
                "recordings.model",
                f"names a model output file, but the spec's model is a {model.kind}",
                hint="remove the row's `model:`, or make `model:` name files "
                "(model: {path: sim/{id}.parquet}) instead of a callable or an FMU",
            )
        return recordings, ()
    template = model.path if model.path is not None and ID_FIELD in model.path else None
    if template is None and len(given) < len(recordings):
        lacking = next(r for r in recordings if r.model_path is None)
        raise context.error(
            model.line,
            "model.path",
            "names one file, but a campaign needs the model's output for each recording "
            f"(recording {lacking.id!r} has none)",
            hint=f"put {ID_FIELD} in the path (sim/{ID_FIELD}.parquet) for one file per "
            "recording, give each row of `recordings:` its `model:`, or name a callable or "
            "an FMU that runs on each recording",
        )
    out = [
        r
        if r.model_path is not None
        else dataclasses.replace(r, model_path=model_output_path(str(template), r.id))
        for r in recordings
    ]
    unused: tuple[str, ...] = ()
    if template is not None and not is_url(template):
        head, _, tail = template.partition(ID_FIELD)
        ids = {r.id for r in recordings}
        unused = tuple(
            found
            for found in sorted(glob.glob(glob.escape(head) + "*" + glob.escape(tail)))
            if found[len(head) : len(found) - len(tail)] not in ids
        )
    return out, unused


def _recording_entries(
    context: _Context, top: LineDict, base: Path, matched: Mapping[str, str]
) -> dict[str, _Row]:
    """id → its row, for every row of `recordings:`."""
    if "recordings" not in top or top["recordings"] is None:
        return {}
    rows = top["recordings"]
    if not isinstance(rows, LineList) or not rows:
        raise context.error(
            top.line_of("recordings"),
            "recordings",
            "must be a non-empty list of recordings ({id, path, role, params})",
            got=rows,
        )
    entries: dict[str, _Row] = {}
    for index, row in enumerate(rows):
        key = f"recordings[{index}]"
        line = rows.line_of(index)
        mapping = context.mapping(row, line, key)
        context.check_keys(mapping, _RECORDING_KEYS, key)
        if matched and "path" in mapping:
            raise context.error(
                mapping.line_of("path"),
                _join(key, "path"),
                "the recordings come from reference.path's pattern, so a row names one by id",
                hint="remove `path:`, or list every recording with its path and no pattern",
            )
        if matched:
            if "id" not in mapping:
                raise context.error(mapping.line, _join(key, "id"), "is required (a recording id)")
            path = ""
        else:
            if "path" not in mapping:
                raise context.error(
                    mapping.line, _join(key, "path"), "is required (the recording's data file)"
                )
            raw = context.text(mapping["path"], mapping.line_of("path"), _join(key, "path"))
            path = (
                raw
                if is_url(raw)
                else _resolve(context, base, raw, mapping.line_of("path"), _join(key, "path"))
            )
        recording_id = context.get(mapping, "id", key, context.text, _recording_id(path))
        id_line = mapping.line_of("id") if "id" in mapping else mapping.line
        _item_name(context, recording_id, id_line, _join(key, "id"))
        if recording_id in entries:
            raise context.error(
                id_line,
                _join(key, "id"),
                f"duplicate recording id {recording_id!r} "
                f"(first listed at line {entries[recording_id].line})",
                hint="give each recording its own id",
            )
        if matched:
            if recording_id not in matched:
                raise context.error(
                    id_line,
                    _join(key, "id"),
                    "no file matched by reference.path has this id",
                    got=recording_id,
                    hint=did_you_mean(recording_id, tuple(matched))
                    or "matched: " + ", ".join(matched),
                )
            path = matched[recording_id]
        role = cast("Role", context.get(mapping, "role", key, context.choice(ROLES), "validation"))
        no_params: dict[str, Any] = {}
        params = context.get(mapping, "params", key, _plain_mapping(context), no_params)
        model: str | None = None
        if "model" in mapping:
            where = _join(key, "model")
            raw_model = context.text(mapping["model"], mapping.line_of("model"), where)
            model = (
                raw_model
                if is_url(raw_model)
                else _resolve(context, base, raw_model, mapping.line_of("model"), where)
            )
        entries[recording_id] = _Row(path, role, params, mapping.line, model)
    return entries


def _phi_quantile(context: _Context, gate: LineDict) -> tuple[float, float]:
    key = "campaign.phi_quantile"
    table = context.mapping(gate["phi_quantile"], gate.line_of("phi_quantile"), key)
    context.check_keys(table, ("q", "min"), key)
    for required in ("q", "min"):
        if required not in table:
            raise context.error(
                table.line,
                _join(key, required),
                "is required",
                hint="write phi_quantile: {q: 0.1, min: 0.85} (10 % of recordings may score "
                "below 0.85)",
            )
    return (
        context.unit_interval(table["q"], table.line_of("q"), _join(key, "q")),
        context.unit_interval(table["min"], table.line_of("min"), _join(key, "min")),
    )
