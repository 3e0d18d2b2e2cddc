"""Regressions: the quantities of a comparison that got worse by more than a rule allows.

A comparison (:class:`~pytest_hevval.results.changes.Comparison`) says what changed; the
rules of ``--compare-fail`` (:mod:`.compare_fail`) say how much of a drop is acceptable;
:func:`regressions` applies the one to the other.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from ..core.registry import describe
from ..results.changes import Comparison, FieldDelta
from .compare_fail import Rule

__all__ = ["Regression", "regressions"]

# Float noise from re-running the same model must never count as a drop.
_TOLERANCE = 1e-12


@dataclass(frozen=True)
class Regression:
    """A quantity that got worse by more than a rule allows."""

    spec: str
    signal: str | None
    field: str
    before: float
    after: float | None
    allowed: float
    rule: str
    #: Both runs' 95 % intervals, when the rule asked for a change beyond noise.
    intervals: tuple[tuple[float, float], tuple[float, float]] | None = None

    def _noise_text(self) -> str:
        if self.intervals is None:
            return ""
        (a, b), (c, d) = self.intervals
        return f"; 95 % intervals [{a:.4g}, {b:.4g}] → [{c:.4g}, {d:.4g}] do not overlap"

    def __str__(self) -> str:
        where = self.spec if self.signal is None else f"{self.spec}::{self.signal}"
        after = "undefined" if self.after is None else f"{self.after:.4g}"
        if self.field == "lag":
            change = "grew" if self.after is not None else "became undefined"
            return (
                f"{where}: |lag| {change} {self.before:.4g} s → {after} s "
                f"(allowed growth {self.allowed:.4g} s, rule {self.rule!r})"
            )
        if self.field == "phi":
            label = "Φ"
        else:
            symbol = describe(self.field).symbol
            label = self.field if symbol == self.field else f"{symbol} {self.field}"
        return (
            f"{where}: {label} dropped {self.before:.4g} → {after} "
            f"(allowed drop {self.allowed:.4g}, rule {self.rule!r}{self._noise_text()})"
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "spec": self.spec,
            "signal": self.signal,
            "field": self.field,
            "before": self.before,
            "after": self.after,
            "allowed": self.allowed,
            "rule": self.rule,
            **({"intervals": [list(i) for i in self.intervals]} if self.intervals else {}),
        }


def regressions(comparison: Comparison, rules: Sequence[Rule]) -> list[Regression]:
    """Every quantity that worsened by more than a matching rule allows.

    Φ and λ are "higher is better": a drop larger than allowed is a regression, and so is a
    value that was defined before and is undefined (NaN) now. ``lag`` compares |lag_s|, where
    growth is the regression. Nothing that was undefined before can regress.
    """
    found: list[Regression] = []
    for spec in comparison.specs:
        for rule in rules:
            if rule.applies_to("phi"):
                hit = _worsened(
                    spec.phi.before,
                    spec.phi.after,
                    rule,
                    higher_is_better=True,
                    beyond_noise=spec.phi.beyond_noise,
                )
                if hit is not None:
                    found.append(
                        Regression(
                            spec.key,
                            None,
                            "phi",
                            spec.phi.before or 0.0,
                            *hit,
                            rule.text,
                            _noise_intervals(spec.phi, rule),
                        )
                    )
        for signal in spec.signals:
            for rule in rules:
                for delta in signal.lambdas:
                    if not rule.applies_to(delta.field):
                        continue
                    hit = _worsened(
                        delta.before,
                        delta.after,
                        rule,
                        higher_is_better=True,
                        beyond_noise=delta.beyond_noise,
                    )
                    if hit is not None:
                        found.append(
                            Regression(
                                spec.key,
                                signal.path,
                                delta.field,
                                delta.before or 0.0,
                                *hit,
                                rule.text,
                                _noise_intervals(delta, rule),
                            )
                        )
                if rule.applies_to("lag"):
                    lag = signal.field("lag_s")
                    before = None if lag.before is None else abs(lag.before)
                    after = None if lag.after is None else abs(lag.after)
                    hit = _worsened(before, after, rule, higher_is_better=False)
                    if hit is not None:
                        found.append(
                            Regression(spec.key, signal.path, "lag", before or 0.0, *hit, rule.text)
                        )
    return found


def _noise_intervals(
    delta: FieldDelta, rule: Rule
) -> tuple[tuple[float, float], tuple[float, float]] | None:
    """The intervals that showed a change beyond noise, for a rule that asked."""
    if not rule.beyond_noise or delta.before_interval is None or delta.after_interval is None:
        return None
    return (delta.before_interval, delta.after_interval)


def _worsened(
    before: float | None,
    after: float | None,
    rule: Rule,
    *,
    higher_is_better: bool,
    beyond_noise: bool | None = None,
) -> tuple[float | None, float] | None:
    if before is None:
        return None
    allowed = rule.allowed(before)
    if after is None:
        return (None, allowed)
    change = (before - after) if higher_is_better else (after - before)
    if rule.beyond_noise and beyond_noise is False:
        return None  # within noise: the intervals overlap
    if change > allowed + _TOLERANCE:
        return (after, allowed)
    return None
