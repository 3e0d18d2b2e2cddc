"""The signal tree (``sets``): each signal with its expressions, units, weight, thresholds,
sensor uncertainty and requirements, and its children.

Requirement IDs are inherited down the tree, so a signal verifies its own and those of the spec
and of the signals above it; ``measurement`` says how a result within the declared
uncertainty counts. Signal paths become test item ids, so they must be unique, and Φ needs at
least one signal with a weight above zero.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any, cast

from ..core.measurement import MeasurementUncertainty
from ..defaults import UNCERTAINTY_SIGMA, WITHIN_UNCERTAINTY, requirement_id_problem
from ..errors import SpecError
from .model import Interpolation, MeasurementSpec, SignalSpec
from .thresholds import thresholds_of
from .validate import Context, item_name, join, parse_expression
from .yaml_lines import LineDict, LineList

__all__ = [
    "all_nodes",
    "check_phi_defined",
    "check_unique_paths",
    "measurement_of",
    "requirements_of",
    "signal_of",
]

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
_UNCERTAINTY_KEYS = ("abs", "rel", "sigma")
_MEASUREMENT_KEYS = ("within_uncertainty",)
#: The settings of ``measurement.within_uncertainty``, the default first.
_WITHIN_UNCERTAINTY = (WITHIN_UNCERTAINTY, *sorted({"fail", "pass"} - {WITHIN_UNCERTAINTY}))


def check_phi_defined(context: Context, roots: Sequence[SignalSpec], line: int) -> None:
    """Φ (eq. 14) divides by Σ α·β; with every α zero it can never be scored (β: weights_of)."""
    if not any(node.alpha > 0 for _, node in all_nodes(roots)):
        raise context.error(
            line,
            "sets",
            "every signal's alpha is zero, so Φ is undefined",
            hint="give at least one signal an alpha above 0",
        )


def all_nodes(roots: Sequence[SignalSpec]) -> Iterator[tuple[int, SignalSpec]]:
    """Every signal of the tree with its depth (1 for a root of ``sets``)."""
    stack = [(1, root) for root in roots]
    while stack:
        level, node = stack.pop()
        yield level, node
        stack.extend((level + 1, child) for child in node.children)


def requirements_of(
    context: Context, mapping: LineDict, key: str, inherited: Mapping[str, int]
) -> dict[str, int]:
    """``requirements: [ID, ...]`` of a spec or a signal, merged after ``inherited`` (the
    spec's and the ancestors' IDs, each with the line that gave it): ID → its line.

    An ID given twice, here or already above, is an error.
    """
    merged = dict(inherited)
    if "requirements" not in mapping or mapping["requirements"] is None:
        return merged
    where = join(key, "requirements")
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
        entry = join(where, index)
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


def signal_of(
    context: Context, value: Any, line: int, key: str, inherited: Mapping[str, int]
) -> SignalSpec:
    """One signal of ``sets`` (or of a ``children`` list) and its subtree."""
    mapping = context.mapping(value, line, key)
    context.check_keys(mapping, _SIGNAL_KEYS, key)
    if "signal" not in mapping:
        raise context.error(mapping.line, join(key, "signal"), "is required (the signal's name)")
    name = item_name(
        context,
        context.text(mapping["signal"], mapping.line_of("signal"), join(key, "signal")),
        mapping.line_of("signal"),
        join(key, "signal"),
    )
    requirements = requirements_of(context, mapping, key, inherited)
    ref = parse_expression(
        context, mapping.get("ref", name), mapping.line_of("ref"), join(key, "ref")
    )
    sim = parse_expression(
        context, mapping.get("sim", name), mapping.line_of("sim"), join(key, "sim")
    )
    children_value = mapping.get("children")
    children: tuple[SignalSpec, ...] = ()
    if children_value is not None:
        children_line = mapping.line_of("children")
        if not isinstance(children_value, LineList):
            raise context.error(
                children_line,
                join(key, "children"),
                "must be a list of signals",
                got=children_value,
            )
        children = tuple(
            signal_of(
                context, item, children_value.line_of(i), f"{key}.children[{i}]", requirements
            )
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
        thresholds=thresholds_of(context, mapping, "thresholds", join(key, "thresholds")),
        ref_unit=ref_unit,
        sim_unit=sim_unit,
        ref_scale=context.get(mapping, "ref_scale", key, context.number, 1.0),
        ref_offset=context.get(mapping, "ref_offset", key, context.number, 0.0),
        sim_scale=context.get(mapping, "sim_scale", key, context.number, 1.0),
        sim_offset=context.get(mapping, "sim_offset", key, context.number, 0.0),
        children=children,
        local_thresholds=thresholds_of(
            context, mapping, "local_thresholds", join(key, "local_thresholds")
        ),
        region_thresholds=thresholds_of(
            context, mapping, "region_thresholds", join(key, "region_thresholds")
        ),
        uncertainty=_uncertainty(context, mapping, key),
        requirements=tuple(requirements),
    )


def _uncertainty(
    context: Context, signal: LineDict, signal_key: str
) -> MeasurementUncertainty | None:
    """A signal's ``uncertainty: {abs, rel, sigma}``: its sensor's declared accuracy."""
    if "uncertainty" not in signal or signal["uncertainty"] is None:
        return None
    key = join(signal_key, "uncertainty")
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
            join(key, "rel"),
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


def measurement_of(context: Context, top: LineDict) -> MeasurementSpec:
    """``measurement: {within_uncertainty: fail | pass}``."""
    mapping = context.section(top, "measurement", _MEASUREMENT_KEYS)
    if mapping is None:
        return MeasurementSpec()
    line = top.line_of("measurement")
    within = context.get(
        mapping,
        "within_uncertainty",
        "measurement",
        context.choice(_WITHIN_UNCERTAINTY),
        WITHIN_UNCERTAINTY,
    )
    return MeasurementSpec(within_uncertainty=within, line=line)  # type: ignore[arg-type]


def check_unique_paths(context: Context, roots: tuple[SignalSpec, ...]) -> None:
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
