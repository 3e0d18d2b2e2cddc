"""The model's runtime across two runs, with a rule that a busy machine does not trip.

A timing is noisy, and one-sided: load on the machine only ever slows a call down. So a model is
called slower only when even its fastest new calls take longer than its slowest recorded ones
by more than :data:`~pytest_hevval.results.runtime.RUNTIME_SLOWDOWN` (1.5×). Per spec file, the
calls of every recording both runs hold are summed first (a campaign's dozens of short calls
add up to one steady figure). A spec called ``repeat`` times per recording
(``runtime: {repeat: k}``) is judged on its fastest and slowest of k, which keeps a single
loaded call from raising a false alarm (docs/reports.md, "Model runtime").
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from ..defaults import split_key
from ..results.runtime import RUNTIME_SLOWDOWN, ModelRuntime

__all__ = ["RuntimeChange", "runtime_change_lines", "runtime_changes"]


@dataclass(frozen=True)
class RuntimeChange:
    """One spec file's model runtime, before and after, over the recordings both runs hold."""

    spec: str
    recordings: int
    #: Sums over the recordings of the median, fastest and slowest call.
    before_median_s: float
    after_median_s: float
    before_slowest_s: float
    after_fastest_s: float
    before_realtime_factor: float
    after_realtime_factor: float

    @property
    def ratio(self) -> float:
        """How many times slower the median call got (below 1: faster)."""
        return self.after_median_s / self.before_median_s if self.before_median_s > 0 else 1.0

    @property
    def regression(self) -> bool:
        return self.after_fastest_s > RUNTIME_SLOWDOWN * self.before_slowest_s

    def to_dict(self) -> dict[str, Any]:
        return {
            "spec": self.spec,
            "recordings": self.recordings,
            "before_median_s": self.before_median_s,
            "after_median_s": self.after_median_s,
            "before_slowest_s": self.before_slowest_s,
            "after_fastest_s": self.after_fastest_s,
            "before_realtime_factor": self.before_realtime_factor,
            "after_realtime_factor": self.after_realtime_factor,
            "ratio": self.ratio,
            "regression": self.regression,
        }


def _runtimes(specs: Sequence[Mapping[str, Any]]) -> dict[str, dict[str, ModelRuntime]]:
    """Spec file → recording key → runtime, for every result that has one."""
    out: dict[str, dict[str, ModelRuntime]] = {}
    for spec in specs:
        raw = spec.get("runtime")
        key = str(spec.get("spec", spec.get("name", "")))
        if isinstance(raw, Mapping):
            out.setdefault(split_key(key)[0], {})[key] = ModelRuntime.from_dict(raw)
    return out


def runtime_changes(
    before: Sequence[Mapping[str, Any]], after: Sequence[Mapping[str, Any]]
) -> list[RuntimeChange]:
    """Each spec file's model runtime in ``before`` and ``after``. With one timed spec file on
    each side under different names (trip-v1 → trip-v2), those two are compared."""
    old, new = _runtimes(before), _runtimes(after)
    pairs = [(name, old[name], new[name]) for name in new if name in old]
    if not pairs and len(old) == len(new) == 1:
        (name_old, runs_old), (name_new, runs_new) = (
            next(iter(old.items())),
            next(iter(new.items())),
        )
        # One recording each (a spec, not a campaign): pair the two whatever their keys.
        if len(runs_old) == len(runs_new) == 1:
            only_old, only_new = next(iter(runs_old.values())), next(iter(runs_new.values()))
            pairs = [(f"{name_old} → {name_new}", {"": only_old}, {"": only_new})]
    changes = []
    for name, runs_old, runs_new in pairs:
        shared = [key for key in runs_new if key in runs_old]
        if not shared:
            continue
        was = [runs_old[key] for key in shared]
        now = [runs_new[key] for key in shared]
        simulated = sum(r.simulated_s for r in now)
        before_median = sum(r.wall_median_s for r in was)
        after_median = sum(r.wall_median_s for r in now)
        changes.append(
            RuntimeChange(
                spec=name,
                recordings=len(shared),
                before_median_s=before_median,
                after_median_s=after_median,
                before_slowest_s=sum(r.wall_max_s for r in was),
                after_fastest_s=sum(r.wall_min_s for r in now),
                before_realtime_factor=sum(r.simulated_s for r in was) / before_median
                if before_median > 0
                else float("inf"),
                after_realtime_factor=simulated / after_median
                if after_median > 0
                else float("inf"),
            )
        )
    return changes


def runtime_change_lines(changes: Sequence[RuntimeChange], before: str, after: str) -> list[str]:
    """One line per spec file whose model ran in both runs; regressions say so."""
    lines = []
    for change in changes:
        what = (
            f"RUNTIME REGRESSION (the fastest new calls, {change.after_fastest_s:.3g} s, are "
            f"over {RUNTIME_SLOWDOWN:g}× the slowest recorded, {change.before_slowest_s:.3g} s)"
            if change.regression
            else "within the noise rule"
        )
        over = f" over {change.recordings} recordings" if change.recordings > 1 else ""
        lines.append(
            f"model runtime {change.spec} ({before} → {after}){over}: "
            f"{change.before_median_s:.3g} s → {change.after_median_s:.3g} s "
            f"(×{change.ratio:.2f}; real-time factor {change.before_realtime_factor:.4g} → "
            f"{change.after_realtime_factor:.4g}): {what}"
        )
    return lines
