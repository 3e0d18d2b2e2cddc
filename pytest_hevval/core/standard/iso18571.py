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

Long records: the warping band holds about N²/5 cells. Up to :data:`EXACT_DTW_CELLS` cells the
band is the standard's; beyond it the band is narrowed to fit (``banded`` = 1 in the
components) — the measured deviation is in docs/metrics.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal as sps

from ..registry import CharacteristicValue
from ._inputs import FloatArray, checked_pair, degenerate

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
# Rows of the warping band held as float64 at once (their backtracking steps are then chosen
# together): 256 rows of a 4,000-sample band are 1.6 MB.
_DTW_BLOCK = 256


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
    ref, sim = checked_pair(reference, simulated, metric="iso18571", min_samples=_MIN_SAMPLES)
    p = parameters
    n = ref.shape[0]
    corridor = _corridor(ref, sim, p)
    shift = _phase_shift(ref, sim, p.phase_limit)
    limit = n * round(p.phase_limit, 2)
    if shift == 0:
        phase = 1.0
    elif abs(shift) >= limit:
        phase = 0.0
    else:
        phase = ((limit - abs(shift)) / limit) ** p.phase_exponent
    # A negative shift: the simulation lags, its later samples meet the reference's earlier ones.
    if shift < 0:
        ref_s, sim_s = ref[: n + shift], sim[-shift:]
    elif shift > 0:
        ref_s, sim_s = ref[shift:], sim[: n - shift]
    else:
        ref_s, sim_s = ref, sim
    m = ref_s.shape[0]
    band = max(0, math.ceil(p.warping_window * m) - 1)
    banded = m * (2 * band + 1) > max_cells
    if banded:
        band = max(1, (max_cells // m - 1) // 2)
    magnitude_error = _warped_magnitude_error(sim_s, ref_s, band)
    if magnitude_error == 0.0:
        magnitude = 1.0
    elif magnitude_error > p.magnitude_limit:
        magnitude = 0.0
    else:
        magnitude = ((p.magnitude_limit - magnitude_error) / p.magnitude_limit) ** (
            p.magnitude_exponent
        )
    slope_error = _slope_error(ref_s, sim_s)
    if slope_error <= 0.0:
        slope = 1.0
    elif slope_error >= p.slope_limit:
        slope = 0.0
    else:
        slope = (p.slope_limit - slope_error) / p.slope_limit
    rating = (
        p.weight_corridor * corridor
        + p.weight_phase * phase
        + p.weight_magnitude * magnitude
        + p.weight_slope * slope
    )
    return Iso18571Rating(
        rating=float(min(1.0, max(0.0, rating))),
        corridor=corridor,
        phase=float(phase),
        magnitude=float(magnitude),
        slope=float(slope),
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
    shifts = math.floor(n * round(phase_limit, 2)) + 1
    x = ref - ref.mean()
    y = sim - sim.mean()
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

    D[i, j] = (x_i − y_j)² + min(D[i−1, j], D[i, j−1], D[i−1, j−1]). Within a row the
    left-neighbour term is a running minimum: with A_j = c_j + min(D[i−1, j], D[i−1, j−1]) and
    S the row's cumulative cost, D[i, j] = S_j + min_{k ≤ j}(A_k − S_k), so each row is a few
    vector operations. Rows are kept in band coordinates (k = j − i + band) a block at a time;
    the backtracking steps of a whole block are then chosen at once, ties going up, then left,
    then diagonal (as dtwalign backtracks). Memory: one byte per band cell.
    """
    n = x.shape[0]
    width = 2 * band + 1
    choice = np.empty((n, width), dtype=np.int8)
    # Row r of the block sits at rows[r + 1], band cell k at column k + 1, with inf padding on
    # both sides; rows[0] is the last row of the previous block.
    rows = np.full((_DTW_BLOCK + 1, width + 2), np.inf)
    # Band cell k of row i pairs x_i with y_{i+k−band}; cells off the grid cost 0 and are
    # never written, so a row's prefix sums over the whole band equal those over its cells.
    padded = np.concatenate((np.full(band, np.nan), y, np.full(band, np.nan)))
    windows = np.lib.stride_tricks.sliding_window_view(padded, width)
    for first in range(0, n, _DTW_BLOCK):
        last = min(n, first + _DTW_BLOCK)
        cost = np.subtract(x[first:last, None], windows[first:last])
        np.square(cost, out=cost)
        cost[np.isnan(cost)] = 0.0
        total = np.cumsum(cost, axis=1)
        before = total - cost  # Σ of the row's costs left of each cell
        for i in range(first, last):
            lo = max(0, band - i)
            hi = min(width, n - i + band)
            r = i - first
            previous = rows[r]
            reach = np.minimum(previous[lo + 2 : hi + 2], previous[lo + 1 : hi + 1])
            if i == 0:
                reach[0] = 0.0
            reach -= before[r, lo:hi]
            np.minimum.accumulate(reach, out=reach)
            np.add(reach, total[r, lo:hi], out=rows[r + 1, lo + 1 : hi + 1])
        count = last - first
        up = rows[:count, 2:]
        diagonal = rows[:count, 1:-1]
        left = rows[1 : count + 1, :-2]
        step = np.where(left < up, np.int8(1), np.int8(0))
        step[diagonal < np.minimum(up, left)] = 2
        choice[first:last] = step
        rows[0] = rows[count]
        rows[1:] = np.inf
    i = j = n - 1
    path_rows = [i]
    path_cols = [j]
    while i or j:
        move = choice.item(i, j - i + band) if i and j else (1 if i == 0 else 0)
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
