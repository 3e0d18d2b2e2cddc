"""Validation spec files → :class:`~pytest_hevval.spec.model.Spec`.

Reads a spec file, parses its YAML with line numbers and assembles the spec from its sections,
each checked in a room of its own: :mod:`.sources` (reference, model, alignment, data quality,
runtime), :mod:`.thresholds` (metrics, thresholds, weights, min_phi), :mod:`.signals` (the
signal tree, requirements, measurement), :mod:`.localisation` (local, regions), :mod:`.causes`
(candidates, diagnosis) and :mod:`.recordings` (a campaign's recordings). Every problem becomes
a :class:`~pytest_hevval.errors.SpecError` of the form
``file:line: key.path: problem (got …); did you mean …?``, worded by :mod:`.validate`.
"""

from __future__ import annotations

import dataclasses
import hashlib
from pathlib import Path

import yaml

from ..core.registry import select_characteristics
from ..errors import SpecError, did_you_mean
from ..files import read_input, unreadable
from .causes import candidates_of, diagnosis_of
from .localisation import check_local_scored, local_of, regions_of
from .model import Spec, split_key
from .recordings import campaign_of, is_pattern, rows_name_models
from .sidecar import load_sidecar
from .signals import (
    all_nodes,
    check_phi_defined,
    check_unique_paths,
    measurement_of,
    requirements_of,
    signal_of,
)
from .sources import (
    alignment_of,
    check_callable_inputs,
    data_quality_of,
    runtime_of,
    source_of,
    with_events,
)
from .thresholds import check_scored, metrics_of, min_phi_of, thresholds_of, weights_of
from .validate import Context, join
from .yaml_lines import LineList, load_yaml_with_lines

__all__ = ["load_spec", "load_specs", "parse_spec_text"]

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
    context = Context(file)
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
    table = "recordings" in top and not is_pattern(top["reference"], base)
    reference = source_of(
        context, top["reference"], top.line_of("reference"), "reference", base, path_optional=table
    )
    model = source_of(
        context,
        top["model"],
        top.line_of("model"),
        "model",
        base,
        path_optional=rows_name_models(top),
    )
    if model.kind == "fmu":
        # An FMU reads inputs in the FMI event convention: two rows at one time stamp.
        reference = with_events(reference)
    campaign = campaign_of(context, top, reference, model, base)
    alignment = alignment_of(context, top)
    metrics = metrics_of(context, top)
    scored = {c.name for c in select_characteristics(metrics)}
    thresholds = thresholds_of(context, top, "thresholds", "thresholds")
    check_scored(context, thresholds, scored, top.line_of("thresholds"), "thresholds")
    weights = weights_of(context, top, scored)
    min_phi, min_phi_on = min_phi_of(context, top)
    correlation = context.get(top, "correlation", "", context.choice(("xcorr", "pearson")), "xcorr")
    emergent = context.get(top, "emergent", "", context.choice(("V2", "V1")), "V2")
    candidates = candidates_of(context, top)
    diagnosis = diagnosis_of(context, top)
    data_quality = data_quality_of(context, top)
    sets_value = top["sets"]
    sets_line = top.line_of("sets")
    if not isinstance(sets_value, LineList) or not sets_value:
        raise context.error(
            sets_line, "sets", "must be a non-empty list of signals", got=sets_value
        )
    requirements = requirements_of(context, top, "", {})
    roots = tuple(
        signal_of(context, item, sets_value.line_of(i), f"sets[{i}]", requirements)
        for i, item in enumerate(sets_value)
    )
    check_unique_paths(context, roots)
    local = local_of(context, top)
    regions = regions_of(context, top)
    for _, node in all_nodes(roots):
        check_scored(context, node.thresholds, scored, node.line, join(node.key, "thresholds"))
        check_local_scored(context, node.local_thresholds, node, "local_thresholds")
        check_local_scored(context, node.region_thresholds, node, "region_thresholds")
    if local and local.gate:
        check_local_scored(context, local.gate.thresholds, None, "local.gate.thresholds")
    for condition in local.conditions if local else ():
        check_local_scored(
            context, condition.thresholds, None, f"local.conditions.{condition.name}.thresholds"
        )
    if regions and regions.gate:
        check_local_scored(context, regions.gate.thresholds, None, "regions.gate.thresholds")
    check_phi_defined(context, roots, sets_line)
    if model.kind == "callable":
        check_callable_inputs(
            context, model, {c for _, node in all_nodes(roots) for c in node.ref.columns}
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
        measurement=measurement_of(context, top),
        requirements=tuple(requirements),
        runtime=runtime_of(context, top, model),
    )


def _default_name(path: Path) -> str:
    name = path.name
    for suffix in (".hevval.yaml", ".hevval.yml", ".yaml", ".yml"):
        if name.endswith(suffix):
            return name[: -len(suffix)]
    return name
