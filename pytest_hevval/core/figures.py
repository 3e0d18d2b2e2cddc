"""Display data for one signal pair, small enough to travel without the traces.

:func:`figure_data` runs where the samples live (the engine, an xdist worker, a Dask node) and
returns plain JSON-safe lists; the report then draws every per-signal plot from that alone. A
record of any length reduces to at most ``points`` buckets plus a fixed-size correlation curve
and histogram, so a one-hour, 100 Hz trace costs about the same to ship as a one-minute one.

Pure numpy (:mod:`pytest_hevval.core.lag` is imported on first use, so that importing the report
package stays cheap).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from ..errors import DegenerateSignalError

if TYPE_CHECKING:
    from .lag import LagSearch

__all__ = ["FIGURE_SCHEMA_VERSION", "figure_data"]

#: Bumped when the keys or meaning of :func:`figure_data`'s output change.
FIGURE_SCHEMA_VERSION = 2

# Significant digits kept in the shipped lists: plots are a few hundred pixels tall, so six
# digits are far below one pixel while keeping JSON roughly half the size of full repr.
_DIGITS = 6


def _rounded(values: npt.NDArray[np.float64], digits: int = _DIGITS) -> list[float]:
    """``digits`` significant digits relative to the largest magnitude in ``values``."""
    if values.size == 0:
        return []
    peak = float(np.max(np.abs(values)))
    if peak == 0.0 or not math.isfinite(peak):
        return [float(v) for v in values.tolist()]
    decimals = digits - 1 - math.floor(math.log10(peak))
    out: list[float] = np.round(values, decimals).tolist()
    return out


def _round_scalar(value: float, digits: int = _DIGITS) -> float:
    return float(f"{value:.{digits}g}")


def _bucket_edges(n: int, points: int) -> npt.NDArray[np.intp]:
    """Start index of every bucket plus ``n``; buckets differ in size by at most one sample."""
    buckets = max(1, min(points, n))
    return (np.arange(buckets + 1, dtype=np.int64) * n // buckets).astype(np.intp)


def figure_data(
    reference: npt.ArrayLike,
    simulated: npt.ArrayLike,
    *,
    dt: float,
    start_s: float,
    max_lag: int,
    points: int = 2000,
    bins: int = 50,
    search: LagSearch | None = None,
) -> dict[str, Any]:
    r"""Decimated overlay, correlation curve, derivative match and error histogram of one pair.

    Parameters
    ----------
    reference, simulated:
        Aligned, equal-length, finite samples on one time grid.
    dt:
        Sample spacing in seconds.
    start_s:
        Time of the first sample, in seconds.
    max_lag:
        Half-width of the cross-correlation curve, in samples (the λ1 lag search window).
    points:
        Most buckets in the time-axis plots.
    bins:
        Bins of the error histogram.
    search:
        The λ pass's lag search; its lag and its exact ρ at the lag and at zero lag mark the
        curve's peak, so the figure states what every other output states. Without it the
        peak is the curve's own.

    Returns
    -------
    dict
        JSON-safe. ``overlay`` holds per bucket the mid time and the min/max of reference,
        simulated and residual e = y_ref − y_sim (so spikes survive decimation);
        ``correlation`` ρ(m), the mean-removed correlation the lag search maximises
        (:mod:`pytest_hevval.core.lag`), with its peak, its value at zero lag and whether
        the peak lies on the edge of the search (Fig. 5 of the paper);
        ``derivative`` the fraction of samples per overlay bucket whose central-difference
        derivative signs agree (Fig. 7); ``histogram`` the error histogram with its empirical
        CDF (Fig. 9).

    Raises
    ------
    DegenerateSignalError
        Different lengths, fewer than 3 samples, non-finite samples, or dt ≤ 0.

    Notes
    -----
    The derivative match uses the same convention as λ2: sign(y[i+1] − y[i−1]) with the first
    and last derivative set to 0, so the count-weighted mean of ``derivative.match`` is λ2.
    """
    from .lag import LagSearch, correlation_curve

    ref = np.asarray(reference, dtype=np.float64)
    sim = np.asarray(simulated, dtype=np.float64)
    if ref.ndim != 1 or ref.shape != sim.shape:
        raise DegenerateSignalError(
            f"figure data needs two one-dimensional signals of equal length "
            f"(got shapes {ref.shape} and {sim.shape})"
        )
    n = int(ref.shape[0])
    if n < 3:
        raise DegenerateSignalError(f"figure data needs at least 3 samples (got {n})")
    if not (math.isfinite(dt) and dt > 0):
        raise DegenerateSignalError(f"dt must be a positive, finite number of seconds (got {dt!r})")
    if points < 1 or bins < 1:
        raise DegenerateSignalError(f"points and bins must be ≥ 1 (got {points} and {bins})")
    residual = ref - sim
    if not np.isfinite(residual).all():
        raise DegenerateSignalError("figure data needs finite samples (found NaN or inf)")

    edges = _bucket_edges(n, points)
    starts = edges[:-1]
    counts = np.diff(edges)
    mid_time = start_s + (starts + (counts - 1) / 2.0) * dt

    # Central-difference sign agreement, per sample (endpoints have derivative 0 on both sides).
    dr = ref[2:] - ref[:-2]
    ds = sim[2:] - sim[:-2]
    np.sign(dr, out=dr)
    np.sign(ds, out=ds)
    match = np.empty(n, dtype=np.bool_)
    match[0] = match[-1] = True
    np.equal(dr, ds, out=match[1:-1])
    matches = np.add.reduceat(match, starts, dtype=np.int64)
    match_per_bucket = matches / counts

    lags, curve = correlation_curve(ref, sim, max_lag, points=401)
    if search is None:
        zero = int(np.argmin(np.abs(lags)))
        # Ties go to the lag closest to zero, as in the search.
        best = np.flatnonzero(curve == np.max(curve))
        peak_index = int(best[np.argmin(np.abs(lags[best]))])
        search = LagSearch(
            lag=int(lags[peak_index]),
            max_lag=int(lags[-1]),
            method="fft",
            correlation=float(curve[peak_index]),
            zero_lag_correlation=float(curve[zero]),
        )

    hist_counts, hist_edges = np.histogram(
        residual, bins=bins, range=_histogram_range(residual, bins)
    )
    cdf = np.cumsum(hist_counts) / n

    overlay = {
        "time": _rounded(mid_time, 9),
        "ref_min": _rounded(np.minimum.reduceat(ref, starts)),
        "ref_max": _rounded(np.maximum.reduceat(ref, starts)),
        "sim_min": _rounded(np.minimum.reduceat(sim, starts)),
        "sim_max": _rounded(np.maximum.reduceat(sim, starts)),
        "res_min": _rounded(np.minimum.reduceat(residual, starts)),
        "res_max": _rounded(np.maximum.reduceat(residual, starts)),
        "count": counts.tolist(),
    }
    return {
        "schema_version": FIGURE_SCHEMA_VERSION,
        "n_samples": n,
        "dt": float(dt),
        "start_s": float(start_s),
        "overlay": overlay,
        "correlation": {
            "lag_s": _rounded(lags.astype(np.float64) * dt, 9),
            "value": _rounded(curve),
            "peak": _round_scalar(search.correlation),
            "peak_lag_s": _round_scalar(search.lag * dt, 9),
            "zero_lag": _round_scalar(search.zero_lag_correlation),
            "max_lag_s": _round_scalar(search.max_lag * dt, 9),
            "at_bound": search.at_bound,
        },
        "derivative": {
            "match": _rounded(match_per_bucket, 4),
            "fraction": int(matches.sum()) / n,
        },
        "histogram": {
            "edges": _rounded(hist_edges),
            "counts": hist_counts.tolist(),
            "cdf": _rounded(cdf),
            "mean": _round_scalar(float(residual.mean())),
            "std": _round_scalar(float(residual.std(ddof=1))),
        },
    }


def _histogram_range(residual: npt.NDArray[np.float64], bins: int) -> tuple[float, float]:
    """The residual's range, widened where it is narrower than ``bins`` distinct floats at its
    magnitude: a model equal to the reference plus a constant leaves a residual that is that
    constant up to rounding, which cannot be cut into finite bins."""
    low, high = float(np.min(residual)), float(np.max(residual))
    floor = 4.0 * bins * float(np.spacing(max(abs(low), abs(high), np.finfo(np.float64).tiny)))
    if high - low >= floor:
        return low, high
    if low == high and floor <= 1.0:
        return low - 0.5, high + 0.5  # numpy's own range for a constant
    centre = low / 2.0 + high / 2.0
    return centre - floor, centre + floor
