"""What a spec scores and the bar it sets: ``metrics``, ``thresholds``, ``weights`` and
``min_phi``.

The characteristics are named as the registry names them or by their aliases ``lambda1`` …
``lambda7``; a threshold or weight is only accepted for a characteristic the spec scores. The
signal tree (:mod:`.signals`) and the local and region gates (:mod:`.localisation`) read their
threshold tables with :func:`thresholds_of` too.
"""

from __future__ import annotations

from collections.abc import Mapping

from ..core.registry import LAMBDA_ALIASES, is_registered, registered_characteristics
from ..errors import did_you_mean
from .validate import Context, join
from .yaml_lines import LineDict, LineList

__all__ = [
    "THRESHOLD_ALIASES",
    "characteristic_name",
    "check_scored",
    "metrics_of",
    "min_phi_of",
    "thresholds_of",
    "weights_of",
]

#: ``lambda1`` … ``lambda7`` name the seven characteristics in paper order.
THRESHOLD_ALIASES: dict[str, str] = LAMBDA_ALIASES
_MIN_PHI_KEYS = ("value", "on")
#: What ``min_phi: {on: …}`` may judge: Φ itself or a bound of its confidence interval.
_MIN_PHI_ON = ("value", "lower", "upper")


def characteristic_name(name: str) -> str | None:
    """Canonical characteristic name for a name or alias, or None."""
    if is_registered(name):
        return name
    return THRESHOLD_ALIASES.get(name)


def _registered_names() -> tuple[str, ...]:
    return tuple(c.name for c in registered_characteristics())


def _canonical(context: Context, raw_name: str, line: int, key: str, *, listing: bool) -> str:
    """The registry's name for the characteristic a table names; an unknown one is an error
    suggesting a near name, or (``listing``) listing the registered ones."""
    canonical = characteristic_name(raw_name)
    if canonical is None:
        raise context.error(
            line,
            key,
            "unknown characteristic",
            hint=did_you_mean(raw_name, (*_registered_names(), *THRESHOLD_ALIASES))
            or (
                "use one of " + ", ".join(_registered_names()) + " (or lambda1…lambda7)"
                if listing
                else None
            ),
        )
    return canonical


def thresholds_of(context: Context, mapping: LineDict, name: str, key: str) -> dict[str, float]:
    """The threshold table ``mapping[name]``: characteristic → a value between 0 and 1."""
    if name not in mapping or mapping[name] is None:
        return {}
    table = context.mapping(mapping[name], mapping.line_of(name), key)
    out: dict[str, float] = {}
    for raw_name, value in table.items():
        line = table.line_of(raw_name)
        canonical = _canonical(context, raw_name, line, join(key, raw_name), listing=True)
        if canonical in out:
            raise context.error(line, join(key, raw_name), f"repeats {canonical}")
        out[canonical] = context.unit_interval(value, line, join(key, raw_name))
    return out


def metrics_of(context: Context, top: LineDict) -> tuple[str, ...]:
    """``metrics: [name, …]``: the characteristics the spec scores, canonical and once each."""
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


def check_scored(
    context: Context,
    table: Mapping[str, float],
    scored: set[str],
    line: int,
    key: str,
) -> None:
    """Every characteristic of ``table`` is one the spec scores."""
    for name in table:
        if name not in scored:
            raise context.error(
                line,
                join(key, name),
                f"characteristic {name!r} is not scored by this spec",
                hint=f"add it to the spec's metrics: [{name}]",
            )


def weights_of(context: Context, top: LineDict, scored: set[str]) -> dict[str, float]:
    """``weights``: characteristic → β, not all zero among those the spec scores."""
    if "weights" not in top or top["weights"] is None:
        return {}
    table = context.mapping(top["weights"], top.line_of("weights"), "weights")
    values: dict[str, float] = {}
    for raw_name, value in table.items():
        line = table.line_of(raw_name)
        canonical = _canonical(context, raw_name, line, join("weights", raw_name), listing=False)
        values[canonical] = context.weight(value, line, join("weights", raw_name))
    check_scored(context, values, scored, top.line_of("weights"), "weights")
    effective = [
        values.get(c.name, c.default_weight)
        for c in registered_characteristics()
        if c.name in scored
    ]
    if not any(effective):
        raise context.error(top.line_of("weights"), "weights", "cannot all be 0")
    return values


def min_phi_of(context: Context, top: LineDict) -> tuple[float | None, str]:
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
