"""How sure is a characteristic? Block-bootstrap intervals from per-block sums.

At 100 Hz neighbouring samples of a residual are strongly correlated, so a record holds far
fewer independent samples than rows, and an interval that treats samples as independent is far
too narrow. A block bootstrap keeps that dependence: the record is cut into non-overlapping
blocks of ``b`` samples, a replicate record is made of blocks drawn with replacement, and its
characteristics are computed again. Because λ1–λ6 are ratios of sums (see
:mod:`pytest_hevval.core.local`), a replicate needs only the blocks' sums, not the samples:
each signal is read once more, into at most :data:`FINE_BLOCKS` rows of sums, and every
replicate is then a weighted sum of those rows.

Choices, each documented in ``docs/uncertainty.md``:

* **Block length** from the residual's lag-1 autocorrelation ρ, the plug-in rule for the block
  bootstrap of a mean under an AR(1) model (Politis & White 2004, with the correction of
  Patton, Politis & White 2009): b = (√6·ρ / (1 − ρ²))^(2/3) · n^(1/3), at least
  n / :data:`MAX_BLOCKS` and at most n / :data:`MIN_BLOCKS`; rounded up to whole fine blocks of
  ⌈n / FINE_BLOCKS⌉ samples.
* **Non-overlapping blocks** (Carlstein 1986), so replicates are sums of stored block sums.
* **Percentile intervals** from :data:`REPLICATES` replicates drawn with a fixed seed, so one
  record always gives one interval (CI runs are reproducible).
* **The normalising range R is held fixed**: it is the reference's range, a property of the
  measurement the characteristics are scaled by, not an estimate.
* **What is not bootstrapped:** the lag (a search over shifts, not a ratio of sums) keeps its
  point value, and so do registered characteristics that are not ratios of these sums.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import numpy.typing as npt

from .characteristics import power_of_two_scale
from .local import CorrelationKind, SumTable, group_lambdas, labelled_table

__all__ = [
    "CONFIDENCE",
    "FINE_BLOCKS",
    "MAX_BLOCKS",
    "MIN_BLOCKS",
    "REPLICATES",
    "BlockSums",
    "Interval",
    "block_length",
    "block_sums",
    "coarsen",
    "fine_block_size",
    "fine_labels",
    "lag1_autocorrelation",
    "percentile_interval",
    "percentile_intervals",
    "replicate_lambdas",
    "replicate_table",
    "resample_counts",
    "signal_intervals",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

#: Nominal coverage of every interval.
CONFIDENCE = 0.95
#: Bootstrap replicates: enough for the 2.5 % and 97.5 % quantiles to settle to about ±0.1 of
#: the interval's width, cheap because a replicate is a weighted sum of block sums.
REPLICATES = 1000
#: A record is cut into at least this many blocks; fewer cannot show its variability.
MIN_BLOCKS = 10
#: ... and into at most this many. Blocks longer than the rule asks keep the bootstrap valid
#: (they only keep more of the dependence); beyond about a hundred blocks the interval gains
#: little, while every replicate costs one multiply-add per block and sum.
MAX_BLOCKS = 128
#: At most this many rows of sums are kept per signal; a bootstrap block is a run of them.
FINE_BLOCKS = 4096
#: The seed of the draws: one record, one interval.
SEED = 20_140_601


@dataclass(frozen=True)
class Interval:
    """A point value with its confidence interval."""

    value: float
    low: float
    high: float

    def __str__(self) -> str:
        return f"{self.value:.4f} [{self.low:.4f}, {self.high:.4f}]"

    @property
    def bounds(self) -> str:
        """``[low, high]`` as printed beside a value."""
        return f"[{self.low:.4f}, {self.high:.4f}]"

    def to_dict(self) -> dict[str, float]:
        return {"value": self.value, "low": self.low, "high": self.high}

    @classmethod
    def from_dict(cls, data: dict[str, float]) -> Interval:
        return cls(float(data["value"]), float(data["low"]), float(data["high"]))


def lag1_autocorrelation(x: FloatArray) -> float:
    """Lag-1 autocorrelation of ``x`` (0 for a constant or too short series)."""
    values = np.asarray(x, dtype=np.float64)
    if values.shape[0] < 3:
        return 0.0
    centred = values - values.mean()
    power = float(np.dot(centred, centred))
    if not (power > 0.0 and math.isfinite(power)):
        return 0.0
    return float(np.dot(centred[1:], centred[:-1]) / power)


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


def fine_labels(n: int, fine: int) -> IntArray:
    """The fine block of every sample, shared by every signal of a record."""
    return np.arange(n, dtype=np.int64) // max(1, fine)


@dataclass(frozen=True)
class BlockSums:
    """One signal's sums over consecutive fine blocks, and its residual's lag-1 correlation."""

    table: SumTable
    fine: int
    n: int
    rho: float
    #: The exact power of two the sums were taken at (1 unless the values' squares would
    #: overflow or underflow); λ are scale-free, so a range is scaled alike.
    scale: float = 1.0

    @property
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
    labels: IntArray | None = None,
    *,
    compiled: bool | None = None,
) -> BlockSums:
    """A signal's rows of sums over fine blocks (one pass), with its residual's ρ.

    ``labels`` are :func:`fine_labels` of the record, passed in when many signals share it.
    """
    n = int(np.asarray(ref).shape[0])
    fine = fine_block_size(n)
    if labels is None:
        labels = fine_labels(n, fine)
    rows = math.ceil(n / fine)
    scale = _power_of_two_scale(ref, sim)
    if scale != 1.0:
        ref = np.multiply(ref, scale, dtype=np.float64)
        sim = np.multiply(sim, scale, dtype=np.float64)
    table = labelled_table(ref, sim, labels, rows, compiled=compiled)
    residual = np.subtract(ref, sim, dtype=np.float64)
    return BlockSums(table, fine, n, lag1_autocorrelation(residual), scale)


def _power_of_two_scale(ref: FloatArray, sim: FloatArray) -> float:
    peak = max(float(np.max(np.abs(ref), initial=0.0)), float(np.max(np.abs(sim), initial=0.0)))
    return power_of_two_scale(peak) if math.isfinite(peak) else 1.0


def coarsen(table: SumTable, per_block: int) -> SumTable:
    """Runs of ``per_block`` consecutive rows summed into one (the last run may be short)."""
    if per_block <= 1:
        return table
    starts = np.arange(0, table.values.shape[0], per_block)
    return SumTable(np.add.reduceat(table.values, starts, axis=0), table.shift)


@lru_cache(maxsize=32)
def resample_counts(blocks: int, replicates: int = REPLICATES, seed: int = SEED) -> FloatArray:
    """How often each block is drawn into each replicate, shape (replicates, blocks).

    Every replicate draws ``blocks`` blocks with replacement. One seed, one matrix: signals of
    one record drawn with the same matrix share their blocks, so quantities combining them
    (λ7, Φ) keep the dependence between signals. Read-only, as it is shared.
    """
    rng = np.random.default_rng(seed)
    draws = rng.integers(0, blocks, size=(replicates, blocks), dtype=np.int64)
    flat = (draws + blocks * np.arange(replicates, dtype=np.int64)[:, None]).ravel()
    counts = np.bincount(flat, minlength=replicates * blocks).astype(np.float64)
    counts = counts.reshape(replicates, blocks)
    counts.flags.writeable = False
    return counts


def replicate_table(blocks: SumTable, counts: FloatArray) -> SumTable:
    """The sums of every replicate record: one row per row of ``counts``."""
    return SumTable(counts @ blocks.values, blocks.shift)


def replicate_lambdas(
    blocks: SumTable, counts: FloatArray, reference_range: float, correlation: str = "xcorr"
) -> dict[str, FloatArray]:
    """λ1–λ6 of every replicate, keyed by characteristic name."""
    kind: CorrelationKind = "pearson" if correlation == "pearson" else "xcorr"
    return group_lambdas(replicate_table(blocks, counts).sums(), reference_range, kind)


def signal_intervals(
    blocks: BlockSums,
    point: Mapping[str, float],
    reference_range: float,
    correlation: str = "xcorr",
    *,
    per_block: int | None = None,
) -> dict[str, Interval]:
    """λ1–λ6 of one signal with their intervals, from its own block length by default."""
    table = coarsen(blocks.table, blocks.per_block if per_block is None else per_block)
    replicates = replicate_lambdas(
        table,
        resample_counts(table.values.shape[0]),
        reference_range * blocks.scale,
        correlation,
    )
    return percentile_intervals(point, replicates)


def percentile_intervals(
    point: Mapping[str, float], replicates: Mapping[str, FloatArray]
) -> dict[str, Interval]:
    """:func:`percentile_interval` of every named value, with one quantile call for all."""
    names = list(replicates)
    table = np.column_stack([np.asarray(replicates[name], dtype=np.float64) for name in names])
    tail = (1.0 - CONFIDENCE) / 2.0
    finite_columns = np.asarray(np.isfinite(table).all(axis=0), dtype=bool)
    with np.errstate(invalid="ignore"):
        bounds = np.quantile(table, [tail, 1.0 - tail], axis=0)
    out = {}
    for k, name in enumerate(names):
        value = point[name]
        if finite_columns[k] and math.isfinite(value):
            low, high = float(bounds[0, k]), float(bounds[1, k])
            out[name] = Interval(value, min(low, value), max(high, value))
        else:
            out[name] = percentile_interval(value, table[:, k])
    return out


def percentile_interval(
    value: float, replicates: FloatArray, confidence: float = CONFIDENCE
) -> Interval:
    """The point value with the central ``confidence`` quantiles of its replicates.

    Widened to hold the point value where the percentiles would exclude it.
    """
    finite = np.asarray(replicates, dtype=np.float64)
    finite = finite[np.isfinite(finite)]
    if finite.size == 0 or not math.isfinite(value):
        return Interval(value, value, value)
    tail = (1.0 - confidence) / 2.0
    low, high = np.quantile(finite, [tail, 1.0 - tail])
    return Interval(value, float(min(low, value)), float(max(high, value)))
