"""The model's runtime across two runs, with a rule that a busy machine does not trip.

Wall time on a busy machine measures the machine as much as the model: a call waits for a core
as long as it computes, or longer. CPU time is charged only while the model computes, and the
fastest of a model's calls is the one least disturbed (caches, a core shared with another
process). So a model is slower when the CPU time of its fastest calls grew by more than
:data:`~pytest_hevval.results.runtime.RUNTIME_SLOWDOWN` (1.5×). Per spec file, the fastest calls
of every recording both runs hold are summed first, so a campaign's dozens of short calls add
up to one steady figure; ``runtime: {repeat: k}`` gives each recording k calls to take the
fastest of (docs/reports.md, "Model runtime").
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from ..defaults import split_key
from ..results.recorded import RecordedSpec, Side, recorded_specs
from ..results.runtime import RUNTIME_MIN_GROWTH_S, RUNTIME_SLOWDOWN, ModelRuntime

__all__ = ["RuntimeChange", "runtime_change_lines", "runtime_changes"]


@dataclass(frozen=True)
class RuntimeChange:
    """One spec file's model runtime, before and after, over the recordings both runs hold."""

    spec: str
    recordings: int
    #: Sums over the recordings of the fastest call's CPU time (what the rule judges) and of
    #: the median call's wall time (what a user waits for).
    before_cpu_s: float
    after_cpu_s: float
    before_wall_s: float
    after_wall_s: float
    before_realtime_factor: float
    after_realtime_factor: float

    @property
    def ratio(self) -> float:
        """How many times more CPU the fastest calls took (below 1: less)."""
        return self.after_cpu_s / self.before_cpu_s if self.before_cpu_s > 0 else 1.0

    @property
    def regression(self) -> bool:
        return (
            self.after_cpu_s > RUNTIME_SLOWDOWN * self.before_cpu_s
            and self.after_cpu_s - self.before_cpu_s >= RUNTIME_MIN_GROWTH_S
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "spec": self.spec,
            "recordings": self.recordings,
            "before_cpu_s": self.before_cpu_s,
            "after_cpu_s": self.after_cpu_s,
            "before_wall_s": self.before_wall_s,
            "after_wall_s": self.after_wall_s,
            "before_realtime_factor": self.before_realtime_factor,
            "after_realtime_factor": self.after_realtime_factor,
            "ratio": self.ratio,
            "regression": self.regression,
        }


def _runtimes(specs: Sequence[RecordedSpec]) -> dict[str, dict[str, ModelRuntime]]:
    """Spec file → recording key → runtime, for every result that has one."""
    out: dict[str, dict[str, ModelRuntime]] = {}
    for spec in specs:
        if spec.runtime is not None:
            out.setdefault(split_key(spec.key)[0], {})[spec.key] = spec.runtime
    return out


def runtime_changes(before: Side, after: Side) -> list[RuntimeChange]:
    """Each spec file's model runtime in ``before`` and ``after``. With one timed spec file on
    each side under different names (trip-v1 → trip-v2), those two are compared."""
    old, new = _runtimes(recorded_specs(before)), _runtimes(recorded_specs(after))
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
        before_wall = sum(r.wall_median_s for r in was)
        after_wall = sum(r.wall_median_s for r in now)
        changes.append(
            RuntimeChange(
                spec=name,
                recordings=len(shared),
                before_cpu_s=sum(r.cpu_min_s for r in was),
                after_cpu_s=sum(r.cpu_min_s for r in now),
                before_wall_s=before_wall,
                after_wall_s=after_wall,
                before_realtime_factor=_factor(sum(r.simulated_s for r in was), before_wall),
                after_realtime_factor=_factor(sum(r.simulated_s for r in now), after_wall),
            )
        )
    return changes


def _factor(simulated: float, wall: float) -> float:
    return simulated / wall if wall > 0 else float("inf")


def runtime_change_lines(changes: Sequence[RuntimeChange], before: str, after: str) -> list[str]:
    """One line per spec file whose model ran in both runs; regressions say so."""
    lines = []
    for change in changes:
        if change.regression:
            what = f"RUNTIME REGRESSION (more than {RUNTIME_SLOWDOWN:g}× the CPU time)"
        elif change.ratio > RUNTIME_SLOWDOWN:
            what = (
                f"under {RUNTIME_MIN_GROWTH_S:g} s of CPU more, within the machine's noise; "
                "not a regression"
            )
        else:
            what = f"within {RUNTIME_SLOWDOWN:g}× the CPU time"
        over = f" over {change.recordings} recordings" if change.recordings > 1 else ""
        lines.append(
            f"model runtime {change.spec} ({before} → {after}){over}: CPU of the fastest calls "
            f"{change.before_cpu_s:.3g} s → {change.after_cpu_s:.3g} s (×{change.ratio:.2f}); "
            f"wall {change.before_wall_s:.3g} s → {change.after_wall_s:.3g} s, real-time factor "
            f"{change.before_realtime_factor:.4g} → {change.after_realtime_factor:.4g}: {what}"
        )
    return lines
