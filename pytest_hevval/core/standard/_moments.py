"""The sums and centred moments that Theil's U, KGE, NSE, CV(RMSE), NMBE, Sprague–Geers and
Russell are built from: taken from the arrays, or from the λ pass's sums without another read.

Each of those metrics is a formula on a :class:`Moments`; its array function builds one with
:func:`moments_of` and the engine with :func:`moments_from_pass`, so the two ways share every
formula. All sums are in the signal's units times a power of two, which leaves every ratio the
metrics take unchanged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..sums import Sums
from ._inputs import (
    FloatArray,
    checked_pair,
    constant_reference,
    degenerate,
    power_of_two_exponent,
)

__all__ = [
    "CANCELLATION_BITS",
    "Moments",
    "checked_moments",
    "moments_from_pass",
    "moments_of",
    "reference_mean",
]

#: A centred sum Σ(x − x̄)² taken as Σx² − (Σx)²/n may lose at most this many bits to
#: cancellation (about three significant digits of sixteen); a signal whose mean dwarfs its
#: spread more than that is centred on its samples instead.
CANCELLATION_BITS = 10


@dataclass(frozen=True)
class Moments:
    """A pair's sums (``sums``, the whole record's, as λ1–λ6 are taken from), the centred
    Σ(ref − mean)², Σ(sim − mean)² and the co-moment Σ(ref − mean)(sim − mean)."""

    sums: Sums[float]
    ref_m2: float
    sim_m2: float
    co_m2: float

    def check(self, metric: str) -> Moments:
        """These moments, or the error ``checked_pair`` gives for a constant reference (the λ
        pass accepts one that has a declared range)."""
        if self.sums.ref_max == self.sums.ref_min:
            raise constant_reference(metric)
        return self

    @property
    def n(self) -> int:
        count: int = self.sums.n  # a whole record's: an int
        return count

    @property
    def ref_mean(self) -> float:
        return self.sums.ref_sum / self.n

    @property
    def sim_mean(self) -> float:
        return self.sums.sim_sum / self.n

    @property
    def ref_peak(self) -> float:
        """max |ref|."""
        return max(abs(self.sums.ref_min), abs(self.sums.ref_max))


def _deviations(values: FloatArray, scale: float, mean: float) -> FloatArray:
    """x·scale − mean, in a new array."""
    out: FloatArray = np.multiply(values, scale, dtype=np.float64)
    return np.subtract(out, mean, out=out)


def _centred(values: FloatArray, scale: float, mean: float) -> float:
    """Σ(x·scale − mean)², corrected for the rounding of ``mean`` (the two-pass formula)."""
    d = _deviations(values, scale, mean)
    total = float(np.sum(d))
    return max(0.0, float(d @ d) - total * total / int(d.shape[0]))


def _centred_from_sums(square: float, total: float, n: int) -> float | None:
    """Σx² − (Σx)²/n, or None when that would lose more than CANCELLATION_BITS bits."""
    m2 = square - total * (total / n)
    if not math.isfinite(m2) or m2 * 2.0**CANCELLATION_BITS < square:
        return None
    return m2


def moments_from_pass(sums: Sums[float], reference: FloatArray, simulated: FloatArray) -> Moments:
    """The moments of a pair whose λ pass left ``sums``; a side whose mean dwarfs its spread is
    centred on its samples (one read of that side), any other costs no read at all."""
    n = sums.n
    ref_m2 = _centred_from_sums(sums.ref_sq, sums.ref_sum, n)
    if ref_m2 is None:
        ref_m2 = _centred(reference, sums.scale, sums.ref_sum / n)
    sim_m2 = _centred_from_sums(sums.sim_sq, sums.sim_sum, n)
    if sim_m2 is None:
        sim_m2 = _centred(simulated, sums.scale, sums.sim_sum / n)
    low, high = sorted((ref_m2, sim_m2))
    if low * 2.0 ** (2 * CANCELLATION_BITS) >= high:
        # var(ref − sim) = var ref + var sim − 2 cov: rounding of the order of the larger
        # variance, so at most CANCELLATION_BITS bits of the correlation when the two are alike.
        co_m2 = 0.5 * (ref_m2 + sim_m2 - sums.error_m2)
    else:
        co_m2 = _co_moment(reference, simulated, sums.scale, sums.ref_sum / n, sums.sim_sum / n)
    return Moments(sums, ref_m2, sim_m2, co_m2)


def _co_moment(
    reference: FloatArray, simulated: FloatArray, scale: float, ref_mean: float, sim_mean: float
) -> float:
    """Σ(r·scale − ref_mean)(s·scale − sim_mean), corrected for the rounding of the means."""
    d = _deviations(reference, scale, ref_mean)
    f = _deviations(simulated, scale, sim_mean)
    return float(d @ f) - float(np.sum(d)) * float(np.sum(f)) / int(d.shape[0])


def moments_of(reference: FloatArray, simulated: FloatArray) -> Moments:
    """The moments of a checked pair (``checked_pair``), each sum taken on the samples.

    Both signals are scaled by the power of two that brings the larger peak into [0.5, 1), so
    no square overflows.
    """
    peak = max(float(np.max(np.abs(reference))), float(np.max(np.abs(simulated))))
    scale = math.ldexp(1.0, power_of_two_exponent(peak))
    r = np.multiply(reference, scale)
    s = np.multiply(simulated, scale)
    e = r - s
    n = int(r.shape[0])
    ref_sum = float(np.sum(r))
    sim_sum = float(np.sum(s))
    error_sum = float(np.sum(e))
    sums = Sums(
        n=n,
        error_sum=error_sum,
        # Neither is a moment: no metric built on moments reads them.
        abs_error=math.nan,
        sq_error=float(e @ e),
        error_m2=_centred(e, 1.0, error_sum / n),
        ref_sum=ref_sum,
        sim_sum=sim_sum,
        ref_sq=float(r @ r),
        sim_sq=float(s @ s),
        cross=float(r @ s),
        sign_matches=math.nan,
        scale=scale,
        ref_min=float(np.min(r)),
        ref_max=float(np.max(r)),
    )
    return Moments(
        sums,
        _centred(r, 1.0, ref_sum / n),
        _centred(s, 1.0, sim_sum / n),
        _co_moment(r, s, 1.0, ref_sum / n, sim_sum / n),
    )


def checked_moments(reference: FloatArray, simulated: FloatArray, metric: str) -> Moments:
    """The moments of a pair that ``checked_pair`` accepts for ``metric``."""
    return moments_of(*checked_pair(reference, simulated, metric=metric))


# A mean below this fraction of the peak is round-off: a signal that swings about zero.
_ZERO_MEAN = 1e-12


def reference_mean(m: Moments, metric: str, hint: str) -> float:
    """The reference's mean, refused when it is 0 up to round-off (the metric divides by it)."""
    mean = m.ref_mean
    if abs(mean) <= _ZERO_MEAN * m.ref_peak:
        raise degenerate(metric, "the reference's mean is 0, so the metric divides by zero", hint)
    return mean
