"""What changed between two runs, spec by spec and signal by signal: the comparison's typed
result.

:func:`pytest_hevval.history.compare` makes a :class:`Comparison` from two runs; the regression
rules, the terminal, the Markdown and JSON renderings and the reports read it. It is data, as
the spec results are: ``to_dict`` makes its JSON for ``hevval compare --format json`` and
report.json.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

from ..defaults import split_key

__all__ = [
    "CampaignChange",
    "Comparison",
    "FieldDelta",
    "GroupChange",
    "MatchedBy",
    "SignalComparison",
    "SpecComparison",
    "campaign_changes",
]


@dataclass(frozen=True)
class FieldDelta:
    """One quantity before and after; ``None`` where it was missing or undefined."""

    field: str
    before: float | None
    after: float | None
    #: The 95 % intervals (low, high) of both runs, where recorded.
    before_interval: tuple[float, float] | None = None
    after_interval: tuple[float, float] | None = None

    @property
    def delta(self) -> float | None:
        if self.before is None or self.after is None:
            return None
        return self.after - self.before

    @property
    def beyond_noise(self) -> bool | None:
        """Whether the runs' intervals are disjoint; None where either has none."""
        if self.before_interval is None or self.after_interval is None:
            return None
        (low_before, high_before), (low_after, high_after) = (
            self.before_interval,
            self.after_interval,
        )
        return high_after < low_before or low_after > high_before

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"before": self.before, "after": self.after, "delta": self.delta}
        if self.beyond_noise is not None:
            out["intervals"] = {
                "before": list(self.before_interval or ()),
                "after": list(self.after_interval or ()),
            }
            out["beyond_noise"] = self.beyond_noise
        return out


@dataclass(frozen=True)
class GroupChange:
    """One window, driving phase, condition or region cell whose RMS error changed."""

    grouping: str
    label: str
    rms_before: float
    rms_after: float

    @property
    def ratio(self) -> float:
        return self.rms_after / self.rms_before if self.rms_before > 0 else math.inf

    def text(self, unit: str | None) -> str:
        suffix = f" {unit}" if unit else ""
        if self.grouping in ("windows", "regions"):
            where = self.label
        elif self.grouping == "phases":
            where = f"phase {self.label}"
        else:
            where = f"{self.grouping} {self.label}"
        return f"{where} (RMS {self.rms_before:.3g} → {self.rms_after:.3g}{suffix})"

    def to_dict(self) -> dict[str, Any]:
        return {
            "grouping": self.grouping,
            "label": self.label,
            "rms": {"before": self.rms_before, "after": self.rms_after},
        }


@dataclass(frozen=True)
class SignalComparison:
    """λ1–λ7 and the physical errors of one signal present in both runs."""

    path: str
    name: str
    unit: str | None
    lambdas: tuple[FieldDelta, ...]
    errors: tuple[FieldDelta, ...]
    passed_before: bool | None
    passed_after: bool | None
    #: Windows, phases, conditions and cells where the RMS error fell or rose.
    better: tuple[GroupChange, ...] = ()
    worse: tuple[GroupChange, ...] = ()

    def field(self, name: str) -> FieldDelta:
        for delta in (*self.lambdas, *self.errors):
            if delta.field == name:
                return delta
        raise KeyError(name)

    def to_dict(self) -> dict[str, Any]:
        return {
            "path": self.path,
            "name": self.name,
            "unit": self.unit,
            "lambdas": {d.field: d.to_dict() for d in self.lambdas},
            "errors": {d.field: d.to_dict() for d in self.errors},
            "passed": {"before": self.passed_before, "after": self.passed_after},
            **(
                {
                    "where": {
                        "better": [c.to_dict() for c in self.better],
                        "worse": [c.to_dict() for c in self.worse],
                    }
                }
                if self.better or self.worse
                else {}
            ),
        }


#: How a spec of the current run found its baseline: the same spec file, the same spec name,
#: or being the only spec on each side (``compare(..., pair_single=True)``).
MatchedBy = Literal["path", "name", "single"]


@dataclass(frozen=True)
class SpecComparison:
    """One spec present in both runs: ``key`` in the current run, ``before_key`` in the baseline."""

    key: str
    name: str
    phi: FieldDelta
    passed_before: bool | None
    passed_after: bool | None
    signals: tuple[SignalComparison, ...]
    added_signals: tuple[str, ...]
    removed_signals: tuple[str, ...]
    before_key: str | None = None
    matched_by: MatchedBy = "path"
    #: Data sides (reference, model) whose files differ: digests by the same algorithm
    #: differ. Digests by different algorithms say nothing and are not compared.
    data_changed: tuple[str, ...] = ()

    @property
    def data_note(self) -> str | None:
        """A sentence naming the data files that changed between the runs, else ``None``."""
        if not self.data_changed:
            return None
        return f"{self.key}: data changed ({', '.join(self.data_changed)})"

    @property
    def pairing(self) -> str | None:
        """A sentence naming both sides when they are different specs, else ``None``."""
        before = self.before_key if self.before_key is not None else self.key
        if self.matched_by == "path" and before == self.key:
            return None
        why = {
            "path": "the same spec",
            "name": f"the same spec name {self.name!r}",
            "single": "the only spec on each side",
        }[self.matched_by]
        return f"comparing {before} (before) with {self.key} (after): {why}"

    def to_dict(self) -> dict[str, Any]:
        return {
            "spec": self.key,
            "before_spec": self.before_key if self.before_key is not None else self.key,
            "matched_by": self.matched_by,
            "name": self.name,
            "phi": self.phi.to_dict(),
            "passed": {"before": self.passed_before, "after": self.passed_after},
            "signals": [s.to_dict() for s in self.signals],
            "added_signals": list(self.added_signals),
            "removed_signals": list(self.removed_signals),
            "data_changed": list(self.data_changed),
        }


@dataclass(frozen=True)
class Comparison:
    """Everything that differs between a baseline and the current run, spec by spec.

    Specs or signals present on one side only are listed, never counted as regressions.
    """

    before_label: str
    after_label: str
    specs: tuple[SpecComparison, ...]
    added_specs: tuple[str, ...]
    removed_specs: tuple[str, ...]

    @property
    def pairings(self) -> tuple[str, ...]:
        """One sentence per pair of different specs compared with each other."""
        return tuple(p for p in (s.pairing for s in self.specs) if p is not None)

    @property
    def notes(self) -> tuple[str, ...]:
        """The pairings, then one sentence per spec whose data files changed."""
        changed = tuple(n for n in (s.data_note for s in self.specs) if n is not None)
        return self.pairings + changed

    def to_dict(self) -> dict[str, Any]:
        return {
            "before": self.before_label,
            "after": self.after_label,
            "pairings": list(self.pairings),
            "specs": [s.to_dict() for s in self.specs],
            "added_specs": list(self.added_specs),
            "removed_specs": list(self.removed_specs),
            **(
                {"campaigns": [c.to_dict() for c in changes]}
                if (changes := campaign_changes(self))
                else {}
            ),
        }


@dataclass(frozen=True)
class CampaignChange:
    """Which recordings of one campaign got better and which got worse, by their Φ.

    Where both runs recorded Φ's interval, a change counts as better or worse only when the
    intervals are disjoint; a smaller change is listed as within noise.
    """

    spec: str
    #: (recording, change of Φ), largest change first.
    better: tuple[tuple[str, float], ...]
    worse: tuple[tuple[str, float], ...]
    unchanged: tuple[str, ...]
    #: (recording, change of Φ) where the two runs' Φ intervals overlap, largest change first.
    within_noise: tuple[tuple[str, float], ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return {
            "spec": self.spec,
            "better": [{"recording": r, "phi_delta": d} for r, d in self.better],
            "worse": [{"recording": r, "phi_delta": d} for r, d in self.worse],
            "within_noise": [{"recording": r, "phi_delta": d} for r, d in self.within_noise],
            "unchanged": list(self.unchanged),
        }


def campaign_changes(comparison: Comparison) -> list[CampaignChange]:
    """Per campaign, the recordings whose Φ rose and those whose Φ fell between the runs."""
    deltas: dict[str, list[tuple[str, FieldDelta]]] = {}
    for spec in comparison.specs:
        path, recording = split_key(spec.key)
        if recording is not None:
            deltas.setdefault(path, []).append((recording, spec.phi))
    changes = []
    for path, found in deltas.items():
        changed = [(r, d, phi.beyond_noise) for r, phi in found if (d := _moved(phi)) is not None]
        real = [(r, d) for r, d, beyond in changed if beyond is not False]
        noise = [(r, d) for r, d, beyond in changed if beyond is False]
        changes.append(
            CampaignChange(
                spec=path,
                better=tuple(sorted(((r, d) for r, d in real if d > 0), key=lambda x: -x[1])),
                worse=tuple(sorted(((r, d) for r, d in real if d < 0), key=lambda x: x[1])),
                unchanged=tuple(r for r, phi in found if _moved(phi) is None),
                within_noise=tuple(sorted(noise, key=lambda x: -abs(x[1]))),
            )
        )
    return changes


def _moved(phi: FieldDelta) -> float | None:
    """Φ's change where it is known and not zero, else None."""
    delta = phi.delta
    return delta if delta is not None and math.isfinite(delta) and delta != 0 else None
