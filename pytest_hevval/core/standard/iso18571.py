"""ISO/TS 18571:2014 objective rating of a non-ambiguous time history.

The rating R = w_Z·Z + w_E·E_P + w_M·E_M + w_S·E_S combines four scores in [0, 1]
(ISO/TS 18571:2014, clause 5 and Table 2 for every parameter below):

* **corridor** Z: the mean over samples of a corridor score; |e| below the inner corridor
  a₀·max|y_ref| scores 1, above the outer corridor b₀·max|y_ref| scores 0, in between
  ((δ_o − |e|)/(δ_o − δ_i))^k_Z (unshifted curves).
* **phase** E_P: the shift n_ε (in samples, at most ε_P·N) that maximises Pearson's
  correlation of the overlapping parts; E_P = ((ε_P·N − |n_ε|)/(ε_P·N))^k_P. Shifts of the
  simulation to the left are tried before shifts to the right and a shift replaces the best so
  far only when strictly better, so ties go to the smallest shift (clause 5.3).
* **magnitude** E_M: the shifted curves are warped onto each other by dynamic time warping
  (squared distance, symmetric steps, Sakoe–Chiba band of 10 % of the samples);
  ε_mag = ‖c_w − r_w‖₁ / ‖r_w‖₁ along the warping path, E_M = ((ε_M − ε_mag)/ε_M)^k_M.
* **slope** E_S: central-difference derivatives of the shifted curves smoothed by a
  nine-sample moving average (shorter averages at the four ends),
  ε_slope = ‖ċ − ṙ‖₁ / ‖ṙ‖₁, E_S = (ε_S − ε_slope)/ε_S.

The standard asks for curves sampled at 10 kHz; the scores here are computed on hevval's
aligned grid, whatever its rate (the slope's dt cancels in its ratio). Identical to the
``objective-rating-metrics`` package (the standard's reference implementation in Python) to
better than 0.001 on its curves; ``tests/test_standard_metrics.py`` checks it.

Units: both curves are first scaled by one power of two (exact in binary floating point), so
a pair in units a power of two apart gets the same bits, and values from 1e-300 to 1e300 score
as at 1. Ties: where several warping paths cost the same, the numpy and the compiled paths
compute every cell of the recurrence alike and so pick the same one.

Long records: the warping band holds about N²/5 cells. Up to :data:`EXACT_DTW_CELLS` cells the
band is the standard's; beyond it the band is narrowed to fit (``banded`` = 1 in the
components) — the measured deviation is in docs/metrics.md.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import signal as sps

from .. import kernel
from ..registry import CharacteristicValue
from ._inputs import FloatArray, checked_pair, degenerate, power_of_two_exponent

__all__ = [
    "EXACT_DTW_CELLS",
    "ISO18571_PARAMETERS",
    "Iso18571Parameters",
    "Iso18571Rating",
    "iso18571_characteristic",
    "iso18571_rating",
]

#: Cells of the warping band computed exactly (int8 back-pointers: 64 MB).
EXACT_DTW_CELLS = 64_000_000
# Correlations closer than this are a tie (FFT round-off must not break the standard's ties).
_CORRELATION_TIE = 1e-12
_MIN_SAMPLES = 10
# Samples of the slope's moving average; the phase shift can leave fewer than _MIN_SAMPLES.
_SLOPE_AVERAGE = 9
# Anti-diagonals of the warping band held as float64 at once (their backtracking steps are
# then chosen together): 512 diagonals of a 4,000-sample band are 1.6 MB.
_DTW_BLOCK = 512


@dataclass(frozen=True)
class Iso18571Parameters:
    """ISO/TS 18571:2014 Table 2 (the standard's values are the defaults)."""

    inner_corridor: float = 0.05  # a₀
    outer_corridor: float = 0.5  # b₀
    corridor_exponent: float = 2.0  # k_Z
    phase_limit: float = 0.2  # ε_P, a fraction of the curve's samples
    phase_exponent: float = 1.0  # k_P
    magnitude_limit: float = 0.5  # ε_M
    magnitude_exponent: float = 1.0  # k_M
    slope_limit: float = 2.0  # ε_S
    warping_window: float = 0.1  # Sakoe–Chiba band, a fraction of the samples
    weight_corridor: float = 0.4
    weight_phase: float = 0.2
    weight_magnitude: float = 0.2
    weight_slope: float = 0.2


ISO18571_PARAMETERS = Iso18571Parameters()


@dataclass(frozen=True)
class Iso18571Rating:
    """The overall rating and its four scores; ``shift`` in samples, negative = sim lags."""

    rating: float
    corridor: float
    phase: float
    magnitude: float
    slope: float
    shift: int
    magnitude_error: float
    slope_error: float
    band: int
    banded: bool


def iso18571_rating(
    reference: FloatArray,
    simulated: FloatArray,
    parameters: Iso18571Parameters = ISO18571_PARAMETERS,
    *,
    max_cells: int = EXACT_DTW_CELLS,
) -> Iso18571Rating:
    """ISO/TS 18571 rating of ``simulated`` against ``reference`` (one grid, equal length)."""
    ref, sim = _unit_scaled(
        *checked_pair(reference, simulated, metric="iso18571", min_samples=_MIN_SAMPLES)
    )
    p = parameters
    n = ref.shape[0]
    corridor = _corridor(ref, sim, p)
    shift = _phase_shift(ref, sim, p.phase_limit)
    phase = _ramp(abs(shift), n * p.phase_limit, p.phase_exponent)
    # A negative shift: the simulation lags, its later samples meet the reference's earlier ones.
    if shift < 0:
        ref_s, sim_s = ref[: n + shift], sim[-shift:]
    elif shift > 0:
        ref_s, sim_s = ref[shift:], sim[: n - shift]
    else:
        ref_s, sim_s = ref, sim
    m = ref_s.shape[0]
    if m < _SLOPE_AVERAGE:
        raise degenerate(
            "iso18571",
            f"the curves overlap in {m} samples after the phase shift, fewer than the "
            f"{_SLOPE_AVERAGE} of the slope's moving average",
            "compare longer curves",
        )
    band = max(0, math.ceil(p.warping_window * m) - 1)
    banded = m * (2 * band + 1) > max_cells
    if banded:
        band = max(1, (max_cells // m - 1) // 2)
    magnitude_error = _warped_magnitude_error(sim_s, ref_s, band)
    magnitude = _ramp(magnitude_error, p.magnitude_limit, p.magnitude_exponent)
    slope_error = _slope_error(ref_s, sim_s)
    slope = _ramp(slope_error, p.slope_limit, 1.0)
    rating = (
        p.weight_corridor * corridor
        + p.weight_phase * phase
        + p.weight_magnitude * magnitude
        + p.weight_slope * slope
    )
    return Iso18571Rating(
        rating=float(min(1.0, max(0.0, rating))),
        corridor=corridor,
        phase=phase,
        magnitude=magnitude,
        slope=slope,
        shift=shift,
        magnitude_error=magnitude_error,
        slope_error=slope_error,
        band=band,
        banded=banded,
    )


def iso18571_characteristic(
    reference: FloatArray, simulated: FloatArray, dt: float
) -> CharacteristicValue:
    """The registry's ``iso18571``: the rating, its four scores and the shift in seconds."""
    r = iso18571_rating(reference, simulated)
    return CharacteristicValue(
        r.rating,
        {
            "corridor": r.corridor,
            "phase": r.phase,
            "magnitude": r.magnitude,
            "slope": r.slope,
            "shift_s": r.shift * dt,
            "magnitude_error": r.magnitude_error,
            "slope_error": r.slope_error,
            "banded": float(r.banded),
        },
    )


def _unit_scaled(ref: FloatArray, sim: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Both curves times the one power of two that brings the larger peak into [0.5, 1).

    Every score is a ratio and a power of two changes no significand, so no score moves; but
    the arithmetic then runs on the same numbers for a pair in any unit a power of two apart,
    so the rating is the same bits. Values of at most 1 keep every square and sum finite
    (squares of 1e200 overflow, those of 1e-300 vanish, which broke the warping and moved the
    phase shift); the larger peak rather than the reference's keeps them so when the
    simulation is far above the reference. Refused when the reference would then fall below
    the normal floats: its values would lose bits.
    """
    ref_peak = float(np.max(np.abs(ref)))
    exponent = power_of_two_exponent(max(ref_peak, float(np.max(np.abs(sim)))))
    if math.ldexp(ref_peak, exponent) < sys.float_info.min:
        raise degenerate(
            "iso18571",
            "the signals' magnitudes differ by a factor beyond the float range",
            "check the model output's column and scale",
        )
    return np.ldexp(ref, exponent), np.ldexp(sim, exponent)


def _ramp(error: float, limit: float, exponent: float) -> float:
    """The standard's score of an error: 1 at 0, 0 from ``limit`` on, ((ε_lim − ε)/ε_lim)^k."""
    if error <= 0.0:
        return 1.0
    if error >= limit:
        return 0.0
    return float(((limit - error) / limit) ** exponent)


def _corridor(ref: FloatArray, sim: FloatArray, p: Iso18571Parameters) -> float:
    peak = float(np.max(np.abs(ref)))
    inner = p.inner_corridor * peak
    outer = p.outer_corridor * peak
    deviation = np.abs(ref - sim)
    scores = np.clip((outer - deviation) / (outer - inner), 0.0, None) ** p.corridor_exponent
    scores[deviation < inner] = 1.0
    scores[deviation > outer] = 0.0
    return float(np.mean(scores))


def _phase_shift(ref: FloatArray, sim: FloatArray, phase_limit: float) -> int:
    """The shift of ``sim`` (samples; negative = sim lags) with the highest overlap correlation."""
    n = ref.shape[0]
    shifts = math.floor(n * phase_limit) + 1
    # Pearson's r is the same for each curve in its own unit: scaled apart, neither one's
    # squares underflow where the other is far larger.
    x = _centred_unit(ref)
    y = _centred_unit(sim)
    cross = sps.correlate(y, x, mode="full", method="fft" if n > 256 else "direct")
    m = np.arange(1, shifts)
    # left[m]: ref[:n-m] against sim[m:]; right[m]: ref[m:] against sim[:n-m].
    left = _overlap_correlation(x, y, m, cross[n - 1 + m], from_start=True)
    right = _overlap_correlation(x, y, m, cross[n - 1 - m], from_start=False)
    zero = _overlap_correlation(x, y, np.zeros(1, dtype=np.int64), cross[n - 1 : n], True)[0]
    if not math.isfinite(zero):
        # Nothing correlates with a constant simulation: no shift (as the standard's loop ends).
        return 0
    candidates = np.empty(2 * (shifts - 1) + 1)
    candidates[0] = zero
    candidates[1::2] = left
    candidates[2::2] = right
    candidates[~np.isfinite(candidates)] = -np.inf
    best = int(np.argmax(candidates >= candidates.max() - _CORRELATION_TIE))
    if best == 0:
        return 0
    lag = (best + 1) // 2
    return -lag if best % 2 == 1 else lag


def _centred_unit(values: FloatArray) -> FloatArray:
    """``values`` minus their mean, scaled by a power of two to a peak in [0.5, 1)."""
    centred = values - values.mean()
    return np.asarray(
        np.ldexp(centred, power_of_two_exponent(float(np.max(np.abs(centred))))), np.float64
    )


def _overlap_correlation(
    x: FloatArray, y: FloatArray, m: np.ndarray, cross: FloatArray, from_start: bool
) -> FloatArray:
    """Pearson's r of x and y overlapping after shifting one by each of ``m`` samples."""
    n = x.shape[0]
    px = np.concatenate(([0.0], np.cumsum(x)))
    py = np.concatenate(([0.0], np.cumsum(y)))
    pxx = np.concatenate(([0.0], np.cumsum(x * x)))
    pyy = np.concatenate(([0.0], np.cumsum(y * y)))
    length = n - m
    if from_start:  # x[0 : n-m], y[m : n]
        sx, sxx = px[n - m], pxx[n - m]
        sy, syy = py[n] - py[m], pyy[n] - pyy[m]
    else:  # x[m : n], y[0 : n-m]
        sx, sxx = px[n] - px[m], pxx[n] - pxx[m]
        sy, syy = py[n - m], pyy[n - m]
    cov = cross - sx * sy / length
    var_x = sxx - sx * sx / length
    var_y = syy - sy * sy / length
    with np.errstate(invalid="ignore", divide="ignore"):
        r = cov / np.sqrt(var_x * var_y)
    r[(var_x <= 0) | (var_y <= 0)] = np.nan
    return np.asarray(r, dtype=np.float64)


def _warped_magnitude_error(x: FloatArray, y: FloatArray, band: int) -> float:
    """ε_mag = ‖x_w − y_w‖₁ / ‖y_w‖₁ along the DTW path of x (rows) onto y (columns)."""
    rows, cols = _dtw_path(x, y, band)
    return _relative_l1(x[rows], y[cols], "the shifted reference is zero everywhere")


def _relative_l1(candidate: FloatArray, reference: FloatArray, when_zero: str) -> float:
    """‖candidate − reference‖₁ / ‖reference‖₁, the form of ε_mag and ε_slope."""
    norm = float(np.sum(np.abs(reference)))
    if norm == 0.0:
        raise degenerate(
            "iso18571", f"{when_zero}, so the error is undefined", "compare a signal that varies"
        )
    return float(np.sum(np.abs(candidate - reference))) / norm


def _dtw_path(x: FloatArray, y: FloatArray, band: int) -> tuple[np.ndarray, np.ndarray]:
    """The minimal warping path of x onto y with |i − j| ≤ band, from (0, 0) to (n−1, n−1).

    D[i, j] = (x_i − y_j)² + min(D[i−1, j], D[i, j−1], D[i−1, j−1]), ties going up, then left,
    then diagonal (as dtwalign backtracks). Equal-cost paths are common (piecewise-constant or
    quantised curves), so which one wins must not depend on round-off: both paths evaluate
    every cell as this one sum of two floats, so their D, steps and path are the same bits.
    With the ``fast`` extra, bands the kernel takes
    (:func:`~pytest_hevval.core.kernel.kernel_for`, counted in cells) run as one compiled loop
    row by row. The numpy path runs along anti-diagonals instead (d = i + j): a cell needs only
    the two diagonals before it, so each diagonal is three vector operations. Memory: one byte
    per band cell.
    """
    n = x.shape[0]
    # A wider band allows nothing more, and the diagonals below would only grow.
    band = min(band, n - 1)
    compiled = kernel.kernel_for(n * (2 * band + 1), ("dtw_path",))
    if compiled is not None:
        return kernel.dtw_path(compiled, x, y, band)
    choice = _dtw_steps(x, y, band)
    i = j = n - 1
    path_rows = [i]
    path_cols = [j]
    while i or j:
        if i and j:
            d = i + j
            move = choice.item(d, (i - j + band - ((d + band) & 1)) >> 1)
        else:
            move = 1 if i == 0 else 0
        if move == 0:
            i -= 1
        elif move == 1:
            j -= 1
        else:
            i -= 1
            j -= 1
        path_rows.append(i)
        path_cols.append(j)
    return np.asarray(path_rows[::-1]), np.asarray(path_cols[::-1])


def _dtw_steps(x: FloatArray, y: FloatArray, band: int) -> npt.NDArray[np.int8]:
    """The backtracking step of every band cell (0 up, 1 left, 2 diagonal) by anti-diagonal.

    Cell s of diagonal d is (i, j) with i + j = d and i − j + band = 2s + p, p the parity of
    d + band: a diagonal holds band + 1 cells (the last one off the band when p = 1). Its
    up, left and diagonal neighbours are cells s − 1 + p, s + p of diagonal d − 1 and s of
    d − 2, so a diagonal is two minima and one sum over contiguous slices.
    """
    n = x.shape[0]
    cells = band + 1
    diagonals = 2 * n - 1
    choice = np.empty((diagonals, cells), dtype=np.int8)
    # Off the grid x is +inf and y −inf, so the cost there is +inf and no NaN can arise: such
    # cells, like those off the band, keep D = +inf as the compiled loop's padding does.
    pad = band + 1
    xs = np.concatenate((np.full(pad, np.inf), x, np.full(pad, np.inf)))
    ys = np.concatenate((np.full(pad, -np.inf), y, np.full(pad, -np.inf)))[::-1].copy()
    x_windows = np.lib.stride_tricks.sliding_window_view(xs, cells)
    y_windows = np.lib.stride_tricks.sliding_window_view(ys, cells)
    # One block for short curves; else blocks of an even number of diagonals, so that every
    # block starts on an even diagonal and reads and writes the same views of ``rows``.
    block = min(_DTW_BLOCK, diagonals)
    # Row r + 2 holds diagonal first + r, cell s at column s + 1 with +inf on both sides; rows
    # 0 and 1 are the two diagonals before the block. A row holds its cells' costs until D
    # replaces them.
    rows = np.full((block + 2, cells + 2), np.inf)
    # The path starts at (0, 0): its diagonal neighbour (−1, −1) costs 0, so D[0, 0] is its
    # cost plus 0, as in the compiled loop.
    rows[0, 1 + band // 2] = 0.0
    nearer = np.empty((block, cells))  # min(up, left), kept for choosing the steps
    best = np.empty(cells)
    # Made once, these views spare the loop (two diagonals per sample) their slicing.
    recurrence = []
    for r in range(block):
        p = (r + band) & 1
        previous, here = rows[r + 1], rows[r + 2, 1:-1]
        recurrence.append(
            (
                previous[p : p + cells],
                previous[p + 1 : p + 1 + cells],
                nearer[r],
                rows[r, 1:-1],
                here,
            )
        )
    for first in range(0, diagonals, block):
        last = min(diagonals, first + block)
        count = last - first
        costs = rows[2 : count + 2, 1:-1]
        for start in (0, 1):
            # Cell s of diagonal d pairs x[(d − band + 1) // 2 + s] with y[(d + band) // 2 − s]:
            # from one diagonal to the next of its parity, x moves one sample on and y one back.
            d = first + start
            k = (count - start + 1) // 2
            xi = pad + (d - band + 1) // 2
            yi = n + pad - 1 - (d + band) // 2
            np.subtract(
                x_windows[xi : xi + k], y_windows[yi - k + 1 : yi + 1][::-1], out=costs[start::2]
            )
        np.square(costs, out=costs)
        costs[(first + band + 1) & 1 :: 2, band] = np.inf  # off the band where p = 1
        for up, left, upleft, diagonal, here in recurrence[:count]:
            np.minimum(up, left, out=upleft)
            np.minimum(upleft, diagonal, out=best)
            np.add(here, best, out=here)
        for start in (0, 1):
            p = (first + start + band) & 1
            previous = rows[start + 1 : count + 1 : 2]
            steps = choice[first + start : last : 2]
            np.less(previous[:, p + 1 : p + 1 + cells], previous[:, p : p + cells], out=steps)
            np.copyto(steps, 2, where=rows[start:count:2, 1:-1] < nearer[start:count:2])
        rows[:2] = rows[count : count + 2]
    return choice


def _smoothed_slope(values: FloatArray) -> FloatArray:
    """Central differences averaged over nine samples (1, 3, 5, 7 at the ends), per sample."""
    derivative = np.gradient(values)
    smoothed = np.empty_like(derivative)
    for index, count in enumerate((1, 3, 5, 7)):
        smoothed[index] = derivative[:count].mean()
        smoothed[-index - 1] = derivative[-count:].mean()
    smoothed[4:-4] = np.convolve(derivative, np.ones(9) / 9, mode="valid")
    return smoothed


def _slope_error(ref: FloatArray, sim: FloatArray) -> float:
    return _relative_l1(
        _smoothed_slope(sim), _smoothed_slope(ref), "the shifted reference has no slope"
    )
