"""How sure is a characteristic? Block-bootstrap intervals from per-block sums.

At 100 Hz neighbouring samples of a residual are strongly correlated, so a record holds far
fewer independent samples than rows, and an interval that treats samples as independent is far
too narrow. A block bootstrap keeps that dependence: the record is cut into non-overlapping
blocks of ``b`` samples, a replicate record is made of blocks drawn with replacement, and its
characteristics are computed again. Because λ1–λ6 are ratios of sums (see
:mod:`pytest_hevval.core.groups`), a replicate needs only the blocks' sums, not the samples:
each signal is read once more, into at most :data:`FINE_BLOCKS` rows of sums, and every
replicate is then a weighted sum of those rows.

Choices, each documented in ``docs/uncertainty.md``:

* **Block length** from the residual's lag-1 autocorrelation ρ, the plug-in rule for the block
  bootstrap of a mean under an AR(1) model (Politis & White 2004, with the correction of
  Patton, Politis & White 2009): b = (√6·ρ / (1 − ρ²))^(2/3) · n^(1/3), at least
  n / :data:`MAX_BLOCKS` and at most n / :data:`MIN_BLOCKS`; rounded up to whole fine blocks of
  ⌈n / FINE_BLOCKS⌉ samples.
* **Non-overlapping blocks** (Carlstein 1986), so replicates are sums of stored block sums.
* **Normal intervals with the bootstrap's standard error**: value ± z·s, s the standard
  deviation of :data:`REPLICATES` replicates drawn with a fixed seed (one record always gives
  one interval, so CI runs are reproducible), cut to the span of the replicates so it keeps a
  characteristic's bounds. Their end points are as steady with 250 replicates as percentile end
  points with 1,000 (a standard deviation settles far faster than a 2.5 % quantile), and a
  quarter of the replicates is what makes the intervals cheap next to the scoring.
* **The normalising range R is held fixed**: it is the reference's range, a property of the
  measurement the characteristics are scaled by, not an estimate.
* **What is not bootstrapped:** the lag (a search over shifts, not a ratio of sums) keeps its
  point value, and so do registered characteristics that are not ratios of these sums.
"""

from __future__ import annotations

import functools
import math
import threading
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property, lru_cache
from statistics import NormalDist
from types import ModuleType

import numpy as np
import numpy.typing as npt

from ..errors import DegenerateSignalError
from . import kernel
from .characteristics import power_of_two_scale
from .groups import SHIFT_SAMPLES, SUM_COLUMNS, SumTable, labelled_table
from .sums import Sums, lambdas_from_sums

__all__ = [
    "CONFIDENCE",
    "FINE_BLOCKS",
    "MAX_BLOCKS",
    "MIN_BLOCKS",
    "NORMAL_QUANTILE",
    "REPLICATES",
    "SHARED_BLOCK_FACTOR",
    "BlockSums",
    "Interval",
    "block_length",
    "block_sums",
    "block_sums_many",
    "block_sums_stacked",
    "coarsen",
    "fine_block_size",
    "fine_labels",
    "lag1_autocorrelation",
    "lag1_autocorrelations",
    "replicate_lambdas",
    "replicate_sums",
    "replicate_table",
    "resample_counts",
    "signal_intervals",
    "stacked_intervals",
    "stacked_replicates",
    "standard_interval",
    "sums_lambdas",
    "value_text",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

#: Nominal coverage of every interval.
CONFIDENCE = 0.95
#: The normal quantile of :data:`CONFIDENCE`, two-sided (1.96).
NORMAL_QUANTILE = NormalDist().inv_cdf(0.5 + CONFIDENCE / 2.0)
#: Bootstrap replicates. The end points z·s move by about 1.96 / √(2·(R − 1)) ≈ 9 % of the
#: standard error from one seed to another, as the 2.5 % and 97.5 % percentiles of 1,000
#: replicates do; the simulation in ``docs/uncertainty.md`` finds the same coverage for both.
REPLICATES = 250
#: A record is cut into at least this many blocks; fewer cannot show its variability.
MIN_BLOCKS = 10
#: ... and into at most this many. Blocks longer than the rule asks keep the bootstrap valid
#: (they only keep more of the dependence); beyond about a hundred blocks the interval gains
#: little, while every replicate costs one multiply-add per block and sum.
MAX_BLOCKS = 128
#: At most this many rows of sums are kept per signal; a bootstrap block is a run of them.
#: Eight times :data:`MAX_BLOCKS`: rounding a block up to whole rows lengthens the shortest
#: block by less than an eighth, and fewer rows make the pass and every coarsening cheaper.
FINE_BLOCKS = 1024
#: A signal's λ1–λ6 are resampled with the spec's common blocks (the longest any of its signals
#: needs, which λ7 and Φ use) when those are at most this many times as long as its own rule
#: asks. The rule's length is an estimate whose error is of that order, and a longer block only
#: keeps more of the dependence; resampling once instead of twice halves the work per signal.
SHARED_BLOCK_FACTOR = 2
#: The seed of the draws: one record, one interval.
SEED = 20_140_601
#: Multiply-adds per matrix product at most. OpenBLAS runs a dgemm on its own threads above
#: 65,536 × 4 of them (measured here: from about 600,000); those threads spin while they wait,
#: and next to the engine's two threads on two cores one replicate product of a signal
#: (then 1,000 × 125 × 10) cost many times its single-thread CPU time. Larger products are cut into
#: pieces of at most this size, batched into one ``matmul`` call.
GEMM_LIMIT = 1 << 18
#: The fine-block pass of records up to this many samples runs on all signals of a record at
#: once (one set of array operations on a stack of signals, in chunks of about
#: :data:`STACK_ELEMENTS` samples); a longer record is read signal by signal.
STACK_SAMPLES = 1 << 16
STACK_ELEMENTS = 1 << 16


@dataclass(frozen=True)
class Interval:
    """A point value with its confidence interval."""

    value: float
    low: float
    high: float

    def __str__(self) -> str:
        return value_text(self.value, self)

    @property
    def bounds(self) -> str:
        """``[low, high]`` as printed beside a value."""
        return f"[{self.low:.4f}, {self.high:.4f}]"

    def to_dict(self) -> dict[str, float]:
        return {"value": self.value, "low": self.low, "high": self.high}

    @classmethod
    def from_dict(cls, data: dict[str, float]) -> Interval:
        return cls(float(data["value"]), float(data["low"]), float(data["high"]))


def value_text(value: float, interval: Interval | None) -> str:
    """``0.9257 [0.9190, 0.9311]``, or the bare value where no interval is known."""
    return f"{value:.4f}" if interval is None else f"{value:.4f} {interval.bounds}"


def lag1_autocorrelation(x: FloatArray) -> float:
    """Lag-1 autocorrelation of ``x`` (0 for a constant or too short series)."""
    values = np.asarray(x, dtype=np.float64)
    return float(lag1_autocorrelations(values.reshape(1, -1))[0])


def lag1_autocorrelations(rows: FloatArray, scratch: FloatArray | None = None) -> FloatArray:
    """:func:`lag1_autocorrelation` of every row of a (series, samples) array; ``scratch``
    (its shape) holds the centred values if given."""
    values = np.asarray(rows, dtype=np.float64)
    k, n = values.shape
    if n < 3:
        return np.zeros(k)
    centred = np.subtract(values, values.mean(axis=1, keepdims=True), out=scratch)
    power = np.einsum("ij,ij->i", centred, centred)
    lagged = np.einsum("ij,ij->i", centred[:, 1:], centred[:, :-1])
    # A constant series is caught before dividing: its mean's rounding leaves a constant
    # non-zero remainder, whose ρ would be near 1.
    varies = np.max(values, axis=1) > np.min(values, axis=1)
    usable = varies & (power > 0.0) & np.isfinite(power)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(usable, lagged / np.where(usable, power, 1.0), 0.0)


def block_length(n: int, rho: float) -> int:
    """Samples per block for a record of ``n`` samples whose residual has lag-1 correlation ρ.

    (√6·ρ / (1 − ρ²))^(2/3) · n^(1/3), the AR(1) plug-in optimum of the block bootstrap; a
    white residual gets blocks of one sample. Clipped so the record holds at least
    :data:`MIN_BLOCKS` and at most :data:`MAX_BLOCKS` blocks.
    """
    if n < 1:
        return 1
    r = min(abs(rho), 0.999)
    length = (math.sqrt(6.0) * r / (1.0 - r * r)) ** (2.0 / 3.0) * n ** (1.0 / 3.0)
    length = max(length, math.ceil(n / MAX_BLOCKS))
    return int(max(1, min(math.ceil(length), n // MIN_BLOCKS or 1)))


def fine_block_size(n: int) -> int:
    """Samples per row of sums: one row per sample up to :data:`FINE_BLOCKS` samples."""
    return max(1, math.ceil(n / FINE_BLOCKS))


@functools.lru_cache(maxsize=4)
def fine_labels(n: int, fine: int) -> IntArray:
    """The fine block of every sample, shared by every signal of a record (and kept for the
    next: the engine sums a long record's signals one at a time, on their scoring threads)."""
    labels = np.arange(n, dtype=np.int64) // max(1, fine)
    labels.flags.writeable = False
    return labels


@dataclass(frozen=True)
class BlockSums:
    """One signal's sums over consecutive fine blocks, and its residual's lag-1 correlation."""

    table: SumTable
    fine: int
    n: int
    rho: float

    @property
    def scale(self) -> float:
        """The exact power of two the sums were taken at (1 unless the values' squares would
        overflow or underflow); λ are scale-free, so a range is scaled alike."""
        return self.table.scale

    @cached_property
    def per_block(self) -> int:
        """Fine blocks per bootstrap block: :func:`block_length` rounded up to whole rows."""
        rows = self.table.values.shape[0]
        wanted = math.ceil(block_length(self.n, self.rho) / self.fine)
        return int(max(1, min(wanted, rows // MIN_BLOCKS or 1)))

    @property
    def block_samples(self) -> int:
        return self.per_block * self.fine


def block_sums(
    ref: FloatArray,
    sim: FloatArray,
    *,
    compiled: bool | None = None,
) -> BlockSums:
    """A signal's rows of sums over fine blocks (one pass), with its residual's ρ."""
    return block_sums_many([(ref, sim)], compiled=compiled)[0]


def block_sums_stacked(n: int) -> bool:
    """Whether :func:`block_sums_many` sums the signals of a record of ``n`` samples as one
    stack (numpy, short records), rather than signal by signal."""
    return n <= STACK_SAMPLES and kernel.kernel_for(n, ("fine_block_sums",)) is None


def block_sums_many(
    pairs: Sequence[tuple[FloatArray, FloatArray]],
    *,
    compiled: bool | None = None,
) -> list[BlockSums]:
    """:func:`block_sums` of several signals of one record (all of one length), in order.

    Where :func:`pytest_hevval.core.kernel.kernel_for` says (``compiled`` decides instead where
    given), each signal is one compiled call that finds its scale, shift, sums and ρ in three
    loops over its samples. On numpy, records up to :data:`STACK_SAMPLES` samples are summed
    for all signals at once, as a stack; longer ones signal by signal.
    """
    if not pairs:
        return []
    n = int(np.asarray(pairs[0][0]).shape[0])
    for ref, sim in pairs:
        if np.asarray(ref).shape != (n,) or np.asarray(sim).shape != (n,):
            raise DegenerateSignalError(
                f"every signal of a record must be 1-D and {n} samples long "
                f"(got {np.asarray(ref).shape}, {np.asarray(sim).shape})"
            )
    if compiled is None:
        module = kernel.kernel_for(n, ("fine_block_sums",))
    else:
        module = kernel.load_or_raise() if compiled else None
    if module is not None:
        return _compiled_block_sums(module, pairs, n)
    if n > STACK_SAMPLES:
        fine = fine_block_size(n)
        labels = fine_labels(n, fine)
        return [_one_block_sums(ref, sim, labels, fine) for ref, sim in pairs]
    step = max(1, STACK_ELEMENTS // max(n, 1))
    out: list[BlockSums] = []
    for first in range(0, len(pairs), step):
        out.extend(_stacked_block_sums(pairs[first : first + step], n))
    return out


def _compiled_block_sums(
    module: ModuleType, pairs: Sequence[tuple[FloatArray, FloatArray]], n: int
) -> list[BlockSums]:
    fine = fine_block_size(n)
    # (signal, row, column): each signal's table one contiguous block, written once.
    tables = np.empty((len(pairs), math.ceil(n / fine), len(SUM_COLUMNS)), dtype=np.float64)
    out: list[BlockSums] = []
    for table, (ref, sim) in zip(tables, pairs, strict=True):
        scale, shift, rho = kernel.fine_block_sums(module, ref, sim, fine, SHIFT_SAMPLES, table)
        out.append(BlockSums(SumTable(table, shift, scale), fine, n, rho))
    return out


def _one_block_sums(ref: FloatArray, sim: FloatArray, labels: IntArray, fine: int) -> BlockSums:
    n = int(np.asarray(ref).shape[0])
    table = labelled_table(ref, sim, labels, math.ceil(n / fine), compiled=False)
    if table.scale != 1.0:  # ρ of the rescaled residual, whose squares stay finite
        ref = np.multiply(ref, table.scale, dtype=np.float64)
        sim = np.multiply(sim, table.scale, dtype=np.float64)
    residual = np.subtract(ref, sim, dtype=np.float64)
    return BlockSums(table, fine, n, lag1_autocorrelation(residual))


def _stacked_block_sums(pairs: Sequence[tuple[FloatArray, FloatArray]], n: int) -> list[BlockSums]:
    """:func:`labelled_table` over fine blocks for a stack of signals: the same sums (in the
    order of ``SUM_COLUMNS``, each block's samples added in order as ``np.bincount`` adds them)
    with a few array operations per column for all signals.

    Every product goes through one scratch stack and every column is written whole, so the pass
    touches little fresh memory: on records of a few thousand samples, first touches of new
    arrays cost more than the arithmetic.
    """
    fine = fine_block_size(n)
    rows = math.ceil(n / fine)
    k = len(pairs)
    r, s, e, scratch = _stack_buffers(k, n)
    for i, (ref, sim) in enumerate(pairs):
        r[i] = ref
        s[i] = sim
    if n:
        with np.errstate(invalid="ignore"):
            peaks = np.maximum(
                np.max(np.abs(r, out=scratch), axis=1), np.max(np.abs(s, out=scratch), axis=1)
            )
    else:
        peaks = np.zeros(k)
    scales = np.array([power_of_two_scale(p) if math.isfinite(p) else 1.0 for p in peaks.tolist()])
    if np.any(scales != 1.0):  # exact powers of two
        r *= scales[:, None]
        s *= scales[:, None]
    np.subtract(r, s, out=e)
    shift = np.mean(e[:, :SHIFT_SAMPLES], axis=1) if n else np.zeros(k)
    rho = lag1_autocorrelations(e, scratch).tolist()
    # (column, signal, row): each column of every signal's table is one contiguous run.
    columns = np.empty((len(SUM_COLUMNS), k, rows), dtype=np.float64)
    columns[0] = fine
    if rows:
        columns[0, :, -1] = n - (rows - 1) * fine
    d = np.subtract(e, shift[:, None], out=scratch)
    _fine_sums(d, fine, columns[1])
    _fine_sums(np.multiply(d, d, out=scratch), fine, columns[2])
    _fine_sums(np.abs(e, out=e), fine, columns[3])
    _fine_sums(r, fine, columns[4])
    _fine_sums(s, fine, columns[5])
    _fine_sums(np.multiply(r, r, out=scratch), fine, columns[6])
    _fine_sums(np.multiply(s, s, out=scratch), fine, columns[7])
    _fine_sums(np.multiply(r, s, out=scratch), fine, columns[8])
    # λ2: the central-difference signs of reference and model agree (both ends are 0 on both
    # sides, so they agree); y[i+1] − y[i−1] > 0 exactly when y[i+1] > y[i−1].
    matches = scratch
    if n:
        matches[:, [0, -1]] = 1.0
    if n > 2:
        r2, r0, s2, s0 = r[:, 2:], r[:, :-2], s[:, 2:], s[:, :-2]
        np.logical_and((r2 > r0) == (s2 > s0), (r2 < r0) == (s2 < s0), out=matches[:, 1:-1])
    _fine_sums(matches, fine, columns[9])
    return [
        BlockSums(SumTable(columns[:, i, :].T, float(shift[i]), float(scales[i])), fine, n, rho[i])
        for i in range(k)
    ]


_BUFFERS = threading.local()


def _stack_buffers(k: int, n: int) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Four (k, n) work arrays, reused by the calling thread from one call to the next.

    A stack holds at most max(:data:`STACK_ELEMENTS`, n) samples, ``n`` at most
    :data:`STACK_SAMPLES`, so the buffers stay under 2 MB per thread. Fresh arrays of this size
    are mapped anew by the allocator whenever other work has allocated in between, and their
    first touch costs about as much as the arithmetic: 20 signals of 6,000 samples, with other
    allocations between calls, took a median 4.3 ms with fresh arrays and 2.0 ms with these.
    """
    size = k * n
    held: FloatArray | None = getattr(_BUFFERS, "flat", None)
    if held is None or held.shape[0] < 4 * size:
        held = np.empty(4 * max(size, STACK_ELEMENTS), dtype=np.float64)
        _BUFFERS.flat = held
    r, s, e, scratch = (held[i * size : (i + 1) * size].reshape(k, n) for i in range(4))
    return r, s, e, scratch


def _fine_sums(x: FloatArray, fine: int, out: FloatArray) -> None:
    """Sums of runs of ``fine`` consecutive samples of every row of ``x`` into ``out`` (the
    last run may be short), each run added left to right as ``np.bincount`` adds it."""
    n = x.shape[1]
    whole = (n // fine) * fine
    runs = whole // fine
    if runs:
        if fine == 1:
            out[:, :runs] = x
        else:
            np.add(x[:, 0:whole:fine], x[:, 1:whole:fine], out=out[:, :runs])
            for offset in range(2, fine):
                out[:, :runs] += x[:, offset:whole:fine]
    if whole < n:
        tail = x[:, whole].copy()
        for j in range(whole + 1, n):
            tail += x[:, j]
        out[:, runs] = tail


def coarsen(table: SumTable, per_block: int) -> SumTable:
    """Runs of ``per_block`` consecutive rows summed into one (the last run may be short)."""
    if per_block <= 1:
        return table
    starts = np.arange(0, table.values.shape[0], per_block)
    return SumTable(np.add.reduceat(table.values, starts, axis=0), table.shift, table.scale)


@lru_cache(maxsize=64)
def resample_counts(blocks: int, replicates: int = REPLICATES, seed: int = SEED) -> FloatArray:
    """How often each block is drawn into each replicate, shape (replicates, blocks).

    Every replicate draws ``blocks`` blocks with replacement. One seed, one matrix: signals of
    one record drawn with the same matrix share their blocks, so quantities combining them
    (λ7, Φ) keep the dependence between signals. Read-only, as it is shared. A spec's signals
    need a matrix per distinct block count (between :data:`MIN_BLOCKS` and about
    :data:`MAX_BLOCKS`), so the cache holds 64 of them: at most 64 × 250 × 130 × 8 bytes
    (17 MB), typically about a MB.
    """
    rng = np.random.default_rng(seed)
    draws = rng.integers(0, blocks, size=(replicates, blocks), dtype=np.int64)
    flat = (draws + blocks * np.arange(replicates, dtype=np.int64)[:, None]).ravel()
    counts = np.bincount(flat, minlength=replicates * blocks).astype(np.float64)
    counts = counts.reshape(replicates, blocks)
    counts.flags.writeable = False
    return counts


def replicate_sums(counts: FloatArray, rows: FloatArray) -> FloatArray:
    """``counts @ rows`` in matrix products of at most :data:`GEMM_LIMIT` multiply-adds each,
    so BLAS stays on the calling thread."""
    replicates, blocks = counts.shape
    width = rows.shape[1]
    if replicates * blocks * width <= GEMM_LIMIT:
        return np.asarray(counts @ rows, dtype=np.float64)
    if blocks * width > GEMM_LIMIT // 8:  # too wide for 8 replicates a product: split columns
        step = max(1, GEMM_LIMIT // (8 * blocks))
        return np.concatenate(
            [replicate_sums(counts, rows[:, a : a + step]) for a in range(0, width, step)], axis=1
        )
    per = GEMM_LIMIT // (blocks * width)
    pieces, rest = divmod(replicates, per)
    whole = pieces * per
    head: FloatArray = np.matmul(counts[:whole].reshape(pieces, per, blocks), rows)
    head = head.reshape(whole, width)
    if not rest:
        return head
    return np.concatenate((head, counts[whole:] @ rows))


def replicate_table(blocks: SumTable, counts: FloatArray) -> SumTable:
    """The sums of every replicate record: one row per row of ``counts``."""
    return SumTable(replicate_sums(counts, blocks.values), blocks.shift, blocks.scale)


def replicate_lambdas(
    blocks: SumTable, counts: FloatArray, reference_range: float, correlation: str = "xcorr"
) -> dict[str, FloatArray]:
    """λ1–λ6 of every replicate, keyed by characteristic name."""
    table = replicate_sums(counts, blocks.values)
    columns = {name: table[:, c] for c, name in enumerate(SUM_COLUMNS)}
    return sums_lambdas(columns, blocks.shift, reference_range, correlation)


def sums_lambdas(
    columns: Mapping[str, FloatArray],
    shift: float | FloatArray,
    reference_range: float | FloatArray,
    correlation: str = "xcorr",
) -> dict[str, FloatArray]:
    """λ1–λ6 from columns of additive sums, elementwise, for many signals at once: the columns
    read as :class:`~pytest_hevval.core.sums.Sums` (``Sums.of_columns``, as
    :meth:`SumTable.sums` reads a table) and λ from them by
    :func:`~pytest_hevval.core.sums.lambdas_from_sums`, as
    :func:`~pytest_hevval.core.groups.group_lambdas` takes them.

    ``columns`` maps the names of ``SUM_COLUMNS`` to arrays of one shape (``ref_sum`` and
    ``sim_sum`` only for ``pearson``), e.g. (replicates, signals); ``shift`` and
    ``reference_range`` broadcast against them (one per signal).
    """
    return lambdas_from_sums(Sums.of_columns(columns, shift), reference_range, correlation).lambdas


def _needed_columns(correlation: str) -> tuple[int, ...]:
    """The columns of the sums a replicate needs, as indices into ``SUM_COLUMNS``
    (``ref_sum`` and ``sim_sum`` only for Pearson's coefficient)."""
    skip = () if correlation == "pearson" else ("ref_sum", "sim_sum")
    return tuple(c for c, name in enumerate(SUM_COLUMNS) if name not in skip)


def stacked_replicates(
    tables: Sequence[SumTable],
    per_blocks: Sequence[int],
    reference_ranges: Sequence[float],
    correlation: str = "xcorr",
) -> dict[str, FloatArray]:
    """λ1–λ6 of every replicate of several signals of one record: each name maps to an array
    (replicates, signals), the same values as :func:`replicate_lambdas` of each table coarsened
    to its ``per_blocks`` entry with the draws of that many blocks.

    Tables of one length merged into blocks of one length share their draws and one product
    (a table may appear twice, at two block lengths); λ then come in one pass for all.
    ``reference_ranges`` are the signals' ranges at the scale of their sums.
    """
    columns = _needed_columns(correlation)
    groups: dict[tuple[int, int], list[int]] = {}
    for i, (table, per_block) in enumerate(zip(tables, per_blocks, strict=True)):
        groups.setdefault((table.values.shape[0], max(1, int(per_block))), []).append(i)
    # One plane per column of sums, (replicates, signals): λ then run on contiguous arrays.
    planes = np.empty((len(columns), REPLICATES, len(tables)), dtype=np.float64)
    for (rows, per_block), members in groups.items():
        starts = np.arange(0, rows, per_block)
        coarse = [np.add.reduceat(tables[i].values, starts, axis=0) for i in members]
        blocks = coarse[0].shape[0]
        # blocks × (signals · columns), each signal's needed columns side by side
        stack = np.stack(coarse, axis=1)[:, :, columns] if len(coarse) > 1 else coarse[0]
        product = replicate_sums(
            resample_counts(blocks),
            stack.reshape(blocks, -1) if len(coarse) > 1 else stack[:, columns],
        ).reshape(REPLICATES, len(members), len(columns))
        first, last = members[0], members[-1]
        if last - first + 1 == len(members):  # consecutive: a view, no index arrays
            planes[:, :, first : last + 1] = product.transpose(2, 0, 1)
        else:
            planes[:, :, members] = product.transpose(2, 0, 1)
    named = {SUM_COLUMNS[c]: planes[i] for i, c in enumerate(columns)}
    shifts = np.array([table.shift for table in tables], dtype=np.float64)
    ranges = np.asarray(reference_ranges, dtype=np.float64)
    return sums_lambdas(named, shifts, ranges, correlation)


def signal_intervals(
    blocks: BlockSums,
    point: Mapping[str, float],
    reference_range: float,
    correlation: str = "xcorr",
    *,
    per_block: int | None = None,
) -> dict[str, Interval]:
    """λ1–λ6 of one signal with their intervals, from its own block length by default."""
    replicates = stacked_replicates(
        [blocks.table],
        [blocks.per_block if per_block is None else per_block],
        [reference_range * blocks.scale],
        correlation,
    )
    names = list(replicates)
    found = stacked_intervals(
        [point[name] for name in names], np.stack([replicates[name][:, 0] for name in names])
    )
    return dict(zip(names, found, strict=True))


def stacked_intervals(values: Sequence[float], replicates: FloatArray) -> list[Interval]:
    """:func:`standard_interval` of every value, with the replicates of ``values[i]`` in row
    ``i`` of ``replicates``; one pass over all rows when every replicate is finite."""
    table = np.asarray(replicates, dtype=np.float64)
    if table.ndim != 2 or table.shape[0] != len(values):
        raise ValueError(
            f"one row of replicates per value (got {table.shape}, {len(values)} values)"
        )
    if table.shape[1] < 2 or not bool(np.isfinite(table).all()):
        return [standard_interval(value, row) for value, row in zip(values, table, strict=True)]
    return _normal_intervals(np.asarray(values, dtype=np.float64), table)


def standard_interval(value: float, replicates: FloatArray) -> Interval:
    """The point value ± z·s at :data:`CONFIDENCE`, s the standard deviation of the finite
    replicates, cut to the span of the replicates and the value.

    The cut keeps a characteristic's own bounds (λ3 never above 1): the replicates come from the
    same formula, so they never leave them. Fewer than two finite replicates, or a value that is
    not finite, give the bare point.
    """
    finite = np.asarray(replicates, dtype=np.float64)
    finite = finite[np.isfinite(finite)]
    if finite.size < 2 or not math.isfinite(value):
        return Interval(value, value, value)
    return _normal_intervals(np.array([value], dtype=np.float64), finite[None, :])[0]


def _normal_intervals(point: FloatArray, table: FloatArray) -> list[Interval]:
    """The rule of :func:`standard_interval` for each ``point[i]`` and row ``i`` of ``table``
    (finite, at least two replicates a row); a point that is not finite stays bare."""
    spread = NORMAL_QUANTILE * np.std(table, axis=1, ddof=1)
    with np.errstate(invalid="ignore"):
        low = np.maximum(point - spread, np.minimum(np.min(table, axis=1), point))
        high = np.minimum(point + spread, np.maximum(np.max(table, axis=1), point))
    bare = ~np.isfinite(point)
    low[bare] = high[bare] = point[bare]
    return [
        Interval(value, lo, hi)
        for value, lo, hi in zip(point.tolist(), low.tolist(), high.tolist(), strict=True)
    ]
