"""One view-model for every report format.

HTML, JSON and Markdown all read the per-spec result dicts through these functions, so the order
of signals, what counts as "worst", and the pass/fail colour of every λ agree across formats.
Pure Python on plain dicts: no numpy, no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal, cast

from ..core.characteristics import CHARACTERISTICS
from ..core.registry import describe, order_names, registered_characteristics
from ..results.codec import is_finite_number, keyed_lambdas
from ..results.measurement import ErrorCheck
from ..results.spec_result import SpecResult
from ..results.verdict import RunVerdict
from .sentences import failure_sentence, verdict_line

__all__ = [
    "CHARACTERISTICS",
    "CHARACTERISTIC_COLOURS",
    "LABELS",
    "SHORT_LABELS",
    "Cell",
    "GlyphPoint",
    "StandardMetricRow",
    "WorstRow",
    "cells",
    "characteristic_names",
    "failing_signals",
    "glyph_points",
    "is_finite_number",
    "items",
    "margin",
    "measurement_lines",
    "ordered_signals",
    "signal_order",
    "standard_metric_rows",
    "summary",
    "tree_rows",
    "worst_rows",
]


class _Described(Mapping[str, str]):
    """One field of every characteristic's registry entry, by name (plain names for unknowns)."""

    def __init__(self, attribute: str) -> None:
        self._attribute = attribute

    def __getitem__(self, name: str) -> str:
        return str(getattr(describe(name), self._attribute))

    def __iter__(self) -> Iterator[str]:
        return iter([c.name for c in registered_characteristics()])

    def __len__(self) -> int:
        return len(registered_characteristics())


#: Long label of each characteristic ("lag correlation", "MAE", …).
LABELS: Mapping[str, str] = _Described("label")
#: Symbol of each characteristic ("λ1" … "λ7"; a registered one's name).
SHORT_LABELS: Mapping[str, str] = _Described("symbol")
#: Fill colour of each characteristic (Okabe–Ito for λ1…λ7, safe for colour-blind readers).
CHARACTERISTIC_COLOURS: Mapping[str, str] = _Described("colour")


def characteristic_names(specs: Iterable[Mapping[str, Any]]) -> list[str]:
    """Every characteristic any signal of ``specs`` carries, in report order."""
    names: list[str] = []
    for spec in specs:
        for signal in items(spec.get("signals")):
            if isinstance(signal, Mapping):
                names.extend(_lambdas(signal))
    return order_names(names) if names else list(CHARACTERISTICS)


#: "within": missed within the measurement uncertainty, and passing by the spec's choice.
Status = Literal["pass", "fail", "ungated", "within"]


def items(value: object) -> list[Any]:
    """``value`` as a list: ``None`` and scalars give ``[]``; numpy arrays work too."""
    if value is None or isinstance(value, (str, bytes, Mapping)):
        return []
    try:
        return list(cast("Iterable[Any]", value))
    except TypeError:
        return []


def _lambdas(signal: Mapping[str, Any]) -> dict[str, float | None]:
    """λ values by name, in report order (a list in paper order is read too)."""
    try:
        raw = keyed_lambdas(signal.get("lambdas"))
    except ValueError:
        return {}
    return {name: raw[name] for name in order_names(raw)}


def _thresholds(signal: Mapping[str, Any]) -> dict[str, float]:
    raw = signal.get("thresholds")
    if not isinstance(raw, Mapping):
        return {}
    return {str(k): float(v) for k, v in raw.items() if is_finite_number(v)}


def _failed_names(signal: Mapping[str, Any]) -> set[str]:
    return {
        str(f.get("characteristic"))
        for f in items(signal.get("failures"))
        if isinstance(f, Mapping)
    }


@dataclass(frozen=True)
class Cell:
    """One λ of one signal, with its gate."""

    characteristic: str
    index: int
    value: float | None
    threshold: float | None
    status: Status
    #: The value's 95 % interval, where the result carries one.
    low: float | None = None
    high: float | None = None

    @property
    def label(self) -> str:
        return SHORT_LABELS[self.characteristic]


def cells(signal: Mapping[str, Any]) -> list[Cell]:
    """λ1…λ7 of ``signal`` coloured against their thresholds.

    A characteristic listed in ``failures`` is failing even if its value would pass (the engine
    is the judge, e.g. for tolerances); otherwise a value below its threshold fails.
    """
    values = _lambdas(signal)
    gates = _thresholds(signal)
    failed = _failed_names(signal)
    raw = signal.get("intervals")
    intervals: Mapping[str, Any] = raw if isinstance(raw, Mapping) else {}
    excused = _failed_names({"failures": signal.get("within_uncertainty")})
    out: list[Cell] = []
    for i, (name, value) in enumerate(values.items(), 1):
        threshold = gates.get(name)
        status: Status
        if name in failed:
            status = "fail"
        elif name in excused:
            status = "within"
        elif threshold is None:
            status = "ungated"
        elif value is None or value < threshold:
            status = "fail"
        else:
            status = "pass"
        low, high = interval_bounds(intervals.get(name))
        out.append(Cell(name, i, value, threshold, status, low, high))
    return out


def interval_bounds(raw: Any) -> tuple[float | None, float | None]:
    """(low, high) of a result's ``{"low", "high"}`` interval; (None, None) where absent."""
    if not isinstance(raw, Mapping):
        return None, None
    low, high = raw.get("low"), raw.get("high")
    if is_finite_number(low) and is_finite_number(high):
        return float(low), float(high)
    return None, None


def phi_failed(spec: Mapping[str, Any]) -> bool:
    """Whether Φ missed ``min_phi`` (the engine's verdict where recorded, else Φ < min Φ)."""
    if isinstance(spec.get("phi_passed"), bool):
        return not spec["phi_passed"]
    phi, min_phi = spec.get("phi"), spec.get("min_phi")
    return is_finite_number(phi) and is_finite_number(min_phi) and float(phi) < float(min_phi)


def min_phi_bound(spec: Mapping[str, Any]) -> str:
    """`` on the lower bound`` when ``min_phi`` judges a bound of Φ's interval, else empty."""
    on = spec.get("min_phi_on", "value")
    return "" if on == "value" else f" on the {on} bound"


def measurement_lines(signal: Mapping[str, Any]) -> list[str]:
    """Each miss of ``signal`` checked against its declared measurement uncertainty.

    Failing misses first, then those passing within the uncertainty (ending "; passes").
    """
    unit = signal.get("unit")
    lines: list[str] = []
    for key, suffix in (("failures", ""), ("within_uncertainty", "; passes")):
        for found in items(signal.get(key)):
            if not isinstance(found, Mapping) or not isinstance(found.get("measurement"), Mapping):
                continue
            try:
                check = ErrorCheck.from_dict(found["measurement"])
                name = str(found["characteristic"])
                value, threshold = float(found["value"]), float(found["threshold"])
            except (KeyError, TypeError, ValueError):
                continue
            if check.uncertainty is None:
                continue
            sentence = failure_sentence(
                describe(name).title, name, value, threshold, check, unit if unit else None
            )
            lines.append(sentence + suffix)
    return lines


@dataclass(frozen=True)
class StandardMetricRow:
    """One standard metric of one signal: its scored cell and the raw values behind it."""

    cell: Cell
    components: tuple[tuple[str, float], ...]

    @property
    def title(self) -> str:
        return describe(self.cell.characteristic).label

    def components_text(self, digits: int = 4) -> str:
        return ", ".join(f"{key} {value:.{digits}g}" for key, value in self.components)


def standard_metric_rows(signal: Mapping[str, Any]) -> list[StandardMetricRow]:
    """The "standard metrics" table of ``signal``: empty unless its spec switched any on."""
    parts = signal.get("components")
    parts = parts if isinstance(parts, Mapping) else {}
    rows: list[StandardMetricRow] = []
    for cell in cells(signal):
        if not describe(cell.characteristic).standard:
            continue
        found = parts.get(cell.characteristic)
        components = tuple(
            (str(key), float(value))
            for key, value in (found.items() if isinstance(found, Mapping) else ())
            if is_finite_number(value)
        )
        rows.append(StandardMetricRow(cell, components))
    return rows


def margin(signal: Mapping[str, Any]) -> float | None:
    """Smallest λ − threshold over the gated characteristics (negative: failing)."""
    gaps = [
        c.value - c.threshold
        for c in cells(signal)
        if c.threshold is not None and c.value is not None
    ]
    return min(gaps) if gaps else None


def _min_lambda(signal: Mapping[str, Any]) -> float:
    values = [v for v in _lambdas(signal).values() if v is not None]
    return min(values) if values else 1.0


def signal_order(signal: Mapping[str, Any]) -> tuple[int, float, float, str]:
    """Sort key: failing first, then the smallest margin, then the smallest λ."""
    gap = margin(signal)
    return (
        0 if signal.get("passed") is False else 1,
        gap if gap is not None else math.inf,
        _min_lambda(signal),
        str(signal.get("path", "")),
    )


def ordered_signals(spec: Mapping[str, Any]) -> list[Mapping[str, Any]]:
    return sorted(items(spec.get("signals")), key=signal_order)


def failing_signals(spec: Mapping[str, Any]) -> list[Mapping[str, Any]]:
    return [s for s in ordered_signals(spec) if s.get("passed") is False]


def _parent(path: str) -> str | None:
    return path.rsplit("/", 1)[0] if "/" in path else None


def tree_rows(spec: Mapping[str, Any]) -> list[tuple[Mapping[str, Any], int]]:
    """Signals depth-first as (signal, depth), each set's root first, siblings by position.

    A signal's parent is the signal whose path is its own minus the last segment; signals whose
    parent is not in the spec start a new root.
    """
    signals: list[Mapping[str, Any]] = items(spec.get("signals"))
    by_path = {str(s.get("path", "")): s for s in signals}
    children: dict[str | None, list[Mapping[str, Any]]] = {}
    for s in signals:
        parent = _parent(str(s.get("path", "")))
        if parent not in by_path:
            parent = None
        children.setdefault(parent, []).append(s)

    def key(s: Mapping[str, Any]) -> tuple[float, float, float]:
        def num(name: str) -> float:
            value = s.get(name)
            return float(value) if is_finite_number(value) else math.inf

        return (num("set"), num("level"), num("position"))

    rows: list[tuple[Mapping[str, Any], int]] = []
    seen: set[int] = set()

    def visit(s: Mapping[str, Any], depth: int) -> None:
        if id(s) in seen:
            return
        seen.add(id(s))
        rows.append((s, depth))
        for child in sorted(children.get(str(s.get("path", "")), []), key=key):
            visit(child, depth + 1)

    for root in sorted(children.get(None, []), key=key):
        visit(root, 0)
    return rows


@dataclass(frozen=True)
class GlyphPoint:
    """One glyph of the behavioural plot (paper Fig. 10)."""

    signal: str
    characteristic: str
    index: int
    value: float
    weight: float
    level: int
    status: Status


def _weights(spec: Mapping[str, Any]) -> dict[str, float]:
    try:
        raw = keyed_lambdas(spec.get("weights"))
    except ValueError:
        return {}
    return {name: value for name, value in raw.items() if value is not None}


def glyph_points(spec: Mapping[str, Any]) -> list[GlyphPoint]:
    """Every (signal, λ) pair at x = λ, y = α·β."""
    beta = _weights(spec)
    out: list[GlyphPoint] = []
    for s in items(spec.get("signals")):
        alpha = float(s["alpha"]) if is_finite_number(s.get("alpha")) else 1.0
        level = int(s["level"]) if is_finite_number(s.get("level")) else 1
        for c in cells(s):
            if c.value is None:
                continue
            out.append(
                GlyphPoint(
                    signal=str(s.get("path") or s.get("name") or "?"),
                    characteristic=c.characteristic,
                    index=c.index,
                    value=c.value,
                    weight=alpha
                    * beta.get(c.characteristic, describe(c.characteristic).default_weight),
                    level=max(1, level),
                    status=c.status,
                )
            )
    return out


@dataclass(frozen=True)
class WorstRow:
    spec: str
    spec_index: int
    signal: Mapping[str, Any]
    worst: Cell | None

    @property
    def margin(self) -> float | None:
        return margin(self.signal)


def _worst_cell(signal: Mapping[str, Any]) -> Cell | None:
    all_cells = [c for c in cells(signal) if c.value is not None]
    if not all_cells:
        return None
    gated = [c for c in all_cells if c.threshold is not None]
    if gated:
        return min(gated, key=lambda c: (c.value or 0.0) - (c.threshold or 0.0))
    return min(all_cells, key=lambda c: c.value or 0.0)


def worst_rows(spec_results: Sequence[Mapping[str, Any]], limit: int = 10) -> list[WorstRow]:
    """The ``limit`` worst signals of all specs: failing first, then the closest to failing."""
    rows = [
        WorstRow(str(spec.get("name", "")), i, s, _worst_cell(s))
        for i, spec in enumerate(spec_results)
        for s in items(spec.get("signals"))
    ]
    rows.sort(key=lambda r: signal_order(r.signal))
    return rows[:limit]


def summary(
    spec_results: Iterable[Mapping[str, Any]], verdict: RunVerdict | None = None
) -> dict[str, Any]:
    """Counts for the headers; ``outcome`` is the run's verdict in one line (as the terminal's
    last line), ``passed`` the verdict itself: ``verdict`` as the run decided it, else decided
    here from the results alone. A spec or signal a regression fails counts as failed."""
    specs = list(spec_results)
    regressed = verdict.regressed if verdict is not None else {}

    def signal_failed(spec: Mapping[str, Any], signal: Mapping[str, Any]) -> bool:
        return signal.get("passed") is False or signal.get("path") in regressed.get(
            str(spec.get("spec")), ()
        )

    counts: dict[str, Any] = {
        "specs": len(specs),
        "specs_failed": sum(
            1 for spec in specs if spec.get("passed") is False or str(spec.get("spec")) in regressed
        ),
        "signals": sum(len(items(spec.get("signals"))) for spec in specs),
        "signals_failed": sum(
            signal_failed(spec, signal) for spec in specs for signal in items(spec.get("signals"))
        ),
        "regressions": len(verdict.regressions) if verdict is not None else 0,
    }
    try:
        typed = [SpecResult.from_dict(spec) for spec in specs]
    except (KeyError, TypeError, ValueError):  # a hand-made partial result: the plain counts
        counts["outcome"] = (
            f"{counts['specs']} specs, {counts['specs_failed']} fail; "
            f"{counts['signals_failed']} of {counts['signals']} signals fail"
        )
        counts["passed"] = counts["specs_failed"] == 0 and (verdict is None or verdict.passed)
        return counts
    decided = verdict if verdict is not None else RunVerdict.decide(typed)
    counts["passed"] = decided.passed
    counts["outcome"] = verdict_line(typed, decided) if typed else "no specs scored"
    return counts
