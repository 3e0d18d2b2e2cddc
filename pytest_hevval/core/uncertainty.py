"""How sure is a characteristic? Block-bootstrap intervals from per-block sums.

At 100 Hz neighbouring samples of a residual are strongly correlated, so a record holds far
fewer independent samples than rows, and an interval that treats samples as independent is far
too narrow. A block bootstrap keeps that dependence: the record is cut into non-overlapping
blocks of ``b`` samples, a replicate record is made of blocks drawn with replacement, and its
characteristics are computed again. Because λ1–λ6 are ratios of sums (see
:mod:`pytest_hevval.core.local`), a replicate needs only the blocks' sums, not the samples:
the interval costs a few thousand additions per signal, whatever the record's length.

Choices, each documented in ``docs/uncertainty.md``:

* **Block length** from the residual's lag-1 autocorrelation ρ, the plug-in rule for the block
  bootstrap of a mean under an AR(1) model (Politis & White 2004, with the correction of
  Patton, Politis & White 2009): b = (√6·ρ / (1 − ρ²))^(2/3) · n^(1/3), at least 1 and at most
  n / :data:`MIN_BLOCKS`.
* **Non-overlapping blocks** (Carlstein 1986), so replicates are sums of stored block sums.
* **Percentile intervals** from :data:`REPLICATES` replicates drawn with a fixed seed, so one
  record always gives one interval (CI runs are reproducible).
* **The normalising range R is held fixed**: it is the reference's range, a property of the
  measurement the characteristics are scaled by, not an estimate.
* **What is not bootstrapped:** the lag (a search over shifts, not a ratio of sums) keeps its
  point value. λ7 and Φ are computed per replicate from the λ1–λ6 of every signal of the spec
  drawn with the *same* blocks, so their intervals carry the dependence between signals.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .local import CorrelationKind, GroupSums, group_lambdas

__all__ = [
    "CONFIDENCE",
    "MIN_BLOCKS",
    "REPLICATES",
    "Interval",
    "block_length",
    "bootstrap_draws",
    "lag1_autocorrelation",
    "percentile_interval",
    "replicate_lambdas",
    "replicate_sums",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

#: Nominal coverage of every interval.
CONFIDENCE = 0.95
#: Bootstrap replicates: enough for the 2.5 % and 97.5 % quantiles to settle to about ±0.1 of
#: the interval's width, cheap because a replicate is a sum of block sums.
REPLICATES = 1000
#: A record is cut into at least this many blocks; fewer cannot show its variability.
MIN_BLOCKS = 10
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

    def to_dict(self) -> dict[str, float]:
        return {"value": self.value, "low": self.low, "high": self.high}


def lag1_autocorrelation(x: FloatArray) -> float:
    """Lag-1 autocorrelation of ``x`` (0 for a constant or too short series)."""
    values = np.asarray(x, dtype=np.float64)
    if values.shape[0] < 3:
        return 0.0
    centred = values - values.mean()
    power = float(np.dot(centred, centred))
    if power <= 0.0:
        return 0.0
    return float(np.dot(centred[1:], centred[:-1]) / power)


def block_length(n: int, rho: float) -> int:
    """Samples per block for a record of ``n`` samples whose residual has lag-1 correlation ρ.

    (√6·ρ / (1 − ρ²))^(2/3) · n^(1/3), the AR(1) plug-in optimum of the block bootstrap; a
    white residual gets blocks of one sample. Clipped so the record holds at least
    :data:`MIN_BLOCKS` blocks.
    """
    if n < 1:
        return 1
    r = min(abs(rho), 0.999)
    length = (math.sqrt(6.0) * r / (1.0 - r * r)) ** (2.0 / 3.0) * n ** (1.0 / 3.0)
    return int(max(1, min(math.ceil(length), n // MIN_BLOCKS or 1)))


def bootstrap_draws(blocks: int, replicates: int = REPLICATES, seed: int = SEED) -> IntArray:
    """Block indices of every replicate, shape (replicates, blocks), drawn with replacement."""
    rng = np.random.default_rng(seed)
    return rng.integers(0, blocks, size=(replicates, blocks), dtype=np.int64)


def replicate_sums(blocks: GroupSums, draws: IntArray) -> GroupSums:
    """The sums of every replicate record (one entry per row of ``draws``).

    The spread term Σ(e − ē)² of a replicate is rebuilt from each block's own Σ(e − ē_block)²
    and its mean, by the parallel-variance rule, so a large bias does not cancel it.
    """
    n = blocks.n[draws].sum(axis=1)
    error_sum = blocks.error_sum[draws].sum(axis=1)
    safe_n = np.maximum(blocks.n, 1).astype(np.float64)
    block_mean = blocks.error_sum / safe_n
    replicate_mean = error_sum / np.maximum(n, 1)
    between = blocks.n[draws] * (block_mean[draws] - replicate_mean[:, None]) ** 2
    return GroupSums(
        n=n,
        error_sum=error_sum,
        abs_error=blocks.abs_error[draws].sum(axis=1),
        sq_error=blocks.sq_error[draws].sum(axis=1),
        error_m2=blocks.error_m2[draws].sum(axis=1) + between.sum(axis=1),
        ref_sum=blocks.ref_sum[draws].sum(axis=1),
        sim_sum=blocks.sim_sum[draws].sum(axis=1),
        ref_sq=blocks.ref_sq[draws].sum(axis=1),
        sim_sq=blocks.sim_sq[draws].sum(axis=1),
        cross=blocks.cross[draws].sum(axis=1),
        sign_matches=blocks.sign_matches[draws].sum(axis=1),
    )


def replicate_lambdas(
    blocks: GroupSums, draws: IntArray, reference_range: float, correlation: str = "xcorr"
) -> dict[str, FloatArray]:
    """λ1–λ6 of every replicate, keyed by characteristic name."""
    kind: CorrelationKind = "pearson" if correlation == "pearson" else "xcorr"
    return group_lambdas(replicate_sums(blocks, draws), reference_range, kind)


def percentile_interval(
    value: float, replicates: FloatArray, confidence: float = CONFIDENCE
) -> Interval:
    """The point value with the central ``confidence`` quantiles of its replicates."""
    finite = replicates[np.isfinite(replicates)]
    if finite.size == 0:
        return Interval(value, value, value)
    tail = (1.0 - confidence) / 2.0
    low, high = np.quantile(finite, [tail, 1.0 - tail])
    return Interval(value, float(min(low, value)), float(max(high, value)))
