"""A data-quality gate on the measurement: a failing model must not be blamed for bad data.

Every reference channel a spec uses is checked on its own time base for what loggers get
wrong: gaps in time, stretches a logger filled by straight-line interpolation, flat-lined
(stuck) values, saturation at a constant, NaN runs, and, where a physical rate limit is
declared, spikes. Each finding names the channel and the time span. The spec's
``data_quality:`` sets the limits and what happens: ``warn`` (report), ``omit`` (score around
the bad stretches) or ``error`` (the spec errors, saying the measurement is at fault).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from types import ModuleType
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from ..core import kernel
from ..core.groups import runs
from ..errors import DataError
from .record import Record

__all__ = [
    "QUALITY_ACTIONS",
    "Finding",
    "QualityLimits",
    "assess",
    "fail_on",
    "mask_on_grid",
]

FloatArray = npt.NDArray[np.float64]
Action = Literal["warn", "omit", "error"]
QUALITY_ACTIONS: tuple[str, ...] = ("warn", "omit", "error")

#: A step in time longer than this is a gap (dropout, logger pause) on any channel.
MAX_GAP_S = 5.0
#: A run this long whose second difference is within the channel's resolution, while it moves,
#: is what a logger writes when it fills a dropout by linear interpolation; real signals are
#: not that straight for that long.
STRAIGHT_RUN_S = 20.0
#: Exactly the same value this long is a stuck sensor (a vehicle at a stop moves on sooner).
FLAT_RUN_S = 600.0
#: A run this long at the channel's maximum (or a non-zero minimum) is saturation.
SATURATION_RUN_S = 10.0
#: Saturation is reported when the extreme is held this many separate times or more.
SATURATION_EPISODES = 2
#: At most this many findings of one kind on one channel are listed; the rest are counted.
MAX_LISTED = 5


@dataclass(frozen=True)
class QualityLimits:
    """The spec's ``data_quality:`` (every limit in seconds, rates per second)."""

    action: Action = "warn"
    max_gap_s: float = MAX_GAP_S
    straight_run_s: float = STRAIGHT_RUN_S
    flat_run_s: float = FLAT_RUN_S
    saturation_run_s: float = SATURATION_RUN_S
    #: Channel → largest physical rate of change (signal unit per second); beyond is a spike.
    rate_limits: Mapping[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class Finding:
    """One stretch of one channel that the measurement got wrong."""

    channel: str
    kind: str
    start_s: float
    stop_s: float
    detail: str

    def to_dict(self) -> dict[str, Any]:
        return {
            "channel": self.channel,
            "kind": self.kind,
            "start_s": self.start_s,
            "stop_s": self.stop_s,
            "detail": self.detail,
        }

    def line(self) -> str:
        return (
            f"{self.channel}: {self.kind} at {self.start_s:.6g}–{self.stop_s:.6g} s ({self.detail})"
        )


def _runs(mask: npt.NDArray[np.bool_]) -> list[tuple[int, int]]:
    """[start, stop) of each run of True."""
    starts, stops = runs(mask)
    return list(zip(starts.tolist(), stops.tolist(), strict=True))


def _long_runs(
    mask: npt.NDArray[np.bool_], time: FloatArray, seconds: float, widen: int = 0
) -> list[tuple[int, int]]:
    """Runs of ``mask`` (over samples, or over steps when ``widen`` is 1 or 2) lasting at least
    ``seconds``, as sample index ranges [start, stop] inclusive."""
    first, stops = runs(mask)
    if first.shape[0] == 0:
        return []
    final = np.minimum(stops - 1 + widen, time.shape[0] - 1)
    keep = time[final] - time[first] >= seconds
    return list(zip(first[keep].tolist(), final[keep].tolist(), strict=True))


def assess(
    record: Record, channels: Iterable[str], limits: QualityLimits, *, threads: int = 1
) -> list[Finding]:
    """Every finding on the named channels of ``record``, channel by channel, in time order.

    The time stamps are examined once per distinct time array (channels of one table or MDF
    group share theirs); the values of each channel are examined on up to ``threads`` threads
    (numpy's loops release the GIL). The findings do not depend on ``threads``.
    """
    names = [name for name in channels if name in record.channels]
    # (an expression's helper column may live on the model side)
    times: dict[int, tuple[object, FloatArray, _TimeSpans | None]] = {}
    work: list[tuple[str, FloatArray, _TimeSpans | None]] = []
    for name in names:
        original = record.channels[name].time
        known = times.get(id(original))
        if known is None:
            time = np.asarray(original, dtype=np.float64)
            # The original is kept so that its id is not reused while this call runs.
            known = (original, time, _time_spans(time, limits) if time.shape[0] >= 3 else None)
            times[id(original)] = known
        work.append((name, known[1], known[2]))

    # One choice for the whole record: the findings are the same on either path.
    compiled = kernel.kernel_for(
        sum(time.shape[0] for _, time, _ in work), ("quality_steps", "quality_runs")
    )

    def one(item: tuple[str, FloatArray, _TimeSpans | None]) -> list[Finding]:
        name, time, spans = item
        if spans is None:
            return []
        channel = record.channels[name]
        values = np.asarray(channel.values, dtype=np.float64)
        return _channel_findings(
            name, time, values, channel.finite, limits, channel.unit, spans, compiled
        )

    if threads > 1 and len(work) > 1:
        with ThreadPoolExecutor(max_workers=threads) as pool:
            per_channel = list(pool.map(one, work))
    else:
        per_channel = [one(item) for item in work]
    return [finding for found in per_channel for finding in found]


@dataclass(frozen=True)
class _TimeSpans:
    """What a time array alone shows: its gaps and clock resets, as step index ranges."""

    gaps: list[tuple[int, int]]
    resets: list[tuple[int, int]]


def _time_spans(time: FloatArray, limits: QualityLimits) -> _TimeSpans:
    steps = np.diff(time)
    return _TimeSpans(
        gaps=[(i, i + 1) for i in np.flatnonzero(steps > limits.max_gap_s).tolist()],
        resets=[(i, i + 1) for i in np.flatnonzero(steps <= 0).tolist()],
    )


def _channel_findings(
    name: str,
    time: FloatArray,
    values: FloatArray,
    clean: bool,
    limits: QualityLimits,
    unit: str | None,
    spans: _TimeSpans,
    compiled: ModuleType | None = None,
) -> list[Finding]:
    found: list[Finding] = []
    unit_text = f" {unit}" if unit else ""

    def add(kind: str, spans: list[tuple[int, int]], detail: str) -> None:
        for i, (a, b) in enumerate(spans):
            if i == MAX_LISTED:
                found.append(
                    Finding(
                        name,
                        kind,
                        float(time[a]),
                        float(time[spans[-1][1]]),
                        f"and {len(spans) - MAX_LISTED} more stretches like it",
                    )
                )
                return
            found.append(Finding(name, kind, float(time[a]), float(time[b]), detail))

    add("time gap", spans.gaps, f"no samples for more than {limits.max_gap_s:g} s")
    add("clock reset", spans.resets, "time stamps go back or repeat")

    if clean:
        finite = values
    else:
        bad = ~np.isfinite(values)
        nan_runs = [(a, b - 1) for a, b in _runs(bad)]
        if nan_runs:
            add("NaN run", nan_runs, f"{int(bad.sum())} values missing in the channel")
        finite = np.where(bad, np.nan, values)
        clean = not nan_runs

    scan = (
        _compiled_scan(compiled, finite, time, limits)
        if clean and compiled is not None
        else _numpy_scan(finite, clean, time, limits)
    )
    if scan.straight is not None:
        add(
            "straight-line fill",
            scan.straight,
            f"changes at a constant rate for over {limits.straight_run_s:g} s, as a logger "
            "filling a dropout writes",
        )
    if scan.flat is not None:
        add(
            "flat line",
            scan.flat,
            f"the same non-zero value for over {limits.flat_run_s:g} s: a stuck sensor?",
        )
    for extreme, where, episodes in scan.extremes:
        # A clipped sensor hits its limit again and again; a slow signal such as the state of
        # charge sits at its extreme once, at the start or the end.
        if len(episodes) >= SATURATION_EPISODES:
            add(
                "saturation",
                episodes,
                f"held at its {where} {extreme:g}{unit_text} for over "
                f"{limits.saturation_run_s:g} s, {len(episodes)} times",
            )
    rate = limits.rate_limits.get(name)
    if rate is not None:
        steps = np.diff(time)
        with np.errstate(invalid="ignore", divide="ignore"):
            too_fast = np.abs(np.diff(finite)) / np.where(steps > 0, steps, np.inf) > rate
        add(
            "spike",
            _runs(too_fast),
            f"changes faster than the declared {rate:g}{unit_text}/s",
        )
    return found


Runs = list[tuple[int, int]]


@dataclass(frozen=True)
class _Scan:
    """A channel's long runs, as sample index ranges [start, stop] inclusive."""

    #: Straight-line stretches; None where no step moves (there is no resolution).
    straight: Runs | None
    #: Flat lines; None where they were not looked for (every step moves).
    flat: Runs | None
    #: (value, "maximum" or "minimum", its runs) for each extreme looked at.
    extremes: list[tuple[float, str, Runs]]


def _numpy_scan(finite: FloatArray, clean: bool, time: FloatArray, limits: QualityLimits) -> _Scan:
    d1 = np.diff(finite)
    change = np.abs(d1)
    moving = change > 0
    every_step_moves = bool(moving.all())
    straight_runs = None
    if every_step_moves or moving.any():
        # the smallest step that moves
        resolution = float(
            np.min(change) if every_step_moves else np.min(change, where=moving, initial=np.inf)
        )
        # diff(finite, 2), without taking the first difference again
        d2 = np.subtract(d1[1:], d1[:-1])
        np.abs(d2, out=d2)
        straight = d2 <= 2.0 * resolution
        straight &= moving[1:]
        straight &= moving[:-1]
        del d2
        straight_runs = _long_runs(straight, time, limits.straight_run_s, widen=2)
    steady = clean and every_step_moves
    flat_runs = None
    if not steady:
        # Zero held for long is a vehicle at rest (a soak, a stop), not a stuck sensor.
        flat = (d1 == 0) & (finite[1:] != 0)
        flat_runs = _long_runs(flat, time, limits.flat_run_s, widen=1)
    extremes: list[tuple[float, str, Runs]] = []
    if _looks_for_saturation(steady, limits) and (clean or np.isfinite(finite).any()):
        top = float(np.max(finite) if clean else np.nanmax(finite))
        bottom = float(np.min(finite) if clean else np.nanmin(finite))
        for extreme, where in _saturation_extremes(top, bottom):
            episodes = _long_runs(finite == extreme, time, limits.saturation_run_s)
            extremes.append((extreme, where, episodes))
    return _Scan(straight_runs, flat_runs, extremes)


def _compiled_scan(
    compiled: ModuleType, finite: FloatArray, time: FloatArray, limits: QualityLimits
) -> _Scan:
    """:func:`_numpy_scan` of a channel without NaN or inf, in two compiled loops."""
    resolution, any_moves, every_moves, top, bottom = kernel.quality_steps(compiled, finite)
    steady = every_moves
    checks = 0
    if any_moves:
        checks |= 1 << kernel.STRAIGHT_RUN
    if not steady:
        checks |= 1 << kernel.FLAT_RUN
    extremes = _saturation_extremes(top, bottom) if _looks_for_saturation(steady, limits) else []
    for _, where in extremes:
        checks |= 1 << (kernel.TOP_RUN if where == "maximum" else kernel.BOTTOM_RUN)
    rows = kernel.quality_runs(
        compiled,
        finite,
        time,
        2.0 * resolution,
        (limits.straight_run_s, limits.flat_run_s, limits.saturation_run_s),
        (top, bottom),
        checks,
    )
    found: dict[int, Runs] = {kind: [] for kind in range(4)}
    for kind, start, final in rows.tolist():
        found[kind].append((start, final))
    return _Scan(
        found[kernel.STRAIGHT_RUN] if any_moves else None,
        None if steady else found[kernel.FLAT_RUN],
        [
            (extreme, where, found[kernel.TOP_RUN if where == "maximum" else kernel.BOTTOM_RUN])
            for extreme, where in extremes
        ],
    )


def _looks_for_saturation(steady: bool, limits: QualityLimits) -> bool:
    # Without NaN, a channel whose every step moves holds no value for two samples in a row:
    # it has no flat line and no run at an extreme longer than one sample, which lasts 0 s
    # (unless a run of one sample, 0 s long, is long enough).
    return not steady or limits.saturation_run_s <= 0.0


def _saturation_extremes(top: float, bottom: float) -> list[tuple[float, str]]:
    """The extremes a saturation is looked for at: none on a constant channel, and not zero,
    where resting is a standstill, not saturation."""
    if not top > bottom:
        return []
    return [
        (value, where) for value, where in ((top, "maximum"), (bottom, "minimum")) if value != 0.0
    ]


def mask_on_grid(findings: Iterable[Finding], grid: FloatArray) -> npt.NDArray[np.bool_]:
    """Grid points inside any finding's stretch (the stretches ``omit`` scores around)."""
    mask = np.zeros(grid.shape[0], dtype=bool)
    for finding in findings:
        mask |= (grid >= finding.start_s) & (grid <= finding.stop_s)
    return mask


def fail_on(findings: list[Finding], source: str) -> None:
    """The ``error`` action: the first finding as a DataError that blames the measurement."""
    if not findings:
        return
    first = findings[0]
    more = f" ({len(findings) - 1} more findings)" if len(findings) > 1 else ""
    raise DataError(
        f"the measurement is at fault, not the model: {first.kind} at "
        f"{first.start_s:.6g}–{first.stop_s:.6g} s ({first.detail}){more}",
        file=source,
        column=first.channel,
        hint="fix or cut the recording, or set data_quality.action: omit to score around it",
    )
