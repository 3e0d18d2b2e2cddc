"""One view-model for every report format.

HTML, JSON and Markdown all read the typed results through these functions, so the order of
signals, what counts as "worst", and the pass/fail colour of every λ agree across formats.
The result's fields that are still plain mappings (``data``, ``alignment``, the spec's
``local`` grid) are read here and nowhere else in the reports. No numpy, no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

from ..core.characteristics import CHARACTERISTICS
from ..core.registry import describe, order_names, registered_characteristics
from ..core.uncertainty import Interval
from ..results.campaign import CampaignVerdict, campaign_verdicts
from ..results.codec import is_finite_number
from ..results.spec_facts import RegionGrid
from ..results.spec_result import SignalResult, SpecResult
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
    "alignment_of",
    "cells",
    "characteristic_names",
    "data_quality",
    "failing_signals",
    "glyph_points",
    "is_finite_number",
    "margin",
    "measurement_lines",
    "ordered_signals",
    "region_grid",
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


def characteristic_names(specs: Iterable[SpecResult]) -> list[str]:
    """Every characteristic any signal of ``specs`` carries, in report order."""
    names: list[str] = []
    for spec in specs:
        for signal in spec.signals:
            names.extend(_lambdas(signal))
    return order_names(names) if names else list(CHARACTERISTICS)


#: "within": missed within the measurement uncertainty, and passing by the spec's choice.
Status = Literal["pass", "fail", "ungated", "within"]


def _finite(value: float) -> float | None:
    return float(value) if is_finite_number(value) else None


def _lambdas(signal: SignalResult) -> dict[str, float | None]:
    """λ values by name, in report order; None for a value that is not a finite number."""
    return {name: _finite(signal.lambdas[name]) for name in order_names(signal.lambdas)}


def _thresholds(signal: SignalResult) -> dict[str, float]:
    return {str(k): float(v) for k, v in signal.thresholds.items() if is_finite_number(v)}


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


def cells(signal: SignalResult) -> list[Cell]:
    """λ1…λ7 of ``signal`` coloured against their thresholds.

    A characteristic listed in ``failures`` is failing even if its value would pass (the engine
    is the judge, e.g. for tolerances); otherwise a value below its threshold fails.
    """
    values = _lambdas(signal)
    gates = _thresholds(signal)
    failed = {f.characteristic for f in signal.failures}
    excused = {f.characteristic for f in signal.within_uncertainty}
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
        low, high = interval_bounds(signal.intervals.get(name))
        out.append(Cell(name, i, value, threshold, status, low, high))
    return out


def interval_bounds(interval: Interval | None) -> tuple[float | None, float | None]:
    """(low, high) of a 95 % interval; (None, None) where absent or not finite."""
    if interval is None:
        return None, None
    low, high = interval.low, interval.high
    if is_finite_number(low) and is_finite_number(high):
        return float(low), float(high)
    return None, None


def phi_failed(spec: SpecResult) -> bool:
    """Whether Φ missed ``min_phi``."""
    return not spec.phi_passed


def min_phi_bound(spec: SpecResult) -> str:
    """`` on the lower bound`` when ``min_phi`` judges a bound of Φ's interval, else empty."""
    on = spec.min_phi_on
    return "" if on == "value" else f" on the {on} bound"


def measurement_lines(signal: SignalResult) -> list[str]:
    """Each miss of ``signal`` checked against its declared measurement uncertainty.

    Failing misses first, then those passing within the uncertainty (ending "; passes").
    """
    unit = signal.unit
    lines: list[str] = []
    for found_list, suffix in ((signal.failures, ""), (signal.within_uncertainty, "; passes")):
        for found in found_list:
            check = found.check
            if check is None or check.uncertainty is None:
                continue
            name = found.characteristic
            sentence = failure_sentence(
                describe(name).title,
                name,
                found.value,
                found.threshold,
                check,
                unit if unit else None,
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


def standard_metric_rows(signal: SignalResult) -> list[StandardMetricRow]:
    """The "standard metrics" table of ``signal``: empty unless its spec switched any on."""
    rows: list[StandardMetricRow] = []
    for cell in cells(signal):
        if not describe(cell.characteristic).standard:
            continue
        found = signal.components.get(cell.characteristic, {})
        components = tuple(
            (str(key), float(value)) for key, value in found.items() if is_finite_number(value)
        )
        rows.append(StandardMetricRow(cell, components))
    return rows


def margin(signal: SignalResult) -> float | None:
    """Smallest λ − threshold over the gated characteristics (negative: failing)."""
    gaps = [
        c.value - c.threshold
        for c in cells(signal)
        if c.threshold is not None and c.value is not None
    ]
    return min(gaps) if gaps else None


def _min_lambda(signal: SignalResult) -> float:
    values = [v for v in _lambdas(signal).values() if v is not None]
    return min(values) if values else 1.0


def signal_order(signal: SignalResult) -> tuple[int, float, float, str]:
    """Sort key: failing first, then the smallest margin, then the smallest λ."""
    gap = margin(signal)
    return (
        0 if not signal.passed else 1,
        gap if gap is not None else math.inf,
        _min_lambda(signal),
        signal.path,
    )


def ordered_signals(spec: SpecResult) -> list[SignalResult]:
    return sorted(spec.signals, key=signal_order)


def failing_signals(spec: SpecResult) -> list[SignalResult]:
    return [s for s in ordered_signals(spec) if not s.passed]


def _parent(path: str) -> str | None:
    return path.rsplit("/", 1)[0] if "/" in path else None


def tree_rows(spec: SpecResult) -> list[tuple[SignalResult, int]]:
    """Signals depth-first as (signal, depth), each set's root first, siblings by position.

    A signal's parent is the signal whose path is its own minus the last segment; signals whose
    parent is not in the spec start a new root.
    """
    signals = spec.signals
    by_path = {s.path: s for s in signals}
    children: dict[str | None, list[SignalResult]] = {}
    for s in signals:
        parent = _parent(s.path)
        if parent not in by_path:
            parent = None
        children.setdefault(parent, []).append(s)

    def key(s: SignalResult) -> tuple[float, float, float]:
        return (float(s.set), float(s.level), float(s.position))

    rows: list[tuple[SignalResult, int]] = []
    seen: set[int] = set()

    def visit(s: SignalResult, depth: int) -> None:
        if id(s) in seen:
            return
        seen.add(id(s))
        rows.append((s, depth))
        for child in sorted(children.get(s.path, []), key=key):
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


def glyph_points(spec: SpecResult) -> list[GlyphPoint]:
    """Every (signal, λ) pair at x = λ, y = α·β."""
    beta = {name: value for name, value in spec.weights.items() if is_finite_number(value)}
    out: list[GlyphPoint] = []
    for s in spec.signals:
        alpha = float(s.alpha) if is_finite_number(s.alpha) else 1.0
        level = int(s.level)
        for c in cells(s):
            if c.value is None:
                continue
            out.append(
                GlyphPoint(
                    signal=str(s.path or s.name or "?"),
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
    signal: SignalResult
    worst: Cell | None

    @property
    def margin(self) -> float | None:
        return margin(self.signal)


def _worst_cell(signal: SignalResult) -> Cell | None:
    all_cells = [c for c in cells(signal) if c.value is not None]
    if not all_cells:
        return None
    gated = [c for c in all_cells if c.threshold is not None]
    if gated:
        return min(gated, key=lambda c: (c.value or 0.0) - (c.threshold or 0.0))
    return min(all_cells, key=lambda c: c.value or 0.0)


def worst_rows(spec_results: Sequence[SpecResult], limit: int = 10) -> list[WorstRow]:
    """The ``limit`` worst signals of all specs: failing first, then the closest to failing."""
    rows = [
        WorstRow(spec.name, i, s, _worst_cell(s))
        for i, spec in enumerate(spec_results)
        for s in spec.signals
    ]
    rows.sort(key=lambda r: signal_order(r.signal))
    return rows[:limit]


def summary(
    spec_results: Iterable[SpecResult], verdict: RunVerdict | None = None
) -> dict[str, Any]:
    """Counts for the headers; ``outcome`` is the run's verdict in one line (as the terminal's
    last line), ``passed`` the verdict itself: ``verdict`` as the run decided it, else decided
    here from the results alone. A spec or signal a regression fails counts as failed."""
    specs = list(spec_results)
    regressed = verdict.regressed if verdict is not None else {}

    def signal_failed(spec: SpecResult, signal: SignalResult) -> bool:
        return not signal.passed or signal.path in regressed.get(spec.spec, ())

    decided = verdict if verdict is not None else RunVerdict.decide(specs)
    return {
        "specs": len(specs),
        "specs_failed": sum(1 for spec in specs if not spec.passed or spec.spec in regressed),
        "signals": sum(len(spec.signals) for spec in specs),
        "signals_failed": sum(
            signal_failed(spec, signal) for spec in specs for signal in spec.signals
        ),
        "regressions": len(verdict.regressions) if verdict is not None else 0,
        "passed": decided.passed,
        "outcome": verdict_line(specs, decided) if specs else "no specs scored",
    }


def campaigns_of(
    results: Sequence[SpecResult], verdict: RunVerdict | None
) -> Sequence[CampaignVerdict]:
    """The campaigns' verdicts: the run's verdict judged them once; results shown without a
    verdict (or with one made without campaigns) are judged here."""
    if verdict is not None and verdict.campaigns:
        return verdict.campaigns
    return campaign_verdicts(results)


# -- the result's facts, as the templates and tables read them ---------------------------------
# The facts are typed (results/spec_facts.py); the HTML template and report.md read them by
# their JSON keys, so each accessor hands a template that one part's JSON form.


def data_quality(spec: SpecResult) -> Mapping[str, Any] | None:
    """The data-quality findings on the spec's measurement (``action``, ``findings``)."""
    quality = spec.data.quality
    return quality.to_dict() if quality is not None else None


def alignment_of(spec: SpecResult) -> Mapping[str, Any]:
    """How the model's output was lined up with the measurement (rate, window, offset, …)."""
    return spec.alignment.to_dict()


def region_grid(spec: SpecResult) -> RegionGrid | None:
    """The spec's grid of operating-region cells (shape, labels, counts, Φ per cell)."""
    return spec.local.regions if spec.local is not None else None
