"""A campaign's recordings: the files a ``reference.path`` pattern matches or the rows of
``recordings``, each recording's model output file, and the ``campaign`` gate.

Globbing happens only where a spec asks for it: a reference path naming an existing file is
that file even with ``[``, ``*`` or ``?`` in its name, and a pattern is matched inside the
spec's folder, whose own name is never a pattern.
"""

from __future__ import annotations

import dataclasses
import glob
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any, NamedTuple, cast

from ..data.remote import is_url
from ..errors import did_you_mean
from .model import ID_FIELD, ROLES, CampaignSpec, RecordingSpec, Role, SourceSpec, model_output_path
from .validate import Context, item_name, join, plain_mapping, resolve
from .yaml_lines import LineDict, LineList

__all__ = ["campaign_of", "is_pattern", "rows_name_models"]

_RECORDING_KEYS = ("id", "path", "model", "role", "params")
_CAMPAIGN_KEYS = ("min_pass_rate", "phi_quantile")


def is_pattern(reference: Any, base: Path) -> bool:
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


def campaign_of(
    context: Context, top: LineDict, reference: SourceSpec, model: SourceSpec, base: Path
) -> CampaignSpec | None:
    """The recordings of a campaign: the files a reference pattern matches, or a table."""
    pattern = is_pattern(top["reference"], base)
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


def rows_name_models(top: LineDict) -> bool:
    """Whether every row of a `recordings:` table names its own model output file."""
    rows = top.get("recordings")
    return (
        isinstance(rows, LineList)
        and bool(rows)
        and all(isinstance(row, LineDict) and "model" in row for row in rows)
    )


def _model_outputs(
    context: Context, model: SourceSpec, recordings: list[RecordingSpec], top: LineDict
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
    context: Context, top: LineDict, base: Path, matched: Mapping[str, str]
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
                join(key, "path"),
                "the recordings come from reference.path's pattern, so a row names one by id",
                hint="remove `path:`, or list every recording with its path and no pattern",
            )
        if matched:
            if "id" not in mapping:
                raise context.error(mapping.line, join(key, "id"), "is required (a recording id)")
            path = ""
        else:
            if "path" not in mapping:
                raise context.error(
                    mapping.line, join(key, "path"), "is required (the recording's data file)"
                )
            raw = context.text(mapping["path"], mapping.line_of("path"), join(key, "path"))
            path = (
                raw
                if is_url(raw)
                else resolve(context, base, raw, mapping.line_of("path"), join(key, "path"))
            )
        recording_id = context.get(mapping, "id", key, context.text, _recording_id(path))
        id_line = mapping.line_of("id") if "id" in mapping else mapping.line
        item_name(context, recording_id, id_line, join(key, "id"))
        if recording_id in entries:
            raise context.error(
                id_line,
                join(key, "id"),
                f"duplicate recording id {recording_id!r} "
                f"(first listed at line {entries[recording_id].line})",
                hint="give each recording its own id",
            )
        if matched:
            if recording_id not in matched:
                raise context.error(
                    id_line,
                    join(key, "id"),
                    "no file matched by reference.path has this id",
                    got=recording_id,
                    hint=did_you_mean(recording_id, tuple(matched))
                    or "matched: " + ", ".join(matched),
                )
            path = matched[recording_id]
        role = cast("Role", context.get(mapping, "role", key, context.choice(ROLES), "validation"))
        no_params: dict[str, Any] = {}
        params = context.get(mapping, "params", key, plain_mapping(context), no_params)
        model: str | None = None
        if "model" in mapping:
            where = join(key, "model")
            raw_model = context.text(mapping["model"], mapping.line_of("model"), where)
            model = (
                raw_model
                if is_url(raw_model)
                else resolve(context, base, raw_model, mapping.line_of("model"), where)
            )
        entries[recording_id] = _Row(path, role, params, mapping.line, model)
    return entries


def _phi_quantile(context: Context, gate: LineDict) -> tuple[float, float]:
    key = "campaign.phi_quantile"
    table = context.mapping(gate["phi_quantile"], gate.line_of("phi_quantile"), key)
    context.check_keys(table, ("q", "min"), key)
    for required in ("q", "min"):
        if required not in table:
            raise context.error(
                table.line,
                join(key, required),
                "is required",
                hint="write phi_quantile: {q: 0.1, min: 0.85} (10 % of recordings may score "
                "below 0.85)",
            )
    return (
        context.unit_interval(table["q"], table.line_of("q"), join(key, "q")),
        context.unit_interval(table["min"], table.line_of("min"), join(key, "min")),
    )
