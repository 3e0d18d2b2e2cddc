"""Compare a run with a baseline record, spec by spec and signal by signal.

:func:`compare` pairs the specs of two runs and says what changed: Φ, every λ and physical
error of every signal present in both, the windows and cells whose error rose or fell, the
data files that changed, and per campaign the recordings that got better or worse. Which of
these changes are regressions is the rules' business (:mod:`.compare_fail`,
:mod:`.regressions`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

from ..core.registry import order_names
from ..defaults import REGION_MIN_SAMPLES, split_key
from ..results.codec import (
    data_identity,
    interval_bounds,
    interval_table,
    json_number,
    lambdas_or_none,
)
from ._base import ERROR_FIELDS, HistoryError, spec_key

__all__ = [
    "CampaignChange",
    "Comparison",
    "FieldDelta",
    "GroupChange",
    "MatchedBy",
    "SignalComparison",
    "SpecComparison",
    "campaign_change_lines",
    "campaign_changes",
    "compare",
    "local_changes",
    "specs_of",
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


#: A window, phase, condition or cell counts as better or worse when its RMS error changed
#: by more than this share; smaller changes are noise at the scale of one group.
LOCAL_CHANGE = 0.10
#: Groups with fewer samples on either side are not compared.
LOCAL_MIN_SAMPLES = REGION_MIN_SAMPLES


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


def _tables(local: Any) -> dict[str, Mapping[str, Any]]:
    if not isinstance(local, Mapping):
        return {}
    tables = {
        name: local[name]
        for name in ("windows", "phases", "regions")
        if isinstance(local.get(name), Mapping)
    }
    for name, table in dict(local.get("conditions") or {}).items():
        if isinstance(table, Mapping):
            tables[str(name)] = table
    return tables


def _group_rows(table: Mapping[str, Any]) -> dict[str, tuple[int, Any]]:
    labels, counts, rms = (list(table.get(key) or []) for key in ("labels", "n", "rms"))
    if not len(labels) == len(counts) == len(rms):
        return {}
    return {str(a): (int(b), c) for a, b, c in zip(labels, counts, rms, strict=True)}


def local_changes(
    before: Mapping[str, Any], after: Mapping[str, Any]
) -> tuple[tuple[GroupChange, ...], tuple[GroupChange, ...]]:
    """The groups (by label) whose RMS error fell, and those where it rose, largest first."""
    better: list[GroupChange] = []
    worse: list[GroupChange] = []
    after_tables = _tables(after.get("local"))
    for grouping, old in _tables(before.get("local")).items():
        new = after_tables.get(grouping)
        if new is None:
            continue
        old_rows = _group_rows(old)
        for label, (n, rms) in _group_rows(new).items():
            if label not in old_rows:
                continue
            n_old, rms_old = old_rows[label]
            a, b = json_number(rms), json_number(rms_old)
            if a is None or b is None or min(int(n), int(n_old)) < LOCAL_MIN_SAMPLES:
                continue
            change = GroupChange(grouping, str(label), b, a)
            if a < (1.0 - LOCAL_CHANGE) * b:
                better.append(change)
            elif a > (1.0 + LOCAL_CHANGE) * b:
                worse.append(change)
    better.sort(key=lambda c: c.ratio)
    worse.sort(key=lambda c: -c.ratio)
    return tuple(better), tuple(worse)


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


def campaign_change_lines(comparison: Comparison) -> list[str]:
    """One line per campaign: the recordings that got better, then those that got worse."""

    def listed(items: Sequence[tuple[str, float]]) -> str:
        return ", ".join(f"{r} ({d:+.4f})" for r, d in items) or "none"

    return [
        f"campaign {c.spec} ({comparison.before_label} → {comparison.after_label}): "
        f"Φ better on {listed(c.better)}; worse on {listed(c.worse)}"
        + (f"; within noise on {listed(c.within_noise)}" if c.within_noise else "")
        + (f"; unchanged on {', '.join(c.unchanged)}" if c.unchanged else "")
        for c in campaign_changes(comparison)
    ]


def specs_of(document: Sequence[Mapping[str, Any]] | Mapping[str, Any]) -> list[Mapping[str, Any]]:
    """The spec results of a record, a ``hevval run --json`` document, or a plain list."""
    if isinstance(document, Mapping):
        specs = document.get("specs", document.get("results"))
        if not isinstance(specs, list):
            raise HistoryError(
                "expected a record or run result with a 'specs' list",
                hint="pass a history record or the output of `hevval run --json`",
            )
        return [s for s in specs if isinstance(s, Mapping)]
    return [s for s in document if isinstance(s, Mapping)]


def _label(document: Sequence[Mapping[str, Any]] | Mapping[str, Any], default: str) -> str:
    if isinstance(document, Mapping):
        version = document.get("model_version", document.get("version"))
        if isinstance(version, str) and version:
            return version
    return default


def compare(
    current: Sequence[Mapping[str, Any]] | Mapping[str, Any],
    baseline_record: Sequence[Mapping[str, Any]] | Mapping[str, Any],
    *,
    before_label: str | None = None,
    after_label: str | None = None,
    pair_single: bool = False,
) -> Comparison:
    """Compare the current spec results with a baseline (a record, run result or list).

    Specs are matched by spec file path, then the ones left over by spec name (when the name is
    unique on both sides). With ``pair_single``, a run of exactly one spec is compared with a
    baseline of exactly one spec whatever their paths and names: that is how a model version
    written as a new spec file (``trip-v1`` → ``trip-v2``) is compared with the one before.
    Signals are matched by tree path.
    """
    before_specs = _by_key(specs_of(baseline_record))
    after_specs = _by_key(specs_of(current))
    pairs = _pair(before_specs, after_specs, pair_single=pair_single)
    compared = [
        _compare_spec(key, before_specs[before_key], after_specs[key], before_key, matched_by)
        for key, (before_key, matched_by) in pairs.items()
    ]
    paired_before = {before_key for before_key, _ in pairs.values()}
    return Comparison(
        before_label=before_label or _label(baseline_record, "baseline"),
        after_label=after_label or _label(current, "current"),
        specs=tuple(compared),
        added_specs=tuple(k for k in after_specs if k not in pairs),
        removed_specs=tuple(k for k in before_specs if k not in paired_before),
    )


def _by_key(specs: Sequence[Mapping[str, Any]]) -> dict[str, Mapping[str, Any]]:
    # A spec listed twice in one run keeps its last result, as before.
    return {spec_key(s): s for s in specs}


def _pair(
    before: Mapping[str, Mapping[str, Any]],
    after: Mapping[str, Mapping[str, Any]],
    *,
    pair_single: bool,
) -> dict[str, tuple[str, MatchedBy]]:
    """Current key → (baseline key, how they were matched), in the current run's order."""
    if pair_single and len(before) == 1 and len(after) == 1:
        (before_key,), (after_key,) = before, after
        how: MatchedBy = "path" if before_key == after_key else "single"
        return {after_key: (before_key, how)}
    pairs: dict[str, tuple[str, MatchedBy]] = {k: (k, "path") for k in after if k in before}
    left_before = [k for k in before if k not in pairs]
    left_after = [k for k in after if k not in pairs]
    before_names = _unique_names(before, left_before)
    after_names = _unique_names(after, left_after)
    for name, after_key in after_names.items():
        if name in before_names:
            pairs[after_key] = (before_names[name], "name")
    return {k: pairs[k] for k in after if k in pairs}


def _unique_names(specs: Mapping[str, Mapping[str, Any]], keys: Sequence[str]) -> dict[str, str]:
    """Name → key over ``keys``, leaving out names that more than one spec carries."""
    found: dict[str, str] = {}
    shared: set[str] = set()
    for key in keys:
        name = specs[key].get("name")
        if not isinstance(name, str) or not name:
            continue
        if name in found:
            shared.add(name)
        found[name] = key
    return {name: key for name, key in found.items() if name not in shared}


def _flag(value: Any) -> bool | None:
    return value if isinstance(value, bool) else None


def _signals(spec: Mapping[str, Any]) -> dict[str, Mapping[str, Any]]:
    signals = spec.get("signals", [])
    if not isinstance(signals, list):
        return {}
    return {
        str(sig["path"]): sig
        for sig in signals
        if isinstance(sig, Mapping) and isinstance(sig.get("path"), str)
    }


def _lambda_deltas(before: Mapping[str, Any], after: Mapping[str, Any]) -> tuple[FieldDelta, ...]:
    """λ before and after by name (a result of schema 1 held a list in paper order), with the
    95 % intervals both runs recorded."""
    values_before = lambdas_or_none(before.get("lambdas"))
    values_after = lambdas_or_none(after.get("lambdas"))
    intervals_before = interval_table(before.get("intervals"))
    intervals_after = interval_table(after.get("intervals"))
    return tuple(
        FieldDelta(
            name,
            values_before.get(name),
            values_after.get(name),
            intervals_before.get(name),
            intervals_after.get(name),
        )
        for name in order_names([*values_before, *values_after])
    )


def _compare_spec(
    key: str,
    before: Mapping[str, Any],
    after: Mapping[str, Any],
    before_key: str,
    matched_by: MatchedBy,
) -> SpecComparison:
    before_signals = _signals(before)
    after_signals = _signals(after)
    signals = []
    for path, sig_after in after_signals.items():
        sig_before = before_signals.get(path)
        if sig_before is None:
            continue
        better, worse = local_changes(sig_before, sig_after)
        signals.append(
            SignalComparison(
                path=path,
                name=str(sig_after.get("name", path.rsplit("/", 1)[-1])),
                unit=sig_after.get("unit") if isinstance(sig_after.get("unit"), str) else None,
                lambdas=_lambda_deltas(sig_before, sig_after),
                errors=tuple(
                    FieldDelta(
                        name, json_number(sig_before.get(name)), json_number(sig_after.get(name))
                    )
                    for name in ERROR_FIELDS
                ),
                passed_before=_flag(sig_before.get("passed")),
                passed_after=_flag(sig_after.get("passed")),
                better=better,
                worse=worse,
            )
        )
    return SpecComparison(
        key=key,
        name=str(after.get("name", key)),
        phi=FieldDelta(
            "phi",
            json_number(before.get("phi")),
            json_number(after.get("phi")),
            interval_bounds(before.get("phi_interval")),
            interval_bounds(after.get("phi_interval")),
        ),
        passed_before=_flag(before.get("passed")),
        passed_after=_flag(after.get("passed")),
        signals=tuple(signals),
        added_signals=tuple(p for p in after_signals if p not in before_signals),
        removed_signals=tuple(p for p in before_signals if p not in after_signals),
        before_key=before_key,
        matched_by=matched_by,
        data_changed=_data_changed(before, after),
    )


def _data_changed(before: Mapping[str, Any], after: Mapping[str, Any]) -> tuple[str, ...]:
    """Sides whose data digests differ under the same hash algorithm."""
    sides_before = before.get("data")
    sides_after = after.get("data")
    if not isinstance(sides_before, Mapping) or not isinstance(sides_after, Mapping):
        return ()
    changed = []
    for side in ("reference", "model"):
        old = sides_before.get(side)
        new = sides_after.get(side)
        if not isinstance(old, Mapping) or not isinstance(new, Mapping):
            continue
        old_id = data_identity(old)
        new_id = data_identity(new)
        same_hash = old_id is not None and new_id is not None and old_id[0] == new_id[0]
        if same_hash and old_id != new_id:
            changed.append(side)
    return tuple(changed)
