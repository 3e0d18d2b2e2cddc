"""Compare a run with a baseline, spec by spec and signal by signal.

:func:`compare` pairs the specs of two runs and says what changed: Φ, every λ and physical
error of every signal present in both, the windows and cells whose error rose or fell, the
data files that changed, and per campaign the recordings that got better or worse. It reads
both runs as :class:`~pytest_hevval.results.recorded.RecordedSpec` (the current run's typed
results, or a recorded run read from its file) and returns the typed
:class:`~pytest_hevval.results.changes.Comparison`. Which of these changes are regressions is
the rules' business (:mod:`.compare_fail`, :mod:`.regressions`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from ..core.registry import order_names
from ..defaults import REGION_MIN_SAMPLES
from ..results.changes import (
    Comparison,
    FieldDelta,
    GroupChange,
    MatchedBy,
    SignalComparison,
    SpecComparison,
    campaign_changes,
)
from ..results.recorded import (
    DATA_SIDES,
    GroupRows,
    RecordedRun,
    RecordedSignal,
    RecordedSpec,
    Side,
    recorded_specs,
)
from ._base import ERROR_FIELDS

__all__ = ["campaign_change_lines", "compare", "local_changes"]

#: A window, phase, condition or cell counts as better or worse when its RMS error changed
#: by more than this share; smaller changes are noise at the scale of one group.
LOCAL_CHANGE = 0.10
#: Groups with fewer samples on either side are not compared.
LOCAL_MIN_SAMPLES = REGION_MIN_SAMPLES


def local_changes(
    before: RecordedSignal, after: RecordedSignal
) -> tuple[tuple[GroupChange, ...], tuple[GroupChange, ...]]:
    """The groups (by label) whose RMS error fell, and those where it rose, largest first."""
    better: list[GroupChange] = []
    worse: list[GroupChange] = []
    for grouping, old_rows in before.local.items():
        new_rows: GroupRows | None = after.local.get(grouping)
        if new_rows is None:
            continue
        for label, (n, rms) in new_rows.items():
            if label not in old_rows:
                continue
            n_old, rms_old = old_rows[label]
            if rms is None or rms_old is None or min(n, n_old) < LOCAL_MIN_SAMPLES:
                continue
            change = GroupChange(grouping, label, rms_old, rms)
            if rms < (1.0 - LOCAL_CHANGE) * rms_old:
                better.append(change)
            elif rms > (1.0 + LOCAL_CHANGE) * rms_old:
                worse.append(change)
    better.sort(key=lambda c: c.ratio)
    worse.sort(key=lambda c: -c.ratio)
    return tuple(better), tuple(worse)


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


def _label(side: Side, default: str) -> str:
    if isinstance(side, RecordedRun) and side.model_version:
        return side.model_version
    return default


def compare(
    current: Side,
    baseline: Side,
    *,
    before_label: str | None = None,
    after_label: str | None = None,
    pair_single: bool = False,
) -> Comparison:
    """Compare the current spec results with a baseline (a recorded run, or results).

    Specs are matched by spec file path, then the ones left over by spec name (when the name is
    unique on both sides). With ``pair_single``, a run of exactly one spec is compared with a
    baseline of exactly one spec whatever their paths and names: that is how a model version
    written as a new spec file (``trip-v1`` → ``trip-v2``) is compared with the one before.
    Signals are matched by tree path.
    """
    before_specs = _by_key(recorded_specs(baseline))
    after_specs = _by_key(recorded_specs(current))
    pairs = _pair(before_specs, after_specs, pair_single=pair_single)
    compared = [
        _compare_spec(key, before_specs[before_key], after_specs[key], before_key, matched_by)
        for key, (before_key, matched_by) in pairs.items()
    ]
    paired_before = {before_key for before_key, _ in pairs.values()}
    return Comparison(
        before_label=before_label or _label(baseline, "baseline"),
        after_label=after_label or _label(current, "current"),
        specs=tuple(compared),
        added_specs=tuple(k for k in after_specs if k not in pairs),
        removed_specs=tuple(k for k in before_specs if k not in paired_before),
    )


def _by_key(specs: Sequence[RecordedSpec]) -> dict[str, RecordedSpec]:
    # A spec listed twice in one run keeps its last result, as before.
    return {s.key: s for s in specs}


def _pair(
    before: Mapping[str, RecordedSpec],
    after: Mapping[str, RecordedSpec],
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


def _unique_names(specs: Mapping[str, RecordedSpec], keys: Sequence[str]) -> dict[str, str]:
    """Name → key over ``keys``, leaving out names that more than one spec carries."""
    found: dict[str, str] = {}
    shared: set[str] = set()
    for key in keys:
        name = specs[key].name
        if not name:
            continue
        if name in found:
            shared.add(name)
        found[name] = key
    return {name: key for name, key in found.items() if name not in shared}


def _lambda_deltas(before: RecordedSignal, after: RecordedSignal) -> tuple[FieldDelta, ...]:
    """λ before and after by name, with the 95 % intervals both runs recorded."""
    return tuple(
        FieldDelta(
            name,
            before.lambdas.get(name),
            after.lambdas.get(name),
            before.intervals.get(name),
            after.intervals.get(name),
        )
        for name in order_names([*before.lambdas, *after.lambdas])
    )


def _compare_spec(
    key: str,
    before: RecordedSpec,
    after: RecordedSpec,
    before_key: str,
    matched_by: MatchedBy,
) -> SpecComparison:
    before_signals = {signal.path: signal for signal in before.signals}
    after_signals = {signal.path: signal for signal in after.signals}
    signals = []
    for path, sig_after in after_signals.items():
        sig_before = before_signals.get(path)
        if sig_before is None:
            continue
        better, worse = local_changes(sig_before, sig_after)
        signals.append(
            SignalComparison(
                path=path,
                name=sig_after.name,
                unit=sig_after.unit,
                lambdas=_lambda_deltas(sig_before, sig_after),
                errors=tuple(
                    FieldDelta(name, sig_before.errors.get(name), sig_after.errors.get(name))
                    for name in ERROR_FIELDS
                ),
                passed_before=sig_before.passed,
                passed_after=sig_after.passed,
                better=better,
                worse=worse,
            )
        )
    return SpecComparison(
        key=key,
        name=after.name if after.name is not None else key,
        phi=FieldDelta("phi", before.phi, after.phi, before.phi_interval, after.phi_interval),
        passed_before=before.passed,
        passed_after=after.passed,
        signals=tuple(signals),
        added_signals=tuple(p for p in after_signals if p not in before_signals),
        removed_signals=tuple(p for p in before_signals if p not in after_signals),
        before_key=before_key,
        matched_by=matched_by,
        data_changed=_data_changed(before, after),
    )


def _data_changed(before: RecordedSpec, after: RecordedSpec) -> tuple[str, ...]:
    """Sides whose data digests differ under the same hash algorithm."""
    if before.data is None or after.data is None:
        return ()
    changed = []
    for side in DATA_SIDES:
        if side not in before.data or side not in after.data:
            continue
        old_id, new_id = before.data[side], after.data[side]
        same_hash = old_id is not None and new_id is not None and old_id[0] == new_id[0]
        if same_hash and old_id != new_id:
            changed.append(side)
    return tuple(changed)
