"""The cost of running a model: wall time, CPU time and peak memory of one call.

A model that runs itself (a callable or an FMU) is measured where it is called; a model given
as exported files ran elsewhere and carries no runtime. Peak memory is the growth of the
process's resident set at its peak during the call, from Linux's ``VmHWM`` after resetting it
(``/proc/self/clear_refs``); elsewhere, or where the reset is not allowed, it is not measured.
Tracing allocations instead (``tracemalloc``) slowed the example's EV model twentyfold, which
would time the tracer rather than the model.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

__all__ = ["CallCost", "measure_call"]

T = TypeVar("T")

_STATUS = "/proc/self/status"
_CLEAR_REFS = "/proc/self/clear_refs"
#: Written to clear_refs: reset the peak resident set size to the current one (Linux ≥ 4.0).
_RESET_PEAK = "5"


@dataclass(frozen=True)
class CallCost:
    """One call of a model, measured."""

    wall_s: float
    #: CPU time of the process during the call (every thread, the model's own included).
    cpu_s: float
    #: Resident memory the call added at its peak, in bytes; None where not measurable.
    peak_bytes: int | None


def _status_bytes(key: str) -> int | None:
    try:
        with open(_STATUS, encoding="ascii") as status:
            for line in status:
                if line.startswith(key + ":"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def _reset_peak() -> bool:
    try:
        with open(_CLEAR_REFS, "w", encoding="ascii") as clear:
            clear.write(_RESET_PEAK)
    except OSError:
        return False
    return True


def measure_call(call: Callable[[], T]) -> tuple[T, CallCost]:
    """Run ``call`` once and say what it cost."""
    resident = _status_bytes("VmRSS") if _reset_peak() else None
    cpu = time.process_time()
    start = time.perf_counter()
    value = call()
    wall = time.perf_counter() - start
    cpu = time.process_time() - cpu
    peak = _status_bytes("VmHWM") if resident is not None else None
    growth = None if peak is None or resident is None else max(peak - resident, 0)
    return value, CallCost(wall_s=wall, cpu_s=cpu, peak_bytes=growth)
