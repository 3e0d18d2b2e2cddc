"""A model's runtime on one recording, and the spec's ``runtime:`` gate on it.

Timings are noisy, and wall time most: on a busy machine a call waits for a core as long as it
computes, or longer. CPU time is charged only while the model computes, so it is what the gate
judges by default (``clock: cpu``) and what ``hevval compare`` compares; a model called
``repeat`` times is judged on its fastest call, the one least disturbed
(docs/reports.md, "Model runtime").
"""

from __future__ import annotations

import statistics
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from ..defaults import RUNTIME_CLOCKS

__all__ = ["RUNTIME_MIN_GROWTH_S", "RUNTIME_SLOWDOWN", "ModelRuntime", "RuntimeGate"]

#: How many times the CPU time of a model's fastest new call must exceed its fastest recorded
#: one before ``hevval compare`` reports a runtime regression.
RUNTIME_SLOWDOWN = 1.5
#: ... and by at least this many seconds of CPU (summed over the recordings): a model whose
#: calls take a few hundredths of a second is timed at the machine's noise (a 25 ms call came
#: out 0.94× to 1.91× between three identical runs on a loaded machine).
RUNTIME_MIN_GROWTH_S = 0.1


@dataclass(frozen=True)
class RuntimeGate:
    """The spec's ``runtime:`` limits, judged on the fastest call by ``clock``."""

    min_realtime_factor: float | None = None
    max_s: float | None = None
    clock: str = RUNTIME_CLOCKS[0]

    def to_dict(self) -> dict[str, Any]:
        return {
            "min_realtime_factor": self.min_realtime_factor,
            "max_s": self.max_s,
            "clock": self.clock,
        }


@dataclass(frozen=True)
class ModelRuntime:
    """What running the model on one recording cost, call by call."""

    #: "callable" or "fmu".
    kind: str
    #: The simulated span (the model output's time span), in seconds.
    simulated_s: float
    #: Wall and CPU time of every call, in seconds.
    wall_s: tuple[float, ...]
    cpu_s: tuple[float, ...]
    #: Resident memory added at the peak of the largest call, in bytes; None: not measured.
    peak_memory_bytes: int | None = None
    #: FMU: integrator or communication steps, and events, where fmpy reports them.
    steps: int | None = None
    events: int | None = None
    gate: RuntimeGate | None = None

    @property
    def repeats(self) -> int:
        return len(self.wall_s)

    @property
    def wall_median_s(self) -> float:
        return statistics.median(self.wall_s)

    @property
    def wall_min_s(self) -> float:
        return min(self.wall_s)

    @property
    def wall_max_s(self) -> float:
        return max(self.wall_s)

    @property
    def cpu_median_s(self) -> float:
        return statistics.median(self.cpu_s)

    @property
    def cpu_min_s(self) -> float:
        return min(self.cpu_s)

    @property
    def realtime_factor(self) -> float:
        """Simulated seconds per wall-clock second, over the median call."""
        return _factor(self.simulated_s, self.wall_median_s)

    def fastest_s(self, clock: str) -> float:
        """The fastest call by ``clock`` (``cpu`` or ``wall``)."""
        return self.cpu_min_s if clock == "cpu" else self.wall_min_s

    def best_realtime_factor(self, clock: str) -> float:
        """Simulated seconds per second of ``clock`` over the fastest call: what a gate on
        that clock judges (``cpu``: what the model reaches on a core of its own)."""
        return _factor(self.simulated_s, self.fastest_s(clock))

    def failures(self) -> list[str]:
        """What the ``runtime:`` gate finds wrong, in words; empty when it passes."""
        if self.gate is None:
            return []
        clock = self.gate.clock
        fastest = self.fastest_s(clock)
        calls = f"the fastest of {self.repeats} call{'s' if self.repeats > 1 else ''}"
        time_of = "CPU time" if clock == "cpu" else "wall time"
        found = []
        limit = self.gate.min_realtime_factor
        if limit is not None and self.best_realtime_factor(clock) < limit:
            found.append(
                f"real-time factor ({clock}) {self.best_realtime_factor(clock):.4g} < {limit:g} "
                f"({self.simulated_s:.4g} s simulated in {fastest:.4g} s of {time_of}, {calls})"
            )
        if self.gate.max_s is not None and fastest > self.gate.max_s:
            found.append(
                f"model call {fastest:.4g} s of {time_of} > max {self.gate.max_s:g} s ({calls})"
            )
        return found

    @property
    def passed(self) -> bool:
        return not self.failures()

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "kind": self.kind,
            "simulated_s": self.simulated_s,
            "wall_s": list(self.wall_s),
            "cpu_s": list(self.cpu_s),
            "wall_median_s": self.wall_median_s,
            "cpu_median_s": self.cpu_median_s,
            "realtime_factor": self.realtime_factor,
            "peak_memory_bytes": self.peak_memory_bytes,
            "repeats": self.repeats,
        }
        if self.steps is not None:
            out["steps"] = self.steps
        if self.events is not None:
            out["events"] = self.events
        if self.gate is not None:
            out["gate"] = self.gate.to_dict()
            out["passed"] = self.passed
            out["failures"] = self.failures()
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ModelRuntime:
        gate = data.get("gate")
        return cls(
            kind=str(data["kind"]),
            simulated_s=float(data["simulated_s"]),
            wall_s=_floats(data["wall_s"]),
            cpu_s=_floats(data["cpu_s"]),
            peak_memory_bytes=_optional_int(data.get("peak_memory_bytes")),
            steps=_optional_int(data.get("steps")),
            events=_optional_int(data.get("events")),
            gate=RuntimeGate(
                min_realtime_factor=_optional_float(gate.get("min_realtime_factor")),
                max_s=_optional_float(gate.get("max_s")),
                clock=str(gate.get("clock", RUNTIME_CLOCKS[0])),
            )
            if isinstance(gate, Mapping)
            else None,
        )


def _factor(simulated: float, wall: float) -> float:
    return simulated / wall if wall > 0 else float("inf")


def _floats(values: Sequence[Any]) -> tuple[float, ...]:
    return tuple(float(v) for v in values)


def _optional_int(value: Any) -> int | None:
    return None if value is None else int(value)


def _optional_float(value: Any) -> float | None:
    return None if value is None else float(value)
