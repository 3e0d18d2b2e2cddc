"""One common time grid for the reference and the model output.

The grid runs at ``rate_hz`` (default: the reference's own nominal rate, see
:func:`nominal_rate`) over the overlap of both records, or over a declared window. A channel
sampled on the grid is used as it is; any other is interpolated onto it with a named method:
``linear`` for continuous signals, ``previous`` (zero-order hold) for discrete or slowly logged
ones, which is how slow CAN signals are upsampled. A time offset between the two
records is either declared or found by cross-correlating one channel on both sides.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from ..core import kernel
from ..core.lag import search_lag
from ..errors import DataError
from .record import Channel, Record

__all__ = [
    "AlignedData",
    "Grid",
    "Interpolation",
    "align_records",
    "find_offset",
    "median_step",
    "nominal_rate",
]

FloatArray = npt.NDArray[np.float64]
Method = Literal["linear", "previous"]


@dataclass(frozen=True)
class Grid:
    start_s: float
    rate_hz: float
    n_samples: int

    @property
    def dt(self) -> float:
        return 1.0 / self.rate_hz

    @property
    def stop_s(self) -> float:
        return self.start_s + (self.n_samples - 1) / self.rate_hz

    def times(self) -> FloatArray:
        return self.start_s + np.arange(self.n_samples, dtype=np.float64) / self.rate_hz


@dataclass
class AlignedData:
    """Both records on one grid; channels are interpolated on first use and kept."""

    grid: Grid
    reference: Record
    model: Record
    offset_s: float
    offset_found: bool
    nan_policy: Literal["raise", "omit"] = "raise"
    #: "clock" when the records were lined up by their absolute start times.
    by: Literal["time", "clock"] = "time"
    #: The model's absolute start minus the reference's (by clock only).
    clock_offset_s: float = 0.0
    _cache: dict[tuple[str, str, Method], FloatArray] = field(default_factory=dict)
    _times: FloatArray | None = None
    _on_grid: dict[tuple[int, float], bool] = field(default_factory=dict)
    _plans: dict[tuple[int, float, Method], _Plan] = field(default_factory=dict)
    #: The columns declared per side (align_records' arguments): those that share a time base
    #: with a column being interpolated are interpolated with it, in one pass.
    declared: dict[str, tuple[str, ...]] = field(default_factory=dict)
    #: Columns interpolated beside another one, until they are asked for.
    _prepared: dict[tuple[str, str, Method], FloatArray] = field(default_factory=dict)
    #: Columns handed out by ``deferred_column``: not interpolated beside another one.
    _deferred: set[tuple[str, str, Method]] = field(default_factory=set)
    #: Columns interpolated so far (those on the grid are used as they are).
    interpolated: list[tuple[str, str]] = field(default_factory=list)
    #: Grid points that fall in a gap of any channel used so far (policy ``omit``).
    gap_mask: npt.NDArray[np.bool_] | None = None
    #: Data-quality findings on the reference channels (:mod:`pytest_hevval.data.quality`).
    quality: list[Any] = field(default_factory=list)

    @property
    def time(self) -> FloatArray:
        if self._times is None:
            self._times = self.grid.times()
        return self._times

    def _sampled_on_grid(self, time: FloatArray, shift: float) -> bool:
        # Keyed by the array's identity: table formats share one time array among channels.
        key = (id(time), shift)
        if key not in self._on_grid:
            self._on_grid[key] = on_grid(time, shift, self.time, self.grid.dt)
        return self._on_grid[key]

    def column(self, side: Literal["reference", "model"], name: str, method: Method) -> FloatArray:
        key = (side, name, method)
        cached = self._cache.get(key)
        if cached is not None:
            return cached
        record = self.reference if side == "reference" else self.model
        channel = record.channel(name)
        shift = self.offset_s if side == "model" else 0.0
        on_grid_channel = self._sampled_on_grid(channel.time, shift)
        plan = None
        if not on_grid_channel:
            self.interpolated.append((side, name))
            prepared = self._prepared.pop(key, None)
            if prepared is not None:
                self._cache[key] = prepared
                return prepared
            plan = self._plan(channel.time, shift, method)
            values = np.asarray(channel.values, dtype=np.float64)
            if channel.finite:
                # The other declared columns of this time base go through the plan in the same
                # pass: one hand-over to the kernel's threads instead of one per column.
                others = self._same_time_base(side, record, channel.time, name, method)
                outputs = plan.apply_all([values, *others.values()])
                for other, out in zip(others, outputs[1:], strict=True):
                    self._prepared[(side, other, method)] = out
                self._cache[key] = outputs[0]
                return outputs[0]
        values, gaps = _interpolate(
            channel,
            self.time,
            shift,
            method,
            record.source,
            name,
            self.nan_policy,
            on_grid=on_grid_channel,
            plan=plan,
        )
        if gaps is not None:
            self.gap_mask = gaps if self.gap_mask is None else (self.gap_mask | gaps)
        self._cache[key] = values
        return values

    def _plan(self, time: FloatArray, shift: float, method: Method) -> _Plan:
        key = (id(time), shift, method)
        plan = self._plans.get(key)
        if plan is None:
            # Channels that share a time array share one plan: the search is done once.
            plan = self._plans[key] = _Plan.build(time, shift, self.time, method)
        return plan

    def deferred_column(
        self, side: Literal["reference", "model"], name: str, method: Method
    ) -> Interpolation | None:
        """A column to be interpolated where it is used, into a buffer the user keeps
        (:meth:`Interpolation.into`), so that no full-length copy of it need exist beside the
        others; None for a column that is on the grid, holds NaN or inf (its gaps must be known
        first), or is interpolated already."""
        key = (side, name, method)
        if key in self._cache or key in self._prepared:
            return None
        record = self.reference if side == "reference" else self.model
        channel = record.channel(name)
        shift = self.offset_s if side == "model" else 0.0
        if self._sampled_on_grid(channel.time, shift) or not channel.finite:
            return None
        if key not in self._deferred:
            self._deferred.add(key)
            self.interpolated.append((side, name))
        return Interpolation(
            self._plan(channel.time, shift, method), np.asarray(channel.values, dtype=np.float64)
        )

    def _same_time_base(
        self, side: str, record: Record, time: FloatArray, name: str, method: Method
    ) -> dict[str, FloatArray]:
        """The finite values of the declared columns of ``side`` that share ``time`` with
        ``name`` and are not yet interpolated by ``method``."""
        others: dict[str, FloatArray] = {}
        for other in self.declared.get(side, ()):
            key = (side, other, method)
            if other == name or key in self._cache or key in self._prepared:
                continue
            if key in self._deferred:
                continue
            channel = record.channel(other)
            if channel.time is not time:
                continue
            # A column with NaN or inf goes its own way when it is asked for (gaps, errors).
            if channel.finite:
                others[other] = np.asarray(channel.values, dtype=np.float64)
        return others

    def columns(
        self, side: Literal["reference", "model"], names: Iterable[str], method: Method
    ) -> dict[str, FloatArray]:
        return {name: self.column(side, name, method) for name in names}

    def absolute_start(self) -> str | None:
        """The grid's first point as clock time (ISO 8601, UTC), when the reference has one."""
        epoch = self.reference.meta.get("start_epoch_s")
        if epoch is None:
            return None
        from datetime import datetime, timezone

        start = datetime.fromtimestamp(float(epoch) + self.grid.start_s, tz=timezone.utc)
        return start.isoformat()

    @property
    def coverage(self) -> float:
        if self.gap_mask is None or self.grid.n_samples == 0:
            return 1.0
        return float(1.0 - self.gap_mask.mean())


#: A channel whose samples lie within this fraction of a step of the grid points is used as
#: it is: interpolating it would change no value by more than this fraction of one step's
#: change, and would copy it.
ON_GRID_TOLERANCE = 1e-6


def on_grid(time: FloatArray, shift: float, grid_times: FloatArray, dt: float) -> bool:
    """True when ``time + shift`` are ``grid_times``, to within ON_GRID_TOLERANCE steps."""
    if time.shape != grid_times.shape:
        return False
    deviation = np.abs(time + shift - grid_times) if shift else np.abs(time - grid_times)
    return bool(deviation.max() <= ON_GRID_TOLERANCE * dt)


def median_step(time: FloatArray) -> float:
    if time.shape[0] < 2:
        return math.nan
    return float(np.median(np.diff(time)))


#: A rate (or step) that equals a number of at most this many significant digits to within
#: NOMINAL_TOLERANCE is taken to be that number: decimal time stamps (0.1, 0.2, …) give a
#: median step a few ulps off 0.1, and the grid must run at 10 Hz, not 9.999999999997726.
NOMINAL_DIGITS = 6
#: Relative difference below which a measured rate is its nominal value. Rounding of decimal
#: time stamps is ~1e-13 relative; a real clock differs from its nominal rate by ~1e-5 or
#: more only over days.
NOMINAL_TOLERANCE = 1e-9


def _nice(value: float) -> tuple[int, float] | None:
    """(significant digits, value) of the shortest decimal within tolerance of ``value``."""
    for digits in range(1, NOMINAL_DIGITS + 1):
        candidate = float(f"{value:.{digits}g}")
        if abs(candidate - value) <= NOMINAL_TOLERANCE * abs(value):
            return digits, candidate
    return None


def nominal_rate(step: float) -> float:
    """The sample rate a user would write for a median step of ``step`` seconds.

    Whichever of the rate (10 Hz) or the step (3 s, i.e. 1/3 Hz) is the shorter decimal wins;
    a step that is neither stays as measured.
    """
    rate = _nice(1.0 / step)
    period = _nice(step)
    if rate is not None and (period is None or rate[0] <= period[0]):
        return rate[1]
    if period is not None:
        return 1.0 / period[1]
    return 1.0 / step


def _span(records: Iterable[tuple[Record, Iterable[str], float]]) -> tuple[float, float]:
    start = -math.inf
    stop = math.inf
    for record, names, shift in records:
        for name in names:
            channel = record.channel(name)
            if channel.time.shape[0] == 0:
                raise DataError("the column has no samples", file=record.source, column=name)
            start = max(start, float(channel.time[0]) + shift)
            stop = min(stop, float(channel.time[-1]) + shift)
    return start, stop


#: The most points a grid may hold (8 bytes each, per column): 24 h at 5 kHz.
MAX_GRID_SAMPLES = 432_000_000


def _check_grid_size(n: int, start: float, stop: float, rate_hz: float) -> None:
    """Refuse a grid before it is allocated: its size is the work every signal does."""
    if n > MAX_GRID_SAMPLES:
        raise DataError(
            f"the grid would hold {n:.3g} points ({stop - start:g} s at {rate_hz:g} Hz), over "
            f"the limit of {MAX_GRID_SAMPLES:.3g}",
            key="alignment.rate_hz",
            hint="lower alignment.rate_hz, or score a shorter alignment.window",
        )


def find_offset(
    reference: Channel,
    model: Channel,
    *,
    rate_hz: float,
    max_offset_s: float,
) -> float:
    """Time shift to add to the model's time so that ``model`` lines up with ``reference``.

    Both channels are put on one grid at ``rate_hz`` over their common span and the peak of
    the mean-removed cross-correlation within ±max_offset_s gives the shift.
    """
    start = max(float(reference.time[0]), float(model.time[0]) - max_offset_s)
    stop = min(float(reference.time[-1]), float(model.time[-1]) + max_offset_s)
    n = math.floor((stop - start) * rate_hz + 1e-9) + 1
    _check_grid_size(n, start, stop, rate_hz)
    if n < 16:
        raise DataError("the records overlap too little to find a time offset")
    grid = start + np.arange(n) / rate_hz
    ref = np.interp(grid, reference.time, np.asarray(reference.values, dtype=np.float64))
    sim = np.interp(grid, model.time, np.asarray(model.values, dtype=np.float64))
    max_lag = min(round(max_offset_s * rate_hz), n - 1)
    lag = search_lag(ref, sim, max_lag).lag
    return lag / rate_hz


def align_records(
    reference: Record,
    model: Record,
    *,
    reference_columns: Iterable[str],
    model_columns: Iterable[str],
    rate_hz: float | None = None,
    window: tuple[float, float] | None = None,
    offset_s: float = 0.0,
    offset_from: tuple[str, str] | None = None,
    max_offset_s: float = 30.0,
    nan_policy: Literal["raise", "omit"] = "raise",
    by: Literal["time", "clock"] = "time",
) -> AlignedData:
    """Build the common grid for the channels a spec uses.

    With ``by="clock"`` both records carry an absolute start (``meta["start_epoch_s"]``, set
    by readers of clock-time columns) and the model's time is shifted by the difference of
    the two starts before any declared or found offset.
    """
    ref_names = list(dict.fromkeys(reference_columns))
    model_names = list(dict.fromkeys(model_columns))
    for name in ref_names:
        reference.channel(name)
    for name in model_names:
        model.channel(name)

    if rate_hz is None:
        channels = [reference.channel(n) for n in ref_names] or list(reference.channels.values())
        # Table formats share one time array among channels: one median per time base.
        bases = {id(c.time): c.time for c in channels}
        steps = [median_step(time) for time in bases.values()]
        finite = [s for s in steps if math.isfinite(s) and s > 0]
        if not finite:
            raise DataError(
                "cannot infer the sample rate (fewer than 2 samples)",
                file=reference.source,
                hint="declare alignment.rate_hz",
            )
        rate_hz = nominal_rate(min(finite))

    clock_offset = 0.0
    if by == "clock":
        clock_offset = _clock_offset(reference, model)
        offset_s = offset_s + clock_offset
    found = False
    if offset_from is not None:
        ref_channel = reference.channel(offset_from[0])
        model_channel = model.channel(offset_from[1])
        offset_s = offset_s + find_offset(
            ref_channel,
            Channel(model_channel.time + offset_s, model_channel.values),
            rate_hz=rate_hz,
            max_offset_s=max_offset_s,
        )
        found = True

    start, stop = _span([(reference, ref_names, 0.0), (model, model_names, offset_s)])
    if window is not None:
        if window[0] < start - 1e-9 or window[1] > stop + 1e-9:
            raise DataError(
                f"the window [{window[0]:g}, {window[1]:g}] s is not covered by both records "
                f"(their overlap is [{start:g}, {stop:g}] s)",
                file=reference.source,
                hint="shrink alignment.window to the overlap",
            )
        start, stop = window
    if not stop > start:
        raise DataError(
            f"the reference and the model output do not overlap in time "
            f"(reference {_range(reference, ref_names)}, "
            f"model {_range(model, model_names, offset_s)})",
            file=model.source,
            hint="check both time columns, their units (time_scale) and alignment.offset_s",
        )
    # A stop that lies on a grid point to within the on-grid tolerance is the last point: the
    # record's last sample is kept, not lost to rounding.
    n = math.floor((stop - start) * rate_hz + ON_GRID_TOLERANCE) + 1
    _check_grid_size(n, start, stop, rate_hz)
    if n < 3:
        raise DataError(
            f"the overlap [{start:g}, {stop:g}] s holds fewer than 3 samples at {rate_hz:g} Hz",
            file=reference.source,
            hint="raise alignment.rate_hz or widen the window",
        )
    return AlignedData(
        declared={"reference": tuple(ref_names), "model": tuple(model_names)},
        grid=Grid(start_s=float(start), rate_hz=float(rate_hz), n_samples=n),
        reference=reference,
        model=model,
        offset_s=float(offset_s),
        offset_found=found,
        nan_policy=nan_policy,
        by=by,
        clock_offset_s=clock_offset,
    )


def _clock_offset(reference: Record, model: Record) -> float:
    """Seconds to add to the model's time so both count from the reference's start."""
    starts = []
    for record in (reference, model):
        start = record.meta.get("start_epoch_s")
        if start is None:
            raise DataError(
                "alignment.by is clock, but this record has no absolute time",
                file=record.source,
                hint="give it a clock-time column (ISO 8601 text, a datetime, or Unix epoch "
                "time) or drop `by: clock`",
            )
        starts.append(float(start))
    return starts[1] - starts[0]


def _range(record: Record, names: list[str], shift: float = 0.0) -> str:
    if not names:
        return "no columns"
    channel = record.channel(names[0])
    return f"{float(channel.time[0]) + shift:g}–{float(channel.time[-1]) + shift:g} s"


def _interpolate(
    channel: Channel,
    grid: FloatArray,
    shift: float,
    method: Method,
    source: str,
    name: str,
    nan_policy: Literal["raise", "omit"],
    *,
    on_grid: bool = False,
    plan: _Plan | None = None,
) -> tuple[FloatArray, npt.NDArray[np.bool_] | None]:
    values = np.asarray(channel.values, dtype=np.float64)
    finite = channel.finite
    if finite and on_grid:
        # Already sampled on the grid: the channel's own values, not a copy of them.
        return values, None
    if finite and plan is not None:
        return plan.apply(values), None
    time = channel.time + shift if shift else channel.time
    gaps = None
    if not finite:
        bad = ~np.isfinite(values)
        first = int(np.flatnonzero(bad)[0])
        if nan_policy == "raise":
            raise DataError(
                f"{int(bad.sum())} NaN or inf values (first at t = {float(time[first]):g} s)",
                file=source,
                column=name,
                hint="set alignment.nan: omit to score only where data exists",
            )
        keep = ~bad
        if not keep.any():
            raise DataError("every value is NaN or inf", file=source, column=name)
        # A grid point is in a gap when it lies between a bad sample's neighbours.
        gap_start = np.r_[-np.inf, time][:-1][bad]
        gap_stop = np.r_[time, np.inf][1:][bad]
        idx = np.searchsorted(gap_start, grid, side="left") - 1
        inside = idx >= 0
        gaps = np.zeros(grid.shape[0], dtype=bool)
        gaps[inside] = grid[inside] < gap_stop[idx[inside]]
        time = time[keep]
        values = values[keep]
    if method == "previous":
        index = np.searchsorted(time, grid, side="right") - 1
        np.clip(index, 0, time.shape[0] - 1, out=index)
        return values[index], gaps
    return np.interp(grid, time, values), gaps


@dataclass(frozen=True)
class _Plan:
    """Where each grid point falls in one time base, computed once for all its channels.

    ``apply`` gives what ``np.interp`` (linear) or a zero-order hold (previous) would: the
    search over the time stamps, the costly part, is not repeated per channel, and nor are
    the indices of the right-hand neighbours.
    """

    method: Method
    #: Index of the sample at or before each grid point (clipped to the record).
    index: npt.NDArray[np.intp]
    #: Linear only: index of the sample after it, grid point minus that sample's time, and
    #: the step to the next sample. A grid point that takes its left sample as it is (on a
    #: sample, or beyond either end of the record, as np.interp holds the end value) has its
    #: left sample as right neighbour, offset −0.0 and step 1: (left − left) / 1 · −0.0 + left
    #: is left to the bit for any finite value, −0.0 included, so no point needs a branch or
    #: a mask.
    right: npt.NDArray[np.intp] | None = None
    offset: FloatArray | None = None
    step: FloatArray | None = None

    @classmethod
    def build(cls, time: FloatArray, shift: float, grid: FloatArray, method: Method) -> _Plan:
        t = time + shift if shift else time
        last = t.shape[0] - 1
        index = np.searchsorted(t, grid, side="right") - 1
        if method == "previous" or last < 1:
            return cls("previous", np.clip(index, 0, last))
        below = index < 0
        above = index >= last
        index = np.clip(index, 0, last - 1)
        offset = grid - t[index]
        step = t[index + 1] - t[index]
        exact = below | above | (offset == 0.0)
        index = np.where(above, last, index)
        right = index + ~exact
        return cls(
            "linear",
            index,
            right,
            np.where(exact, -0.0, offset),
            np.where(exact, 1.0, step),
        )

    def apply(self, values: FloatArray) -> FloatArray:
        return self.apply_all([values])[0]

    def apply_into(self, values: FloatArray, out: FloatArray) -> FloatArray:
        """One column (finite values of this time base) through the plan into ``out``, on the
        calling thread: the same values as :meth:`apply`."""
        if self.method == "previous":
            return np.take(values, self.index, out=out)
        assert self.offset is not None
        assert self.step is not None
        compiled = self._compiled([values])
        if compiled is not None:
            return kernel.interpolate_into(
                compiled, values, self.index, self.offset, self.step, out
            )
        return self._numpy(values, out)

    def apply_all(self, columns: list[FloatArray]) -> list[FloatArray]:
        """Every column (finite values of this time base) through the plan, in one go."""
        if self.method == "previous":
            return [np.take(values, self.index) for values in columns]
        assert self.right is not None
        assert self.offset is not None
        assert self.step is not None
        compiled = self._compiled(columns)
        if compiled is not None:
            return kernel.interpolate_columns(compiled, columns, self.index, self.offset, self.step)
        return [self._numpy(values) for values in columns]

    def _compiled(self, columns: list[FloatArray]) -> Any:
        """The kernel's module, when it runs this plan on these columns; else None."""
        if not kernel.accepts(*columns):
            return None
        return kernel.kernel_for(self.index.shape[0], ("interpolate",))

    def _numpy(self, values: FloatArray, out: FloatArray | None = None) -> FloatArray:
        """np.interp's arithmetic, (right − left) / step · offset + left, a block at a time:
        two gathers and four in-place passes over buffers that stay in cache, each result
        written once into the column."""
        assert self.right is not None
        assert self.offset is not None
        assert self.step is not None
        n = self.index.shape[0]
        if out is None:
            out = np.empty(n, dtype=np.float64)
        width = min(n, _NUMPY_BLOCK)
        left = np.empty(width, dtype=np.float64)
        part = np.empty(width, dtype=np.float64)
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            for a in range(0, n, width):
                b = min(a + width, n)
                m = b - a
                # mode="clip" (indices are in range) writes into out= without a buffer.
                np.take(values, self.index[a:b], out=left[:m], mode="clip")
                np.take(values, self.right[a:b], out=part[:m], mode="clip")
                np.subtract(part[:m], left[:m], out=part[:m])
                np.divide(part[:m], self.step[a:b], out=part[:m])
                np.multiply(part[:m], self.offset[a:b], out=part[:m])
                np.add(part[:m], left[:m], out=out[a:b])
        return out


@dataclass(frozen=True)
class Interpolation:
    """A column's values and the plan that puts them on the grid, applied where it is used."""

    plan: _Plan
    values: FloatArray

    def into(self, out: FloatArray | None = None) -> FloatArray:
        """The column on the grid, written into ``out`` (grid-long) or a new array."""
        if out is None:
            out = np.empty(self.plan.index.shape[0], dtype=np.float64)
        return self.plan.apply_into(self.values, out)


#: Grid points per block of the numpy interpolation: its two scratch buffers stay in a 1 MiB
#: L2 cache beside the plan's slices.
_NUMPY_BLOCK = 1 << 14
