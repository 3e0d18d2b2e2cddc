"""Where and when the model is wrong: λ1–λ6 over time windows and over operating regions.

Pure numpy. The whole-record characteristics are ratios of a few sums (Σe, Σ|e|, Σe², Σref,
Σsim, Σref², Σsim², Σref·sim, the count of matching derivative signs); the same sums taken over
a group of samples — a time window, a segment where a condition holds, or the cell of an
operating-region grid — give that group's characteristics. So one pass over the record yields
every group at once, and a group that covers the whole record gives the global values exactly
(``tests/test_local.py`` checks both).

Conventions, chosen so that groups are comparable with each other and with the whole record:

* λ3–λ6 of every group are normalised by the **whole record's** reference range R. A window in
  which the reference barely moves would otherwise blow a tiny error up to a failing λ.
* λ1 is the zero-lag correlation of the group's samples in the spec's form (``xcorr`` or
  ``pearson``); the lag itself is a whole-record property and is not searched per group.
* λ2 uses the derivative signs of the whole record (central differences), counted per group.
* A group with fewer than :data:`MIN_GROUP_SAMPLES` samples gets NaN characteristics: too few
  samples to say anything.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
import numpy.typing as npt

from ..errors import DegenerateSignalError
from . import kernel
from .characteristics import power_of_two_scale
from .registry import FUSED_CHARACTERISTICS
from .sums import MIN_GROUP_SAMPLES, SUM_COLUMNS, Sums, lambdas_from_sums

__all__ = [
    "HOT_FACTOR",
    "LOCAL_CHARACTERISTICS",
    "MIN_GROUP_SAMPLES",
    "PHASES",
    "SUM_COLUMNS",
    "Concentration",
    "Grouping",
    "RegionGrid",
    "SumTable",
    "Sums",
    "concentration",
    "derivative_signs",
    "driving_phases",
    "fixed_windows",
    "group_lambdas",
    "grouped_tables",
    "labelled_table",
    "region_grid",
    "region_sums",
    "runs",
    "segment_sums",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

#: The characteristics that have a meaning over part of a record: λ1–λ6, in paper order.
LOCAL_CHARACTERISTICS: tuple[str, ...] = FUSED_CHARACTERISTICS
#: A window whose mean squared error exceeds this many times the record's is "hot": the
#: error concentrates there.
HOT_FACTOR = 2.0

CorrelationKind = Literal["xcorr", "pearson"]


def derivative_signs(y: FloatArray) -> npt.NDArray[np.int8]:
    """sign(y[i+1] − y[i−1]) per sample, 0 at both ends: the core's λ2 convention."""
    out = np.zeros(y.shape[0], dtype=np.int8)
    if y.shape[0] > 2:
        out[1:-1] = np.sign(y[2:] - y[:-2]).astype(np.int8)
    return out


def _check_pair(ref: FloatArray, sim: FloatArray) -> tuple[FloatArray, FloatArray]:
    r = np.asarray(ref, dtype=np.float64)
    s = np.asarray(sim, dtype=np.float64)
    if r.ndim != 1 or r.shape != s.shape:
        raise DegenerateSignalError(
            f"reference and simulated must be 1-D and of one length (got {r.shape}, {s.shape})"
        )
    return r, s


def segment_sums(
    ref: FloatArray, sim: FloatArray, starts: IntArray, stops: IntArray
) -> Sums[FloatArray]:
    """Sums over the contiguous sample ranges [starts[k], stops[k]) (non-empty, in order)."""
    r, s = _check_pair(ref, sim)
    starts = np.asarray(starts, dtype=np.int64)
    stops = np.asarray(stops, dtype=np.int64)
    labels = np.full(r.shape[0], -1, dtype=np.int64)
    for k, (a, b) in enumerate(zip(starts.tolist(), stops.tolist(), strict=True)):
        labels[a:b] = k
    return _group_sums(r, s, labels, starts.shape[0])


def _group_sums(r: FloatArray, s: FloatArray, labels: IntArray, groups: int) -> Sums[FloatArray]:
    """Sums per label in [0, groups); samples labelled −1 belong to no group."""
    keep = labels >= 0
    if not keep.all():
        signs_match = derivative_signs(r)[keep] == derivative_signs(s)[keep]
        r, s, labels = r[keep], s[keep], labels[keep]
    else:
        signs_match = derivative_signs(r) == derivative_signs(s)
    e = r - s

    def total(weights: FloatArray | None) -> FloatArray:
        return np.bincount(labels, weights=weights, minlength=groups).astype(np.float64)

    n = np.bincount(labels, minlength=groups).astype(np.int64)
    error_sum = total(e)
    # The spread about each group's first error: a bias much larger than the spread would
    # otherwise leave the mean's rounding (of the order of the bias's ulp) in every centred
    # value, and its square in Σ(e − ē)².
    present, first = np.unique(labels, return_index=True)
    shift = np.zeros(groups, dtype=np.float64)
    shift[present] = e[first]
    shifted = e - shift[labels]
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(n > 0, total(shifted) / np.maximum(n, 1), 0.0)
    centred = shifted - mean[labels]
    return Sums(
        n=n,
        error_sum=error_sum,
        abs_error=total(np.abs(e)),
        sq_error=total(e * e),
        error_m2=total(centred * centred),
        ref_sum=total(r),
        sim_sum=total(s),
        ref_sq=total(r * r),
        sim_sq=total(s * s),
        cross=total(r * s),
        sign_matches=np.bincount(labels, weights=signs_match, minlength=groups).astype(np.int64),
    )


def group_lambdas(
    sums: Sums[FloatArray],
    reference_range: float | FloatArray,
    correlation: CorrelationKind = "xcorr",
) -> dict[str, FloatArray]:
    """λ1–λ6 per group, keyed by characteristic name; NaN for groups too small to judge
    (fewer than :data:`MIN_GROUP_SAMPLES` samples). ``reference_range``: one for every group,
    or one per group."""
    return lambdas_from_sums(sums, reference_range, correlation).lambdas


# -- how a record is cut into groups -------------------------------------------------------


def fixed_windows(n: int, dt: float, window_s: float) -> tuple[IntArray, IntArray]:
    """Consecutive windows of ``window_s`` seconds; the last one holds what is left over."""
    if not (math.isfinite(window_s) and window_s > 0):
        raise DegenerateSignalError(f"window_s must be a positive number (got {window_s!r})")
    size = max(1, round(window_s / dt))
    starts = np.arange(0, n, size, dtype=np.int64)
    stops = np.minimum(starts + size, n)
    return starts, stops


def runs(mask: npt.NDArray[np.bool_], min_samples: int = 1) -> tuple[IntArray, IntArray]:
    """Start and stop indices of the runs of True in ``mask`` at least ``min_samples`` long."""
    m = np.asarray(mask, dtype=bool)
    if not m.any():  # one cheap pass where most masks (data-quality scans) find nothing
        empty = np.empty(0, dtype=np.int64)
        return empty, empty
    edges = np.diff(np.concatenate(([0], m.view(np.int8), [0])))
    starts = np.flatnonzero(edges == 1).astype(np.int64)
    stops = np.flatnonzero(edges == -1).astype(np.int64)
    long_enough = (stops - starts) >= min_samples
    return starts[long_enough], stops[long_enough]


#: Driving phases, in the order of :func:`driving_phases`' labels.
PHASES: tuple[str, ...] = ("stop", "accelerate", "cruise", "brake")
#: Below this speed the vehicle stands still.
STOP_BELOW_KMH = 2.0
#: Acceleration beyond ± this is accelerating or braking; between, cruising.
ACCELERATION_MS2 = 0.15
#: Speed is smoothed over this long before it is differentiated (logger noise).
PHASE_SMOOTHING_S = 1.0
#: A phase shorter than this is absorbed into the phase before it.
MIN_PHASE_S = 2.0


def driving_phases(speed_kmh: FloatArray, dt: float) -> npt.NDArray[np.int8]:
    """Label every sample stop (0), accelerate (1), cruise (2) or brake (3) from the speed."""
    v = np.asarray(speed_kmh, dtype=np.float64)
    width = max(1, round(PHASE_SMOOTHING_S / dt))
    kernel = np.ones(width) / width
    smooth = np.convolve(np.pad(v, width, mode="edge"), kernel, mode="same")[width:-width]
    acceleration = np.gradient(smooth / 3.6, dt) if v.shape[0] > 1 else np.zeros_like(v)
    labels = np.full(v.shape[0], 2, dtype=np.int8)
    labels[acceleration > ACCELERATION_MS2] = 1
    labels[acceleration < -ACCELERATION_MS2] = 3
    labels[smooth < STOP_BELOW_KMH] = 0
    # Absorb short phases into the one before, so a phase is a manoeuvre, not a wobble.
    shortest = max(1, round(MIN_PHASE_S / dt))
    change = np.flatnonzero(np.diff(labels)) + 1
    bounds = np.concatenate(([0], change, [labels.shape[0]]))
    for a, b in zip(bounds[:-1].tolist(), bounds[1:].tolist(), strict=True):
        if b - a < shortest and a > 0:
            labels[a:b] = labels[a - 1]
    return labels


# -- where the error concentrates ----------------------------------------------------------


@dataclass(frozen=True)
class Concentration:
    """How much of the squared error lies in how little of the time."""

    #: Share of Σe² in the hot windows, and share of the samples they hold.
    error_share: float
    time_share: float
    #: The hot windows merged into contiguous spans, in seconds, worst first.
    spans_s: tuple[tuple[float, float], ...]
    #: Number of hot windows.
    windows: int


def concentration(
    sums: Sums[FloatArray], starts: IntArray, stops: IntArray, dt: float, start_s: float = 0.0
) -> Concentration:
    """The windows whose mean squared error is over :data:`HOT_FACTOR` times the record's."""
    n = sums.n.astype(np.float64)
    total_sq = float(sums.sq_error.sum())
    total_n = float(n.sum())
    if total_sq <= 0.0 or total_n == 0.0:
        return Concentration(0.0, 0.0, (), 0)
    density = sums.sq_error / np.maximum(n, 1.0)
    hot = density > HOT_FACTOR * total_sq / total_n
    if not hot.any():
        return Concentration(0.0, 0.0, (), 0)
    spans: list[tuple[float, float, float]] = []
    for k in np.flatnonzero(hot).tolist():
        a = start_s + float(starts[k]) * dt
        b = start_s + float(stops[k]) * dt
        if spans and abs(spans[-1][1] - a) < 0.5 * dt:
            spans[-1] = (spans[-1][0], b, spans[-1][2] + float(sums.sq_error[k]))
        else:
            spans.append((a, b, float(sums.sq_error[k])))
    spans.sort(key=lambda span: -span[2])
    return Concentration(
        error_share=float(sums.sq_error[hot].sum()) / total_sq,
        time_share=float(n[hot].sum()) / total_n,
        spans_s=tuple((a, b) for a, b, _ in spans),
        windows=int(hot.sum()),
    )


# -- operating regions ---------------------------------------------------------------------


@dataclass(frozen=True)
class RegionGrid:
    """Samples binned by one or two operating variables."""

    edges: tuple[FloatArray, ...]
    #: Cell of every sample as a flat index into the grid, −1 outside it (or NaN).
    cell: IntArray
    #: Samples per cell, in the grid's shape.
    counts: IntArray

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(e.shape[0] - 1 for e in self.edges)

    def unvisited(self) -> list[tuple[int, ...]]:
        """Cells of the declared operating space that the measurement never visits."""
        return [tuple(int(i) for i in index) for index in np.argwhere(self.counts == 0)]


def region_grid(values: Sequence[FloatArray], edges: Sequence[FloatArray]) -> RegionGrid:
    """Bin every sample by one or two variables; bins are [edge_k, edge_k+1), the last closed."""
    if not 1 <= len(values) == len(edges) <= 2:
        raise DegenerateSignalError("regions are binned by one or two variables")
    cell: IntArray | None = None
    clean_edges = []
    for x, raw_edges in zip(values, edges, strict=True):
        e = np.asarray(raw_edges, dtype=np.float64)
        if e.ndim != 1 or e.shape[0] < 2 or not np.all(np.diff(e) > 0):
            raise DegenerateSignalError(
                f"bin edges must be at least two increasing numbers (got {raw_edges!r})"
            )
        clean_edges.append(e)
        v = np.asarray(x, dtype=np.float64)
        index = np.searchsorted(e, v, side="right") - 1
        index[v == e[-1]] = e.shape[0] - 2  # the last bin includes its upper edge
        outside = (index < 0) | (index >= e.shape[0] - 1) | ~np.isfinite(v)
        index = np.where(outside, -1, index).astype(np.int64)
        if cell is None:
            cell = index
        else:
            cell = np.where((cell < 0) | (index < 0), -1, cell * (e.shape[0] - 1) + index)
    assert cell is not None
    shape = tuple(e.shape[0] - 1 for e in clean_edges)
    counts = np.bincount(cell[cell >= 0], minlength=int(np.prod(shape))).reshape(shape)
    return RegionGrid(edges=tuple(clean_edges), cell=cell, counts=counts.astype(np.int64))


def region_sums(ref: FloatArray, sim: FloatArray, grid: RegionGrid) -> Sums[FloatArray]:
    """The sums of every cell of ``grid`` (flat, in the grid's C order)."""
    r, s = _check_pair(ref, sim)
    if grid.cell.shape[0] != r.shape[0]:
        raise DegenerateSignalError(
            f"the region grid has {grid.cell.shape[0]} samples, the signal {r.shape[0]}"
        )
    return _group_sums(r, s, grid.cell, int(np.prod(grid.shape)))


# -- every grouping in one pass ------------------------------------------------------------


#: The shift of the spread sums is the mean error of this many first samples.
SHIFT_SAMPLES = 1024


@dataclass(frozen=True)
class SumTable:
    """Additive sums per group: a union of groups is the sum of their rows. The stored form of
    many groups' :class:`~pytest_hevval.core.sums.Sums`, whose error sums are taken about
    ``shift`` so that they add up (:data:`~pytest_hevval.core.sums.SUM_COLUMNS`).

    The sums are of the samples times ``scale``, a power of two that keeps squares of very large
    or very small signals finite (1 for ordinary magnitudes). λ are ratios and do not change;
    an error in the signal's unit is a scaled error divided by ``scale``.
    """

    values: FloatArray  # (groups, len(SUM_COLUMNS))
    shift: float
    scale: float = 1.0

    def rows(self, selection: slice | npt.NDArray[np.intp]) -> SumTable:
        """The table of some of the groups only."""
        return SumTable(self.values[selection], self.shift, self.scale)

    def sums(self) -> Sums[FloatArray]:
        """The λ-ready sums of the rows (their scale stays with the table: see :class:`Sums`)."""
        return Sums.of_table(self.values, self.shift)


@dataclass(frozen=True)
class Grouping:
    """A record's samples sorted into groups once, for every signal scored over them.

    A sample's group is a mixed-radix number over ``shape``, one digit per way of grouping
    (window, phase, conditions, region cell; −1: no group). Only the groups that hold samples
    are kept, so a grouping with many axes costs what the record visits, not the product of
    their sizes. The samples come in runs of one group (a window, a stretch in one cell): the
    compiled pass sums each run as one contiguous stretch, inside the main pass of the core
    while the record is in cache (:func:`grouped_tables`).
    """

    shape: tuple[int, ...]
    #: The runs [starts[k], stops[k]) of one group each, in sample order; the samples between
    #: them belong to no group.
    starts: IntArray
    stops: IntArray
    #: Each run's group, in [0, groups).
    run_group: IntArray
    #: Each group's index along each axis: (groups, axes).
    digits: IntArray
    #: Every sample's group (−1: none), for the numpy path.
    group: IntArray
    #: The first row of each axis in :func:`grouped_tables`' stacked table.
    offsets: IntArray
    #: How many samples belong to a group.
    samples: int
    #: Where each group's sums go in each axis's rows of the stacked table, flat: (axis,
    #: group × column), the column index running fastest.
    placement: IntArray

    @classmethod
    def of(cls, labels: IntArray, shape: Sequence[int]) -> Grouping:
        """The grouping of ``labels`` (mixed-radix numbers over ``shape``, −1: no group)."""
        fine = np.asarray(labels, dtype=np.int64)
        sizes = tuple(int(size) for size in shape)
        n = fine.shape[0]
        if n and int(fine.max()) >= math.prod(sizes):
            raise ValueError(f"a label is beyond the grouping's {math.prod(sizes)} groups")
        change = np.empty(n, dtype=bool)
        change[:1] = True
        np.not_equal(fine[1:], fine[:-1], out=change[1:])
        every_start = np.flatnonzero(change)
        lengths = np.diff(np.append(every_start, n))
        every_label = fine[every_start]
        in_group = every_label >= 0
        present, run_group = np.unique(every_label[in_group], return_inverse=True)
        every_group = np.full(every_start.shape[0], -1, dtype=np.int64)
        every_group[in_group] = run_group
        starts = every_start[in_group]
        digits = np.stack(np.unravel_index(present, sizes), axis=1)
        offsets = np.concatenate(([0], np.cumsum(sizes[:-1]))).astype(np.int64)
        columns = len(SUM_COLUMNS)
        placement = (digits.T[:, :, None] * columns + np.arange(columns)).reshape(len(sizes), -1)
        return cls(
            shape=sizes,
            starts=starts.astype(np.int64),
            stops=(starts + lengths[in_group]).astype(np.int64),
            run_group=run_group.astype(np.int64).reshape(-1),
            digits=np.ascontiguousarray(digits, dtype=np.int64).reshape(-1, len(sizes)),
            group=np.repeat(every_group, lengths),
            offsets=offsets,
            samples=int(lengths[in_group].sum()),
            placement=placement.astype(np.int64),
        )

    @property
    def groups(self) -> int:
        return int(self.digits.shape[0])

    def rows(self, axis: int) -> slice:
        """Axis ``axis``'s rows in :func:`grouped_tables`' stacked table."""
        first = int(self.offsets[axis])
        return slice(first, first + self.shape[axis])

    def runs(self, ref: FloatArray, sim: FloatArray) -> kernel.GroupRuns:
        """The runs as the compiled passes take them, with the shift of ``ref`` − ``sim``."""
        return kernel.GroupRuns(
            starts=self.starts,
            stops=self.stops,
            run_group=self.run_group,
            groups=self.groups,
            shift=_shift(ref, sim),
        )

    def stacked(self, sums: FloatArray) -> FloatArray:
        """Every axis's rows from the groups' ``sums`` (groups, 10), each adding its groups in
        group order."""
        if len(self.shape) == 1 and self.groups == self.shape[0]:
            return sums  # every row visited, in order: nothing to add
        columns = len(SUM_COLUMNS)
        weights = np.ascontiguousarray(sums, dtype=np.float64).reshape(-1)
        # One count per axis over the groups in group order: every row adds its groups in
        # that order, whatever the path that summed them.
        return np.concatenate(
            [
                np.bincount(placement, weights=weights, minlength=size * columns)
                for placement, size in zip(self.placement, self.shape, strict=True)
            ]
        ).reshape(-1, columns)


def grouped_tables(
    ref: FloatArray,
    sim: FloatArray,
    grouping: Grouping,
    *,
    compiled: bool | None = None,
    summed: FloatArray | None = None,
) -> SumTable:
    """The additive sums of every index along every axis of ``grouping``.

    The rows of axis ``a`` are ``grouping.rows(a)`` of the stacked table. Each signal is read
    once and every grouping (windows, phases, conditions, cells) comes from the sums of the
    groups it visits. ``summed``: the groups' sums the compiled main pass took along with λ
    (``signal_characteristics(group_runs=grouping.runs(ref, sim))``), used unless the values
    need a power-of-two scale. ``compiled``: None lets
    :func:`pytest_hevval.core.kernel.kernel_for` choose (the compiled pass for long records or
    a warm cache, ``HEVVAL_KERNEL`` to force); True or False force a path. The compiled sums
    are reassociated, as the main pass's are, and agree with numpy's to rounding; the shift
    and the scale are the same on both paths.
    """
    r, s = _check_pair(ref, sim)
    if grouping.group.shape[0] != r.shape[0]:
        raise DegenerateSignalError(
            f"the grouping has {grouping.group.shape[0]} samples, the signal {r.shape[0]}"
        )
    module = None
    if summed is None:
        if compiled is None:
            module = kernel.kernel_for(r.shape[0], ("grouped_sums",))
        elif compiled:
            module = kernel.load_or_raise()
    if summed is not None or module is not None:
        shift = _shift(r, s)
        if summed is None:
            assert module is not None
            summed = kernel.grouped_sums(module, r, s, grouping.runs(r, s))
        # The sums of squares tell whether the peak can ask for a power-of-two scale; only
        # then (values beyond 2^±395, a NaN or inf, or samples in no group) is it found as
        # numpy finds it, and the sums taken again of the scaled values.
        power = float(summed[:, 6].sum() + summed[:, 7].sum())
        scale = 1.0
        if not kernel.squares_rule_out_scale(power, r.shape[0], grouping.samples):
            scale = _rescale(r, s)
        if scale != 1.0:
            module = module or kernel.load_or_raise()
            r, s = r * scale, s * scale
            shift = _shift(r, s)
            summed = kernel.grouped_sums(module, r, s, grouping.runs(r, s))
        return SumTable(grouping.stacked(summed), shift, scale)
    sums, shift, scale = _numpy_sums(r, s, grouping.group, grouping.groups)
    return SumTable(grouping.stacked(sums), shift, scale)


def labelled_table(
    ref: FloatArray,
    sim: FloatArray,
    labels: IntArray,
    groups: int,
    *,
    compiled: bool | None = None,
) -> SumTable:
    """The additive sums of every label in [0, ``groups``) (−1: no group), in one pass.

    One axis of :func:`grouped_tables`; the numpy path needs no grouping. ``compiled`` as
    there.
    """
    r, s = _check_pair(ref, sim)
    labels = np.asarray(labels, dtype=np.int64)
    if compiled is None and kernel.kernel_for(r.shape[0], ("grouped_sums",)) is None:
        compiled = False
    if compiled is False:
        return SumTable(*_numpy_sums(r, s, labels, groups))
    return grouped_tables(r, s, Grouping.of(labels, (groups,)), compiled=True)


def _numpy_sums(
    r: FloatArray, s: FloatArray, labels: IntArray, groups: int
) -> tuple[FloatArray, float, float]:
    """The (groups, 10) table of labels in [0, ``groups``) (−1: none), its shift and scale."""
    scale = _rescale(r, s)
    if scale != 1.0:
        r, s = r * scale, s * scale
    shift = _shift(r, s)
    signs_match = (derivative_signs(r) == derivative_signs(s)).view(np.int8)
    if (labels < 0).any():  # samples in no group, as the compiled pass skips them
        keep = labels >= 0
        r, s, labels, signs_match = r[keep], s[keep], labels[keep], signs_match[keep]
    e = r - s
    d = e - shift

    def total(weights: npt.NDArray[np.generic] | None) -> FloatArray:
        return np.asarray(np.bincount(labels, weights=weights, minlength=groups), dtype=np.float64)

    columns = (
        total(None),
        total(d),
        total(d * d),
        total(np.abs(e)),
        total(r),
        total(s),
        total(r * r),
        total(s * s),
        total(r * s),
        total(signs_match),
    )
    return np.column_stack(columns), shift, scale


def _shift(r: FloatArray, s: FloatArray) -> float:
    """The shift of the error sums: any value near the mean error keeps the shifted sums exact
    enough, and the first samples' mean costs nothing and is the same on both paths."""
    if not r.shape[0]:
        return 0.0
    head = np.subtract(r[:SHIFT_SAMPLES], s[:SHIFT_SAMPLES], dtype=np.float64)
    return float(np.mean(head))


def _rescale(ref: FloatArray, sim: FloatArray) -> float:
    """The power of two that keeps the squares of ``ref`` and ``sim`` finite (1 when they are)."""
    if ref.shape[0] == 0:
        return 1.0
    with np.errstate(invalid="ignore"):
        extremes = (ref.max(), ref.min(), sim.max(), sim.min())
    # NaN where a signal holds a NaN: no scale then.
    peak = max(abs(float(a)) for a in extremes)
    return power_of_two_scale(peak) if math.isfinite(peak) else 1.0
