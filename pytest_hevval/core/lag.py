"""Lead/lag search: the argmax of the mean-removed cross-correlation within ±max_lag samples.

Convention (MATLAB ``xcorr(ref, sim)``): C(m) = Σ_n (ref[n+m] − μ_ref)(sim[n] − μ_sim). If the
simulated signal is the reference delayed by d samples, the peak is at m = −d: a negative lag
means the simulation lags the measurement.

The sum runs over the fixed window n ∈ [L, N − L) for every lag |m| ≤ L (L = max_lag, at most
N/4). A sum over each lag's whole overlap tapers with |m| and pulls the peak toward 0, which on
a short or nonzero-mean record can move it by a sample or more; a fixed window compares the
same simulated samples at every lag and has no such bias.

Short records are searched exactly with one FFT. Long records (10^8 samples) would need an FFT
far larger than the data, so they are searched coarse-to-fine: block means by 4, 16, 64, …
smooth the correlation without moving its peak; the coarsest level is searched exactly over
the whole ±max_lag window and each finer level only a few samples around the scaled-up
estimate, ending with a window of exact correlations at full resolution. Cost: one extra read
of both arrays plus a handful of in-cache dot products per sample.

What the search maximises is reported with the lag, as a coefficient: ρ(m) = C(m) /
√(E_ref(m)·E_sim), the mean-removed correlation of the simulation's fixed window with the
reference shifted by m (E_ref(m) and E_sim the centred energies of the two windows), clipped to
[0, 1]. Its value at the lag and at zero lag are the one pair of correlations every output
prints beside the lag; the lag is never one where ρ is below ρ(0).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from . import kernel
from .sums import _coefficient

__all__ = [
    "LagSearch",
    "correlation_curve",
    "dot_overlap",
    "search_lag",
    "window_correlations",
]

FloatArray = npt.NDArray[np.floating]

# Records up to this length are searched exactly with one FFT.
_EXACT_LIMIT = 1 << 18
# The coarsest pyramid level is at most this long, so its exact FFT search is cheap.
_COARSEST = 1 << 15
_FACTOR = 4
# Half-width of the refinement window at each finer level, in that level's samples. The peak
# of the block-mean correlation lies within ±(factor − 1) of the true peak scaled down; two
# more on each side absorb plateaus and rounding.
_REFINE = _FACTOR + 2
# Samples per chunk of the streamed loops (a multiple of _BLAS_PIECE): large enough to amortise
# numpy's per-call overhead, which measured heavier than spilling from L2 into L3.
_CHUNK = 1 << 17


@dataclass(frozen=True)
class LagSearch:
    """Where the mean-removed cross-correlation peaks, how that was found, and its value there.

    ``correlation`` is ρ(lag) and ``zero_lag_correlation`` ρ(0), the coefficient the search
    maximises (module docstring); ``correlation ≥ zero_lag_correlation`` always.
    """

    lag: int
    max_lag: int
    method: Literal["none", "fft", "pyramid"]
    levels: int = 1
    correlation: float = math.nan
    zero_lag_correlation: float = math.nan

    @property
    def at_bound(self) -> bool:
        """The lag lies on the edge of the ±max_lag search, so the peak may lie beyond it."""
        return self.max_lag > 0 and abs(self.lag) >= self.max_lag


# OpenBLAS runs ddot on its own worker threads above 10 000 elements and dgemv above 9 216.
# Those threads spin while waiting; next to this module's two threads on a two-core machine
# they made a 32 768-element dot about 30 times slower than on one thread. Every BLAS call here
# therefore stays at or below this many elements, batching the pieces into one matmul call.
_BLAS_PIECE = 8192


def _dot(a: npt.NDArray[np.float64], b: npt.NDArray[np.float64]) -> float:
    """Σ a·b for float64 vectors of any length, with single-threaded BLAS calls."""
    n = a.shape[0]
    if n <= _BLAS_PIECE:
        return float(np.dot(a, b))
    pieces, rest = divmod(n, _BLAS_PIECE)
    whole = n - rest
    head = np.matmul(
        a[:whole].reshape(pieces, 1, _BLAS_PIECE), b[:whole].reshape(pieces, _BLAS_PIECE, 1)
    )
    # A Python sum of a few floats costs less than numpy's reduction machinery.
    total: float = sum(head.ravel().tolist())
    if rest:
        total += float(np.dot(a[whole:], b[whole:]))
    return total


# Samples per row in _lagged_dots_by_rows; it handles up to _ROW + 1 lags at once.
_ROW = 16


def _lagged_dots_by_rows(
    rw: npt.NDArray[np.float64], sc: npt.NDArray[np.float64], count: int, pieces: int
) -> list[float]:
    """:func:`_lagged_dots` for ``pieces`` whole BLAS pieces, as two small matrix products.

    With both signals laid out in rows of _ROW samples, G[c, u] = Σ_t rw[t·_ROW + c]·sc[t·_ROW + u]
    holds every product a lag below _ROW needs, and C(i) = Σ_u G[i + u, u] sums a diagonal. The
    two products per piece (rows c < _ROW, and the count − 1 rows beyond) cost about as much
    as 1.5 dot products while replacing ``count`` of them.
    """
    rows = _BLAS_PIECE // _ROW
    step = rw.strides[0]
    strides = (step * _BLAS_PIECE, step * _ROW, step)
    near = np.lib.stride_tricks.as_strided(
        rw, shape=(pieces, rows, _ROW), strides=strides, writeable=False
    )
    far = np.lib.stride_tricks.as_strided(
        rw[_ROW:], shape=(pieces, rows, count - 1), strides=strides, writeable=False
    )
    s_rows = sc.reshape(pieces, rows, _ROW)
    g = np.concatenate(
        (
            np.add.reduce(np.matmul(near.transpose(0, 2, 1), s_rows), axis=0),
            np.add.reduce(np.matmul(far.transpose(0, 2, 1), s_rows), axis=0),
        )
    )
    diagonals = np.lib.stride_tricks.as_strided(
        g, shape=(count, _ROW), strides=(g.strides[0], g.strides[0] + g.strides[1]), writeable=False
    )
    totals: list[float] = np.add.reduce(diagonals, axis=1).tolist()
    return totals


class _WindowKernel:
    """One thread's buffers for :func:`_exact_window`, with the strided views over them.

    The views are made once: numpy's as_strided costs several microseconds a call, as much
    as the arithmetic on a chunk, and the buffers are refilled in place for every chunk.
    """

    def __init__(self, count: int) -> None:
        self.count = count
        self.s_buf = np.empty(_CHUNK, dtype=np.float64)
        self.r_buf = np.empty(_CHUNK + count - 1, dtype=np.float64)
        self.by_rows = count <= _ROW + 1
        if not self.by_rows:
            return
        pieces = _CHUNK // _BLAS_PIECE
        rows = _BLAS_PIECE // _ROW
        step = self.r_buf.strides[0]
        strides = (step * _BLAS_PIECE, step * _ROW, step)
        as_strided = np.lib.stride_tricks.as_strided
        self.near = as_strided(
            self.r_buf, shape=(pieces, rows, _ROW), strides=strides, writeable=False
        ).transpose(0, 2, 1)
        self.far = as_strided(
            self.r_buf[_ROW:], shape=(pieces, rows, count - 1), strides=strides, writeable=False
        ).transpose(0, 2, 1)
        self.s_rows = self.s_buf.reshape(pieces, rows, _ROW)
        self.g_near = np.empty((pieces, _ROW, _ROW), dtype=np.float64)
        self.g_far = np.empty((pieces, count - 1, _ROW), dtype=np.float64)
        self.g = np.empty((_ROW + count - 1, _ROW), dtype=np.float64)
        self.diagonals = as_strided(
            self.g,
            shape=(count, _ROW),
            strides=(self.g.strides[0], self.g.strides[0] + self.g.strides[1]),
            writeable=False,
        )

    def full_chunk(self) -> list[float]:
        """:func:`_lagged_dots` of the whole buffers (a chunk of exactly _CHUNK samples)."""
        if not self.by_rows:
            return _lagged_dots(self.r_buf, self.s_buf, self.count)
        np.matmul(self.near, self.s_rows, out=self.g_near)
        np.matmul(self.far, self.s_rows, out=self.g_far)
        np.add.reduce(self.g_near, axis=0, out=self.g[:_ROW])
        np.add.reduce(self.g_far, axis=0, out=self.g[_ROW:])
        totals: list[float] = np.add.reduce(self.diagonals, axis=1).tolist()
        return totals


def _lagged_dots(
    rw: npt.NDArray[np.float64], sc: npt.NDArray[np.float64], count: int
) -> list[float]:
    """[Σ rw[i : i + w]·sc for i in range(count)] with w = len(sc), rw contiguous.

    One batched matmul over a strided view computes every lag and every BLAS-sized piece,
    where a loop of dot calls would pay numpy's call overhead count × pieces times.
    """
    width = sc.shape[0]
    pieces, rest = divmod(width, _BLAS_PIECE)
    whole = width - rest
    totals = [0.0] * count
    if pieces and count <= _ROW + 1:
        totals = _lagged_dots_by_rows(rw, sc[:whole], count, pieces)
    elif pieces:
        step = rw.strides[0]
        lagged = np.lib.stride_tricks.as_strided(
            rw,
            shape=(count, pieces, 1, _BLAS_PIECE),
            strides=(step, step * _BLAS_PIECE, step * _BLAS_PIECE, step),
            writeable=False,
        )
        products = np.matmul(lagged, sc[:whole].reshape(pieces, _BLAS_PIECE, 1))
        totals = np.add.reduce(products.reshape(count, pieces), axis=1).tolist()
    if rest:
        tail = sc[whole:]
        for i in range(count):
            totals[i] += float(np.dot(rw[i + whole : i + width], tail))
    return totals


def dot_overlap(a: FloatArray, b: FloatArray, scale: float = 1.0) -> float:
    """Σ a·b accumulated in float64, in cache-sized chunks for float32 or rescaled input."""
    total = 0.0
    for start in range(0, a.shape[0], _CHUNK):
        x = np.asarray(a[start : start + _CHUNK], dtype=np.float64)
        y = np.asarray(b[start : start + _CHUNK], dtype=np.float64)
        if scale != 1.0:
            x = x * scale
            y = y * scale
        total += _dot(x, y)
    return total


def _centred(x: FloatArray, mean: float, scale: float) -> npt.NDArray[np.float64]:
    out = np.asarray(x, dtype=np.float64) - mean
    if scale != 1.0:
        out *= scale
    return out


def _centre_into(
    x: FloatArray, mean: float, scale: float, out: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """(x − mean)·scale written into ``out``; float32 input is promoted before subtracting."""
    np.subtract(x, mean, out=out, dtype=np.float64)
    if scale != 1.0:
        np.multiply(out, scale, out=out)
    return out


#: Long records are summed in this many contiguous parts, one per thread at most.
PARTS = 2


def _split(spans: list[tuple[int, int]], workers: int) -> list[list[tuple[int, int]]]:
    """Contiguous runs of spans, one per worker, so each thread streams its own region."""
    per = math.ceil(len(spans) / max(1, workers))
    return [spans[i : i + per] for i in range(0, len(spans), per)]


def _exact_window(
    r: FloatArray,
    s: FloatArray,
    lo: int,
    hi: int,
    r_mean: float,
    s_mean: float,
    scale: float,
    workers: int,
    half: int,
) -> tuple[npt.NDArray[np.float64], float]:
    """C(m) for every m in [lo, hi] ⊂ [−half, half], over the fixed window [half, n − half).

    Also returns Σ ((r[j] − μ)·scale)² over j in [half + lo, n − half + lo): those samples pass
    through the centred buffers anyway, so the reference energy costs one in-cache dot per
    chunk instead of another read of the record.
    """
    n = r.shape[0]
    count = hi - lo + 1
    out = np.zeros(count + 1, dtype=np.float64)
    # Every lag compares the same samples of the simulation, so no lag is favoured by a
    # longer overlap, and every index stays inside both records.
    core_lo = half
    core_hi = n - half
    compiled = kernel.kernel_for(n) if kernel.accepts(r, s) else None
    if compiled is not None and core_hi > core_lo:
        out = kernel.lag_window(
            compiled, r, s, lo, count, r_mean, s_mean, scale, (core_lo, core_hi), workers
        )
    elif core_hi > core_lo:
        bounds = [*range(core_lo, core_hi, _CHUNK), core_hi]
        spans = list(itertools.pairwise(bounds))

        def run(part: list[tuple[int, int]]) -> npt.NDArray[np.float64]:
            acc = [0.0] * (count + 1)
            kernel = _WindowKernel(count)
            for a, b in part:
                width = b - a
                sc = _centre_into(s[a:b], s_mean, scale, kernel.s_buf[:width])
                rw = _centre_into(
                    r[a + lo : b + hi], r_mean, scale, kernel.r_buf[: width + count - 1]
                )
                values = kernel.full_chunk() if width == _CHUNK else _lagged_dots(rw, sc, count)
                for i, value in enumerate(values):
                    acc[i] += value
                acc[count] += _dot(rw[:width], rw[:width])
            return np.array(acc, dtype=np.float64)

        # Always the same split and summing order, whatever the thread count, so that the
        # result is bit-identical on any machine.
        parts = _split(spans, PARTS) if len(spans) > 8 else [spans]
        if workers > 1 and len(parts) > 1:
            with ThreadPoolExecutor(max_workers=min(workers, len(parts))) as pool:
                partials = list(pool.map(run, parts))
        else:
            partials = [run(part) for part in parts]
        for partial in partials:
            out += partial
    return out[:count], float(out[count])


def _block_means(x: FloatArray, factor: int) -> npt.NDArray[np.float64]:
    """Means of consecutive blocks of ``factor`` samples (a trailing partial block is dropped)."""
    blocks = x.shape[0] // factor
    out = np.empty(blocks, dtype=np.float64)
    # A matrix-vector product with equal weights is the fastest block mean numpy offers: a
    # reduction along a short axis (reshape(...).mean(axis=1)) is about eight times slower.
    # Each product is a batch of dgemv calls of at most _BLAS_PIECE elements (see there).
    if factor > _BLAS_PIECE // 4:
        # Long blocks reduce quickly along their own contiguous axis.
        per = max(1, (_CHUNK * 4) // factor)
        for first in range(0, blocks, per):
            last = min(first + per, blocks)
            chunk = np.asarray(x[first * factor : last * factor], dtype=np.float64)
            np.mean(chunk.reshape(-1, factor), axis=1, out=out[first:last])
        return out
    weights = np.full(factor, 1.0 / factor, dtype=np.float64)
    rows = _BLAS_PIECE // factor
    per = rows * max(1, (_CHUNK * 4) // _BLAS_PIECE)
    for first in range(0, blocks, per):
        last = min(first + per, blocks)
        chunk = np.asarray(x[first * factor : last * factor], dtype=np.float64)
        batches = (last - first) // rows
        split = first + batches * rows
        if batches:
            np.matmul(
                chunk[: batches * rows * factor].reshape(batches, rows, factor),
                weights,
                out=out[first:split].reshape(batches, rows),
            )
        if split < last:
            np.matmul(
                chunk[batches * rows * factor :].reshape(-1, factor), weights, out=out[split:last]
            )
    return out


def _quarter_level(x: FloatArray, workers: int) -> npt.NDArray[np.float64]:
    """Block means by 4 (a trailing partial block dropped): the next level of the pyramid.

    ((a + b) + (c + d))·0.25 per block, the arithmetic of the main pass's first two levels, on
    both paths alike, so the compiled and numpy pyramids are bit-identical.
    """
    blocks = x.shape[0] // _FACTOR
    compiled = kernel.kernel_for(x.shape[0], ("quarter_level",)) if kernel.accepts(x) else None
    if compiled is not None:
        return kernel.quarter_level(compiled, x, workers)
    out = np.empty(blocks, dtype=np.float64)
    step = _CHUNK * _FACTOR
    for first in range(0, blocks * _FACTOR, step):
        last = min(first + step, blocks * _FACTOR)
        chunk = np.asarray(x[first:last], dtype=np.float64)
        pairs = np.add(chunk[0::2], chunk[1::2])
        part = out[first // _FACTOR : last // _FACTOR]
        np.add(pairs[0::2], pairs[1::2], out=part)
        np.multiply(part, 0.25, out=part)
    return out


def _centred_energy(x: FloatArray, mean: float, scale: float, lo: int, hi: int) -> float:
    """Σ ((x[j] − mean)·scale)² over j in [lo, hi), in cache-sized chunks."""
    total = 0.0
    for start in range(max(lo, 0), hi, _CHUNK):
        part = _centred(x[start : min(start + _CHUNK, hi)], mean, scale)
        total += _dot(part, part)
    return total


def _window_energy(
    r: FloatArray, r_mean: float, scale: float, half: int, lo: int, hi: int, total: float
) -> npt.NDArray[np.float64]:
    """E(m) = Σ (r[j] − μ)² over the reference window [half + m, n − half + m), m in [lo, hi].

    Built from the whole-record energy minus the two short ends, so only about 2·half samples
    are read however long the record is.
    """
    n = r.shape[0]
    head = _centred(r[: half + hi], r_mean, scale)
    tail = _centred(r[n - half + lo :], r_mean, scale)
    head_cum = np.concatenate(([0.0], np.cumsum(head * head)))
    tail_cum = np.concatenate(([0.0], np.cumsum((tail * tail)[::-1])))
    lags = np.arange(lo, hi + 1)
    before = head_cum[half + lags]  # Σ over j < half + m
    after = tail_cum[half - lags]  # Σ over j ≥ n − half + m
    return np.maximum(total - before - after, 0.0)


def _best(values: npt.NDArray[np.float64], energy: npt.NDArray[np.float64], lo: int) -> int:
    """Lag of the largest C(m)/√E(m); near-ties (1e-12) go to the lag closest to zero.

    Dividing by the reference energy in each lag's window makes the correlation a cosine
    similarity: by Cauchy–Schwarz a simulation that is an exact shift of the reference peaks
    at that shift, even when neighbouring lags differ by less than the window ends' energy.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        score = np.where(energy > 0, values / np.sqrt(energy), -np.inf)
    peak = float(np.max(score))
    if not np.isfinite(peak):
        # A constant (zero-energy) reference carries no timing: no lag is better than 0.
        lags = np.arange(lo, lo + values.shape[0])
        return int(lags[np.argmin(np.abs(lags))])
    tolerance = 1e-12 * max(abs(peak), 1e-300)
    candidates = np.flatnonzero(score >= peak - tolerance) + lo
    return int(candidates[np.argmin(np.abs(candidates))])


def _fast_length(n: int) -> int:
    """The smallest 2^a·3^b·5^c ≥ n: a length pocketfft transforms quickly."""
    best = 1 << max(0, (n - 1).bit_length())
    power5 = 1
    while power5 < best:
        power35 = power5
        while power35 < best:
            length = power35
            while length < n:
                length *= 2
            best = min(best, length)
            power35 *= 3
        power5 *= 5
    return best


def _correlate_valid(
    a: npt.NDArray[np.float64], b: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """Σ_j a[j + k]·b[j] for k in 0 … len(a) − len(b) (scipy.signal.correlate's 'valid').

    numpy's FFT, so scoring needs no scipy.signal (over a second to import): with both
    padded to at least len(a), the circular correlation does not wrap for these k.
    """
    n = a.shape[0]
    size = _fast_length(n)
    spectrum = np.fft.rfft(a, size) * np.conj(np.fft.rfft(b, size))
    valid: npt.NDArray[np.float64] = np.fft.irfft(spectrum, size)[: n - b.shape[0] + 1]
    return valid


#: A window's centred energy at most count·(this·mean)² is rounding of a constant: its
#: samples differ from their mean by less than 1e-9 of it, so it carries no timing.
_FLAT = 1e-9


def _flat_to_zero(
    energy: npt.NDArray[np.float64] | float, mean: float, count: int
) -> npt.NDArray[np.float64]:
    """``energy`` with a constant window's rounding-level energy set to 0 (see _FLAT)."""
    floor = count * (_FLAT * mean) ** 2
    values = np.asarray(energy, dtype=np.float64)
    return np.where(values <= floor, 0.0, values)


def _fft_scores(
    r: FloatArray, s: FloatArray, max_lag: int, r_mean: float, s_mean: float, scale: float
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], float]:
    """C(m) and E_ref(m) for every m in [−max_lag, max_lag] by one FFT, and E_sim."""
    rc = _centred(r, r_mean, scale)
    sc = _centred(s[max_lag : s.shape[0] - max_lag], s_mean, scale)
    # 'valid' slides the fixed simulation window over the reference: index k is lag k − max_lag.
    window = _correlate_valid(rc, sc)
    cumulative = np.concatenate(([0.0], np.cumsum(rc * rc)))
    n = r.shape[0]
    lags = np.arange(-max_lag, max_lag + 1)
    energy = cumulative[n - max_lag + lags] - cumulative[max_lag + lags]
    # A constant reference window has no timing: it is not a candidate (see _best).
    energy = _flat_to_zero(energy, r_mean * scale, n - 2 * max_lag)
    return window, energy, _dot(sc, sc)


def _fft_search(
    r: FloatArray, s: FloatArray, max_lag: int, r_mean: float, s_mean: float, scale: float
) -> int:
    window, energy, _ = _fft_scores(r, s, max_lag, r_mean, s_mean, scale)
    return _best(window, energy, -max_lag)


def _rho(
    cross: npt.NDArray[np.float64] | float,
    ref_energy: npt.NDArray[np.float64] | float,
    sim_energy: float,
    means: tuple[float, float],
    count: int,
) -> npt.NDArray[np.float64]:
    """ρ = C / √(E_ref·E_sim) clipped to [0, 1]; a constant window is one without power."""
    r = _flat_to_zero(ref_energy, means[0], count)
    s = _flat_to_zero(np.full_like(r, sim_energy), means[1], count)
    return np.asarray(_coefficient(np.asarray(cross, dtype=np.float64), r, s), dtype=np.float64)


def window_correlations(
    reference: FloatArray, simulated: FloatArray, max_lag: int
) -> npt.NDArray[np.float64]:
    """ρ(m) for m in [−max_lag, max_lag] (module docstring), exactly, by one FFT.

    ``max_lag`` is at most a quarter of the record, as in the search.
    """
    r_mean = float(np.mean(reference, dtype=np.float64))
    s_mean = float(np.mean(simulated, dtype=np.float64))
    window, energy, sim_energy = _fft_scores(reference, simulated, max_lag, r_mean, s_mean, 1.0)
    count = reference.shape[0] - 2 * max_lag
    return _rho(window, energy, sim_energy, (r_mean, s_mean), count)


def _found(
    lag: int,
    peak: tuple[float, float],
    zero: tuple[float, float],
    sim_energy: float,
    window: tuple[float, float, int],
    **how: Any,
) -> LagSearch:
    """The search's result from (C, E_ref) at the lag and at zero lag.

    ``window`` holds both means (times the search's scale) and the window's length. Should
    ρ(0) reach ρ(lag), which the exact search allows only for a constant simulated window or
    where clipping to [0, 1] makes a tie, and the pyramid's refinement could, zero lag is the
    better match and is reported.
    """
    means, count = (window[0], window[1]), window[2]
    at_lag = float(_rho(peak[0], peak[1], sim_energy, means, count))
    at_zero = float(_rho(zero[0], zero[1], sim_energy, means, count))
    if at_zero >= at_lag:
        lag, at_lag = 0, at_zero
    return LagSearch(lag=lag, correlation=at_lag, zero_lag_correlation=at_zero, **how)


def search_lag(
    reference: FloatArray,
    simulated: FloatArray,
    max_lag: int,
    *,
    ref_mean: float | None = None,
    sim_mean: float | None = None,
    scale: float = 1.0,
    workers: int = 2,
) -> LagSearch:
    """Lag (in samples) of the peak of the mean-removed cross-correlation within ±max_lag.

    The correlation at each lag is normalised by the reference energy in that lag's window;
    near-ties go to the lag closest to zero. The result carries ρ at the lag and at zero lag.
    """
    return _search(
        reference,
        simulated,
        max_lag,
        ref_mean=ref_mean,
        sim_mean=sim_mean,
        scale=scale,
        workers=workers,
    )


def _search(
    reference: FloatArray,
    simulated: FloatArray,
    max_lag: int,
    *,
    ref_mean: float | None,
    sim_mean: float | None,
    scale: float,
    workers: int,
    levels: Sequence[tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]] = (),
    ref_energy: float | None = None,
    sim_energy: float | None = None,
    co_moment: float | None = None,
) -> LagSearch:
    """:func:`search_lag`, optionally from pyramid levels a pass has already made.

    ``levels`` optionally holds the first pyramid levels (block means by 4, 16, …) of both
    signals, already made by a pass that read the data anyway, so that building the pyramid
    needs no extra read of the full records.
    ``ref_energy`` optionally gives Σ ((r − μ)·scale)² over the whole record, for the same
    reason; without it the final level reads the reference once more. ``sim_energy`` and
    ``co_moment`` (Σ ((s − μ)·scale)² and Σ (r − μ)(s − μ)·scale² over the whole record) spare
    the reads of ρ's normalisation and of its zero-lag value in the same way: only the
    2·max_lag samples outside the window are read.
    """
    n = reference.shape[0]
    # The fixed comparison window [max_lag, n − max_lag) must keep at least half the record.
    max_lag = int(max(0, min(max_lag, n // 4)))
    r_mean = float(np.mean(reference, dtype=np.float64)) if ref_mean is None else ref_mean
    s_mean = float(np.mean(simulated, dtype=np.float64)) if sim_mean is None else sim_mean
    if max_lag == 0:
        values, ref_window = _exact_window(
            reference, simulated, 0, 0, r_mean, s_mean, scale, workers, 0
        )
        zero = (float(values[0]), ref_window)
        sim_window = _centred_energy(simulated, s_mean, scale, 0, n)
        return _found(
            0, zero, zero, sim_window, (r_mean * scale, s_mean * scale, n), max_lag=0, method="none"
        )
    if n <= _EXACT_LIMIT:
        window, energy, sim_window = _fft_scores(
            reference, simulated, max_lag, r_mean, s_mean, scale
        )
        lag = _best(window, energy, -max_lag)
        at = (float(window[lag + max_lag]), float(energy[lag + max_lag]))
        zero = (float(window[max_lag]), float(energy[max_lag]))
        window_means = (r_mean * scale, s_mean * scale, n - 2 * max_lag)
        return _found(lag, at, zero, sim_window, window_means, max_lag=max_lag, method="fft")

    # Pyramid of block means: levels[k] has factor _FACTOR**k.
    refs: list[FloatArray] = [reference]
    sims: list[FloatArray] = [simulated]
    for r_level, s_level in levels:
        if refs[-1].shape[0] > _COARSEST and refs[-1].shape[0] // _FACTOR >= 16:
            refs.append(r_level)
            sims.append(s_level)
    while refs[-1].shape[0] > _COARSEST and refs[-1].shape[0] // _FACTOR >= 16:
        refs.append(_quarter_level(refs[-1], workers))
        sims.append(_quarter_level(sims[-1], workers))
    top = len(refs) - 1
    factor = _FACTOR**top
    coarse_max = min(math.ceil(max_lag / factor) + 1, refs[top].shape[0] // 4)
    best = _fft_search(refs[top], sims[top], coarse_max, r_mean, s_mean, scale)
    values = energy = np.zeros(1, dtype=np.float64)
    lo = hi = 0
    total = 0.0
    for level in range(top - 1, -1, -1):
        factor = _FACTOR**level
        level_max = math.ceil(max_lag / factor) if level else max_lag
        centre = best * _FACTOR
        lo = max(-level_max, centre - _REFINE)
        hi = min(level_max, centre + _REFINE)
        if lo > hi:  # the estimate fell outside the window: search the window's edge
            lo = hi = max(-level_max, min(level_max, centre))
        values, core_energy = _exact_window(
            refs[level], sims[level], lo, hi, r_mean, s_mean, scale, workers, level_max
        )
        if level == 0 and ref_energy is not None:
            total = ref_energy
        else:
            size = refs[level].shape[0]
            total = (
                core_energy
                + _centred_energy(refs[level], r_mean, scale, 0, level_max + lo)
                + _centred_energy(refs[level], r_mean, scale, size - level_max + lo, size)
            )
        energy = _flat_to_zero(
            _window_energy(refs[level], r_mean, scale, level_max, lo, hi, total),
            r_mean * scale,
            refs[level].shape[0] - 2 * level_max,
        )
        best = _best(values, energy, lo)
    at = (float(values[best - lo]), float(energy[best - lo]))
    ends = ((0, max_lag), (n - max_lag, n))
    if lo <= 0 <= hi:
        zero = (float(values[-lo]), float(energy[-lo]))
    elif co_moment is not None:
        # The window's sums at zero lag are the whole record's less its two ends (``total``
        # is the reference's whole centred energy, from the last level).
        cross = co_moment
        own = total
        for a, b in ends:
            rc = _centred(reference[a:b], r_mean, scale)
            cross -= _dot(rc, _centred(simulated[a:b], s_mean, scale))
            own -= _dot(rc, rc)
        zero = (cross, max(own, 0.0))
    else:
        # Zero lag lies outside the refined window: one more exact sum, over the same window.
        values, ref_window = _exact_window(
            reference, simulated, 0, 0, r_mean, s_mean, scale, workers, max_lag
        )
        zero = (float(values[0]), ref_window)
    if sim_energy is None:
        sim_window = _centred_energy(simulated, s_mean, scale, max_lag, n - max_lag)
    else:
        sim_window = sim_energy - sum(
            _centred_energy(simulated, s_mean, scale, a, b) for a, b in ends
        )
        sim_window = max(sim_window, 0.0)
    window_means = (r_mean * scale, s_mean * scale, n - 2 * max_lag)
    return _found(
        best, at, zero, sim_window, window_means, max_lag=max_lag, method="pyramid", levels=top + 1
    )


def correlation_curve(
    reference: FloatArray,
    simulated: FloatArray,
    max_lag: int,
    *,
    points: int = 401,
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]:
    """ρ(m), the coefficient the lag search maximises, at up to ``points`` lags within ±max_lag.

    For display (the paper's Fig. 5). ``max_lag`` is capped at a quarter of the record, as in
    the search. Long records and wide windows are block-averaged first (by at least the
    display step), so the curve is then ρ of the block means: the correlation smoothed over
    that step. The search's own ρ at the lag and at zero lag are exact.
    """
    n = reference.shape[0]
    max_lag = int(max(0, min(max_lag, n // 4)))
    step = max(1, math.ceil((2 * max_lag + 1) / points))
    r: FloatArray = reference
    s: FloatArray = simulated
    factor = 1
    if step > 1 or n > _EXACT_LIMIT:
        factor = max(step, math.ceil(n / _EXACT_LIMIT))
        r = _block_means(reference, factor)
        s = _block_means(simulated, factor)
    half = min(max_lag // factor, r.shape[0] // 4)
    values = window_correlations(r, s, half)
    lags = (np.arange(-half, half + 1) * factor).astype(np.int64)
    return lags, values.astype(np.float64)
