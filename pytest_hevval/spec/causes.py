"""What the diagnosis may offer as causes of a residual: ``candidates`` (named expressions of
the reference's channels) and ``diagnosis`` (responses, causes, groups and the share of the
residual an effect must explain).
"""

from __future__ import annotations

from .expressions import Expression
from .model import DiagnosisSpec
from .validate import Context, join, parse_expression
from .yaml_lines import LineDict

__all__ = ["candidates_of", "diagnosis_of"]

_DIAGNOSIS_KEYS = ("min_share", "responses", "causes", "groups")


def candidates_of(context: Context, top: LineDict) -> dict[str, Expression]:
    """``candidates``: name → an expression the diagnosis may offer as a cause."""
    if "candidates" not in top or top["candidates"] is None:
        return {}
    table = context.mapping(top["candidates"], top.line_of("candidates"), "candidates")
    return {
        str(name): parse_expression(context, value, table.line_of(name), join("candidates", name))
        for name, value in table.items()
    }


def diagnosis_of(context: Context, top: LineDict) -> DiagnosisSpec:
    """``diagnosis: {min_share, responses, causes, groups}``."""
    mapping = context.section(top, "diagnosis", _DIAGNOSIS_KEYS)
    if mapping is None:
        return DiagnosisSpec()
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
    context: Context, mapping: LineDict, responses: set[str]
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
