"""The six per-signal behavioural characteristics λ1–λ6 of the multi-fidelity algorithm.

Pure numpy: no files, no pytest. One aligned pair (reference, simulated) sampled every ``dt``
seconds goes in; a :class:`SignalCharacteristics` comes out.

The work is done in one streaming pass over cache-sized chunks, so a 10^8-sample pair costs
little more than reading both arrays once and needs no full-length temporaries. The lead/lag
search then refines a coarse estimate from block means down to one sample (see
:mod:`pytest_hevval.core.lag`).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from ..errors import DegenerateSignalError
from . import kernel
from .lag import _EXACT_LIMIT, PARTS, LagSearch, _dot, _search
from .registry import CHARACTERISTIC_LABELS, FUSED_CHARACTERISTICS, PAPER_CHARACTERISTICS
from .sums import Sums, lambdas_from_sums, normalised_error

__all__ = [
    "CHARACTERISTICS",
    "CHARACTERISTIC_LABELS",
    "CorrelationKind",
    "SignalCharacteristics",
    "normalised_error",
    "signal_characteristics",
]

#: The seven characteristics in paper order (λ1 … λ7) and their headings; the registry
#: describes each one.
CHARACTERISTICS: tuple[str, ...] = PAPER_CHARACTERISTICS

CorrelationKind = Literal["xcorr", "pearson"]

# Samples per chunk (a multiple of 16 and of lag._BLAS_PIECE). A chunk costs about 45 numpy
# calls of roughly a microsecond each; 2**17 samples amortise them, and measured faster than
# 2**15 although the chunk then spills from L2 (1 MiB here) into L3.
_CHUNK = 1 << 17
# Below this many samples a single vectorised pass is faster than chunking.
_SMALL = 1 << 17
# Magnitudes beyond these would overflow or underflow sums of squares; rescale by a power of 2.
_TOO_BIG = 2.0**400
_TOO_SMALL = 2.0**-400


def _number(value: Any) -> float:
    """A stored number, NaN where it is missing (``None``)."""
    return math.nan if value is None else float(value)


@dataclass(frozen=True)
class SignalCharacteristics:
    """λ1–λ6 of one signal pair, with the physical errors they are built from.

    Attributes
    ----------
    lambdas:
        (λ1, …, λ6) in paper order: lag correlation, derivative match, MAE, RMS, anomaly,
        error spread. Each lies in [0, 1]; 1 is a perfect match.
    lag_s:
        Lag of the peak of the mean-removed cross-correlation, in seconds. Negative means the
        simulated signal lags the reference.
    peak_correlation:
        ρ at ``lag_s``: the mean-removed correlation coefficient the lag search maximises
        (:mod:`pytest_hevval.core.lag`), clipped to [0, 1]. Never below
        ``correlation_at_zero_lag``. Not λ1's form: λ1 is the spec's correlation at zero
        lag over the whole record.
    correlation_at_zero_lag:
        ρ at zero lag, the same quantity.
    max_lag_s:
        Half-width of the lag search that was run, in seconds (``alignment.max_lag_s``, at most
        a quarter of the record).
    lag_at_bound:
        The lag lies on the edge of that search (|lag| ≥ max_lag_s − dt/2), so the peak may lie
        beyond it.
    mae, rms, delta_e, error_std:
        E_MAE, E_RMS, ΔE = E_RMS − E_MAE and σ (N−1) of e = y_ref − y_sim, in the signal's units.
    mean_error:
        Mean of e (bias), in the signal's units.
    reference_range:
        The normalising range R (y_ref,max − y_ref,min, or the declared range).
    """

    lambdas: tuple[float, float, float, float, float, float]
    lag_s: float
    peak_correlation: float
    mae: float
    rms: float
    delta_e: float
    error_std: float
    mean_error: float
    reference_range: float
    n_samples: int
    dt: float
    correlation: CorrelationKind = "xcorr"
    correlation_at_zero_lag: float = math.nan
    max_lag_s: float = math.nan
    lag_at_bound: bool = False
    lag_search: LagSearch | None = field(default=None, compare=False, repr=False)
    #: The sums of the groups of ``group_runs`` (see ``core.groups.grouped_tables``) when the
    #: compiled main pass took them along, else None.
    group_sums: FloatArray | None = field(default=None, compare=False, repr=False)
    #: The whole record's sums, from which the moment-based standard metrics are scored.
    sums: Sums[float] | None = field(default=None, compare=False, repr=False)

    @property
    def values(self) -> dict[str, float]:
        """λ1–λ6 keyed by characteristic name."""
        return dict(zip(FUSED_CHARACTERISTICS, self.lambdas, strict=True))

    @property
    def lag_correlation(self) -> float:
        return self.lambdas[0]

    @property
    def derivative_match(self) -> float:
        return self.lambdas[1]

    @property
    def lambda_mae(self) -> float:
        return self.lambdas[2]

    @property
    def lambda_rms(self) -> float:
        return self.lambdas[3]

    @property
    def anomaly(self) -> float:
        return self.lambdas[4]

    @property
    def lambda_error_std(self) -> float:
        return self.lambdas[5]

    def as_dict(self) -> dict[str, float | int | str | bool | list[float]]:
        return {
            "lambdas": list(self.lambdas),
            "lag_s": self.lag_s,
            "peak_correlation": self.peak_correlation,
            "mae": self.mae,
            "rms": self.rms,
            "delta_e": self.delta_e,
            "error_std": self.error_std,
            "mean_error": self.mean_error,
            "reference_range": self.reference_range,
            "n_samples": self.n_samples,
            "dt": self.dt,
            "correlation": self.correlation,
            "correlation_at_zero_lag": self.correlation_at_zero_lag,
            "max_lag_s": self.max_lag_s,
            "lag_at_bound": self.lag_at_bound,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> SignalCharacteristics:
        """The inverse of :meth:`as_dict`; ``lambdas`` may also be keyed by name."""
        raw = data["lambdas"]
        if isinstance(raw, Mapping):
            raw = [raw[name] for name in FUSED_CHARACTERISTICS]
        lambdas = tuple(float(v) for v in raw[: len(FUSED_CHARACTERISTICS)])
        mae = float(data["mae"])
        rms = float(data["rms"])
        return cls(
            lambdas=lambdas,  # type: ignore[arg-type]
            lag_s=float(data["lag_s"]),
            peak_correlation=float(data["peak_correlation"]),
            mae=mae,
            rms=rms,
            delta_e=float(data.get("delta_e", rms - mae)),
            error_std=float(data.get("error_std", 0.0)),
            mean_error=float(data.get("mean_error", 0.0)),
            reference_range=float(data.get("reference_range", 0.0)),
            n_samples=int(data.get("n_samples", 0)),
            dt=float(data.get("dt", 0.0)),
            correlation=data.get("correlation", "xcorr"),
            # Results written before these fields existed read as unknown.
            correlation_at_zero_lag=_number(data.get("correlation_at_zero_lag")),
            max_lag_s=_number(data.get("max_lag_s")),
            lag_at_bound=bool(data.get("lag_at_bound", False)),
        )


@dataclass
class _Running:
    """The running state of one pass, merged across chunks and threads: the sums, with the
    error's running mean in place of Σe (Chan et al.'s merge of mean and M2, stable when the
    bias dwarfs the spread) and the extremes of both signals. Its product is the record's
    :class:`~pytest_hevval.core.sums.Sums` (:meth:`record`)."""

    n: int = 0
    abs_error: float = 0.0
    sq_error: float = 0.0
    # Chan et al. running mean / M2 of the error, stable when the bias dwarfs the spread.
    error_mean: float = 0.0
    error_m2: float = 0.0
    ref_sum: float = 0.0
    sim_sum: float = 0.0
    ref_sq: float = 0.0
    sim_sq: float = 0.0
    cross: float = 0.0
    ref_min: float = math.inf
    ref_max: float = -math.inf
    sim_min: float = math.inf
    sim_max: float = -math.inf
    sign_matches: int = 0

    def record(self, scale: float) -> Sums[float]:
        """The whole record's sums, in the units times ``scale``: what λ1–λ6 and the standard
        metrics' moments are taken from."""
        return Sums(
            n=self.n,
            error_sum=self.error_mean * self.n,
            abs_error=self.abs_error,
            sq_error=self.sq_error,
            error_m2=self.error_m2,
            ref_sum=self.ref_sum,
            sim_sum=self.sim_sum,
            ref_sq=self.ref_sq,
            sim_sq=self.sim_sq,
            cross=self.cross,
            sign_matches=self.sign_matches,
            scale=scale,
            ref_min=self.ref_min,
            ref_max=self.ref_max,
        )

    def merge(self, other: _Running) -> None:
        if other.n == 0:
            return
        n = self.n + other.n
        delta = other.error_mean - self.error_mean
        self.error_m2 += other.error_m2 + delta * delta * self.n * other.n / n
        self.error_mean += delta * other.n / n
        self.n = n
        self.abs_error += other.abs_error
        self.sq_error += other.sq_error
        self.ref_sum += other.ref_sum
        self.sim_sum += other.sim_sum
        self.ref_sq += other.ref_sq
        self.sim_sq += other.sim_sq
        self.cross += other.cross
        self.ref_min = min(self.ref_min, other.ref_min)
        self.ref_max = max(self.ref_max, other.ref_max)
        self.sim_min = min(self.sim_min, other.sim_min)
        self.sim_max = max(self.sim_max, other.sim_max)
        self.sign_matches += other.sign_matches


def _sums_from_rows(rows: FloatArray) -> _Running:
    """The compiled pass's per-chunk rows merged in record order, as the numpy path merges."""
    total = _Running()
    for values in rows.tolist():
        m = int(values[kernel.N])
        part = _Running(
            n=m,
            abs_error=values[kernel.ABS_ERROR],
            sq_error=values[kernel.SQ_ERROR],
            error_mean=values[kernel.ERROR_SUM] / m,
            error_m2=values[kernel.ERROR_M2],
            ref_sum=values[kernel.REF_SUM],
            sim_sum=values[kernel.SIM_SUM],
            ref_sq=values[kernel.REF_SQ],
            sim_sq=values[kernel.SIM_SQ],
            cross=values[kernel.CROSS],
            ref_min=values[kernel.REF_MIN],
            ref_max=values[kernel.REF_MAX],
            sign_matches=int(values[kernel.SIGN_MATCHES]),
        )
        total.merge(part)
    # The compiled min and max assume no NaN. A NaN sample makes the sum of squares NaN
    # (overflow gives inf, never NaN), so that marks the extremes unusable. The simulated
    # signal's NaN shows in its sum of squares, which _sim_extremes_needed checks.
    if math.isnan(total.ref_sq):
        total.ref_min = total.ref_max = math.nan
    return total


FloatArray = npt.NDArray[np.float64]
AnyFloatArray = npt.NDArray[np.floating]


class _Scratch:
    """Chunk-sized buffers owned by one thread, reused for every chunk it processes."""

    def __init__(self, size: int, convert: bool) -> None:
        self.error = np.empty(size, dtype=np.float64)
        self.up = np.empty(size, dtype=np.bool_)
        self.down = np.empty(size, dtype=np.bool_)
        self.key = np.empty(size, dtype=np.int8)
        self.ref = np.empty(size, dtype=np.float64) if convert else None
        self.sim = np.empty(size, dtype=np.float64) if convert else None


def _as_float64(x: AnyFloatArray, scale: float, buffer: FloatArray | None) -> FloatArray:
    if buffer is None:
        return x  # type: ignore[return-value]  # float64 and unscaled: used in place
    out = buffer[: x.shape[0]]
    if scale != 1.0:
        np.multiply(x, scale, out=out, dtype=np.float64)
    else:
        np.copyto(out, x)
    return out


def _derivative_key(
    y: AnyFloatArray, i0: int, i1: int, scratch: _Scratch, out: npt.NDArray[np.int8]
) -> npt.NDArray[np.int8]:
    """sign(y[i+1] − y[i−1]) for i in [i0, i1) as int8, from two comparisons.

    For finite floats a − b > 0 exactly when a > b (gradual underflow never rounds a nonzero
    difference to 0), so comparing the neighbours gives the sign of the central difference
    without forming it, and the comparison is the same before and after an exact rescale.
    """
    m = i1 - i0
    up = scratch.up[:m]
    down = scratch.down[:m]
    np.greater(y[i0 + 1 : i1 + 1], y[i0 - 1 : i1 - 1], out=up)
    np.less(y[i0 + 1 : i1 + 1], y[i0 - 1 : i1 - 1], out=down)
    return np.subtract(up.view(np.int8), down.view(np.int8), out=out)


# Pyramid levels made by the main pass: [(ref, sim) block means by 4, by 16, by 64].
_Levels = list[tuple[FloatArray, FloatArray]]

_add = np.add.reduce
_min = np.minimum.reduce
_max = np.maximum.reduce


def _quarter_means(x: FloatArray, out: FloatArray, scratch: FloatArray) -> FloatArray:
    """Means of consecutive blocks of 4 (len(x) is a multiple of 4) written into ``out``.

    Two strided pairwise additions cost about half a matrix-vector product with weights 1/4,
    and ×0.25 is exact, so 4·Σ out is the chunk's sum in a fixed summation order.
    """
    pairs = scratch[: x.shape[0] // 2]
    np.add(x[0::2], x[1::2], out=pairs)
    np.add(pairs[0::2], pairs[1::2], out=out)
    return np.multiply(out, 0.25, out=out)


def _chunk_sums(
    ref: AnyFloatArray,
    sim: AnyFloatArray,
    start: int,
    stop: int,
    scale: float,
    scratch: _Scratch,
    levels: _Levels | None,
) -> _Running:
    """Sums over samples [start, stop) of the whole record.

    The minimum and maximum of the simulated signal are left at ±inf: the caller derives or
    computes them only when they can matter (see :func:`_sim_extremes_needed`).
    """
    n_total = ref.shape[0]
    m = stop - start
    r = _as_float64(ref[start:stop], scale, scratch.ref)
    s = _as_float64(sim[start:stop], scale, scratch.sim)
    out = _Running(n=m)
    e = np.subtract(r, s, out=scratch.error[:m])
    out.sq_error = _dot(e, e)
    # ufunc reductions called directly: the ndarray.sum/min/max wrappers add about a
    # microsecond each, which is a tenth of the work on a chunk.
    error_sum = float(_add(e))
    out.error_mean = error_sum / m
    if out.error_mean * error_sum <= 0.5 * out.sq_error:
        # Σe² − (Σe)²/m loses at most one bit to cancellation when the spread is at least
        # the bias, and saves a pass over the chunk.
        out.error_m2 = out.sq_error - out.error_mean * error_sum
    else:
        centred = e - out.error_mean
        out.error_m2 = _dot(centred, centred)
    out.abs_error = float(_add(np.abs(e, out=e)))
    out.ref_sq = _dot(r, r)
    out.sim_sq = _dot(s, s)
    out.cross = _dot(r, s)
    out.ref_min = float(_min(r))
    out.ref_max = float(_max(r))
    if levels is not None:
        # The block means by 4, 16 and 64 of the lag pyramid come from the chunk while it is
        # in cache; the sum of the first (×4, exact) is the chunk's sum. Chunks start on
        # multiples of 64.
        (r4, s4), (r16, s16), (r64, s64) = levels
        q0 = start // 4
        q1 = q0 + m // 4
        whole = (m // 4) * 4
        rq = _quarter_means(r[:whole], r4[q0:q1], scratch.error)
        sq = _quarter_means(s[:whole], s4[q0:q1], scratch.error)
        out.ref_sum = 4.0 * float(_add(rq)) + float(_add(r[whole:]))
        out.sim_sum = 4.0 * float(_add(sq)) + float(_add(s[whole:]))
        h0 = start // 16
        h1 = h0 + (q1 - q0) // 4
        _quarter_means(rq[: (h1 - h0) * 4], r16[h0:h1], scratch.error)
        _quarter_means(sq[: (h1 - h0) * 4], s16[h0:h1], scratch.error)
        g0 = start // 64
        g1 = g0 + (h1 - h0) // 4
        _quarter_means(r16[h0 : h0 + (g1 - g0) * 4], r64[g0:g1], scratch.error)
        _quarter_means(s16[h0 : h0 + (g1 - g0) * 4], s64[g0:g1], scratch.error)
    else:
        out.ref_sum = float(_add(r))
        out.sim_sum = float(_add(s))
    # Central differences: the first and last sample of the record have derivative 0.
    i0 = max(start, 1)
    i1 = min(stop, n_total - 1)
    if i1 > i0:
        key_r = _derivative_key(ref, i0, i1, scratch, scratch.key[: i1 - i0])
        key_s = _derivative_key(sim, i0, i1, scratch, scratch.up[: i1 - i0].view(np.int8))
        out.sign_matches = int(
            np.count_nonzero(np.equal(key_r, key_s, out=scratch.down[: i1 - i0]))
        )
    # Endpoints (derivative 0 on both sides) always agree.
    out.sign_matches += int(start == 0) + int(stop == n_total and n_total > 1)
    return out


def _all_sums(
    ref: AnyFloatArray,
    sim: AnyFloatArray,
    scale: float,
    workers: int,
    levels: _Levels | None = None,
    group_runs: kernel.GroupRuns | None = None,
) -> tuple[_Running, FloatArray | None]:
    """The whole record's sums, and the groups' sums when the compiled pass took them along."""
    n = ref.shape[0]
    compiled = kernel.kernel_for(n) if kernel.accepts(ref, sim) else None
    if compiled is not None:
        flat = None if levels is None else tuple(x for pair in levels for x in pair)
        rows, group_sums = kernel.main_pass(compiled, ref, sim, scale, workers, flat, group_runs)
        return _sums_from_rows(rows), group_sums
    convert = scale != 1.0 or ref.dtype != np.float64 or sim.dtype != np.float64
    if n <= _SMALL:
        with np.errstate(all="ignore"):
            return _chunk_sums(ref, sim, 0, n, scale, _Scratch(n, convert), levels), None
    bounds = [*range(0, n, _CHUNK), n]
    spans = list(itertools.pairwise(bounds))

    def run(part: Sequence[tuple[int, int]]) -> _Running:
        acc = _Running()
        scratch = _Scratch(_CHUNK, convert)
        # Squares may overflow or underflow here (a rescaled pass follows) and NaN or inf
        # input is reported by the caller, so no floating-point warning is wanted. The error
        # state is per thread, hence set inside each worker.
        with np.errstate(all="ignore"):
            for start, stop in part:
                acc.merge(_chunk_sums(ref, sim, start, stop, scale, scratch, levels))
        return acc

    # numpy releases the GIL inside its loops, so threads share the pass across cores. The
    # record is always cut into the same contiguous parts and merged in order, whatever the
    # thread count, so that results are bit-identical on any machine.
    per = math.ceil(len(spans) / PARTS)
    parts = [spans[i : i + per] for i in range(0, len(spans), per)]
    if workers <= 1:
        partials = [run(part) for part in parts]
    else:
        with ThreadPoolExecutor(max_workers=min(workers, len(parts))) as pool:
            partials = list(pool.map(run, parts))
    total = _Running()
    for partial in partials:
        total.merge(partial)
    return total, None


def _check_inputs(
    reference: npt.ArrayLike, simulated: npt.ArrayLike, dt: float
) -> tuple[FloatArray, FloatArray]:
    ref = np.asarray(reference)
    sim = np.asarray(simulated)
    if ref.ndim != 1 or sim.ndim != 1:
        raise DegenerateSignalError(
            f"signals must be one-dimensional (got shapes {ref.shape} and {sim.shape})"
        )
    if ref.shape[0] != sim.shape[0]:
        raise DegenerateSignalError(
            f"reference and simulated signals differ in length ({ref.shape[0]} vs "
            f"{sim.shape[0]} samples)",
            hint="align both onto one time grid first",
        )
    if ref.shape[0] < 3:
        raise DegenerateSignalError(
            f"at least 3 samples are needed (got {ref.shape[0]})",
            hint="widen the window or raise the sample rate",
        )
    for name, arr in (("reference", ref), ("simulated", sim)):
        if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
            raise DegenerateSignalError(f"{name} signal must be numeric (got dtype {arr.dtype})")
    if not (isinstance(dt, (int, float, np.floating)) and math.isfinite(dt) and dt > 0):
        raise DegenerateSignalError(f"dt must be a positive, finite number of seconds (got {dt!r})")
    # Keep float32/float64 storage as is (the chunks are promoted); promote the rest.
    if ref.dtype not in (np.float32, np.float64):
        ref = ref.astype(np.float64)
    if sim.dtype not in (np.float32, np.float64):
        sim = sim.astype(np.float64)
    return ref, sim


def _level_buffers(n: int, dt: float, max_lag_s: float | None) -> _Levels | None:
    """Storage for the block means by 4, 16 and 64 when the lag search will build a pyramid."""
    if n <= _EXACT_LIMIT:
        return None
    if max_lag_s is not None:
        # Invalid values are reported later, in the usual order of checks.
        if not isinstance(max_lag_s, (int, float)) or not math.isfinite(max_lag_s):
            return None
        if max_lag_s < 0 or round(max_lag_s / dt) < 1:
            return None
    quarter = (np.empty(n // 4, dtype=np.float64), np.empty(n // 4, dtype=np.float64))
    sixteenth = (np.empty(n // 16, dtype=np.float64), np.empty(n // 16, dtype=np.float64))
    sixty_fourth = (np.empty(n // 64, dtype=np.float64), np.empty(n // 64, dtype=np.float64))
    return [quarter, sixteenth, sixty_fourth]


def _sim_extremes_needed(sums: _Running) -> bool:
    """Whether the simulated signal's min and max can change the finiteness or rescale verdict.

    A finite Σ s² below 2^800 proves every |s| < 2^400 and every s finite, so the simulated
    peak cannot call for the downscale; it can call for the upscale only if the reference's
    peak is itself below 2^-400 (or zero).
    """
    if not (math.isfinite(sums.sim_sq) and sums.sim_sq < _TOO_BIG * _TOO_BIG):
        return True
    if not (math.isfinite(sums.ref_min) and math.isfinite(sums.ref_max)):
        return True
    return max(abs(sums.ref_min), abs(sums.ref_max)) < _TOO_SMALL


def power_of_two_scale(peak: float) -> float:
    """The factor that brings values of magnitude ``peak`` to about 1 when their squares would
    overflow or underflow (beyond 2^±400), else 1.

    An exact power of two keeps every ratio bit-identical while the squares stay finite.
    Subnormal peaks need more than 2**1023; 2**1000 already makes them normal.
    """
    if peak > _TOO_BIG or (0.0 < peak < _TOO_SMALL):
        return math.ldexp(1.0, min(-math.frexp(peak)[1], 1000))
    return 1.0


def _first_non_finite(arr: FloatArray) -> int:
    bad = np.flatnonzero(~np.isfinite(arr))
    return int(bad[0]) if bad.size else -1


def signal_characteristics(
    reference: npt.ArrayLike,
    simulated: npt.ArrayLike,
    *,
    dt: float,
    max_lag_s: float | None = None,
    correlation: CorrelationKind = "xcorr",
    reference_range: float | None = None,
    workers: int | None = None,
    group_runs: kernel.GroupRuns | None = None,
) -> SignalCharacteristics:
    r"""Compute λ1–λ6 for one aligned signal pair.

    Parameters
    ----------
    reference, simulated:
        Equal-length, one-dimensional samples on one time grid. float32 input is accepted and
        accumulated in float64.
    dt:
        Sample spacing in seconds.
    max_lag_s:
        Half-width of the lead/lag search. ``None`` searches ±10 % of the record (at least
        one sample).
    correlation:
        ``"xcorr"`` (default, the paper's form) or ``"pearson"`` for λ1.
    reference_range:
        Declared normalising range for λ3–λ6. Needed when the reference is constant.
    workers:
        Threads for long signals; default ``min(2, os.cpu_count())``.
    group_runs:
        Groups of samples (``core.groups.Grouping.runs``) whose sums the compiled main pass
        takes along while each chunk is in cache, into ``group_sums`` of the result.

    Returns
    -------
    SignalCharacteristics

    Raises
    ------
    DegenerateSignalError
        Different lengths, fewer than 3 samples, NaN or inf, dt ≤ 0, or a constant reference
        without a declared range.

    Notes
    -----
    With e = y_ref − y_sim and R = max(y_ref) − min(y_ref):

    * λ1 = Σ y_ref·y_sim / √(Σ y_ref² · Σ y_sim²) (MATLAB ``xcorr(ref, sim, 'coeff')`` at lag 0),
      or Pearson's r clipped to [0, 1].
    * λ2 = #{i : sign(ẏ_ref,i) = sign(ẏ_sim,i)} / N with central differences and ẏ = 0 at
      both ends.
    * λ3 = 1 − E_MAE/R, λ4 = 1 − E_RMS/R, λ5 = 1 − (E_RMS − E_MAE)/R, λ6 = 1 − σ/R with σ
      using N − 1; each clipped to [0, 1].
    """
    ref, sim = _check_inputs(reference, simulated, dt)
    n = int(ref.shape[0])
    if not kernel.accepts(ref, sim) and kernel.kernel_for(n) is not None:
        # The kernel takes contiguous float64 only. Promoting float32 (or a strided view) here
        # keeps the result that of the same values in float64 on this path too, as the numpy
        # path's per-chunk promotion does, for the price of a float64 copy of each signal.
        ref = np.ascontiguousarray(ref, dtype=np.float64)
        sim = np.ascontiguousarray(sim, dtype=np.float64)
    if workers is None:
        import os

        workers = min(2, os.cpu_count() or 1)

    levels = _level_buffers(n, dt, max_lag_s)
    sums, group_sums = _all_sums(ref, sim, 1.0, workers, levels, group_runs)
    sim_extremes = _sim_extremes_needed(sums)
    if sim_extremes:
        sums.sim_min = float(np.min(sim))
        sums.sim_max = float(np.max(sim))
    # Skipped simulated extremes stay ±inf; _sim_extremes_needed then proved Σ s² finite.
    finite = math.isfinite(sums.ref_min) and math.isfinite(sums.ref_max)
    if sim_extremes:
        finite = finite and math.isfinite(sums.sim_min) and math.isfinite(sums.sim_max)
    if not finite:
        for name, arr in (("reference", ref), ("simulated", sim)):
            index = _first_non_finite(np.asarray(arr))
            if index >= 0:
                raise DegenerateSignalError(
                    f"{name} signal contains NaN or inf (first at sample {index})",
                    hint="set a gap policy (nan: omit) or clean the data",
                )
    # Skipped simulated extremes cannot decide the rescale below (see _sim_extremes_needed).
    peak = max(abs(sums.ref_min), abs(sums.ref_max))
    if sim_extremes:
        peak = max(peak, abs(sums.sim_min), abs(sums.sim_max))
    scale = power_of_two_scale(peak)
    if scale != 1.0:
        sums, _ = _all_sums(ref, sim, scale, workers)
        # The first pass's block means are unscaled and may have overflowed; the lag search
        # builds its own from the records instead (this case is rare enough to pay a read).
        levels = None

    span = (sums.ref_max - sums.ref_min) / scale
    if reference_range is not None:
        if not (math.isfinite(reference_range) and reference_range > 0):
            raise DegenerateSignalError(
                f"reference_range must be a positive number (got {reference_range!r})"
            )
        span = float(reference_range)
    elif span <= 0:
        raise DegenerateSignalError(
            f"the reference is constant (every sample is {sums.ref_min / scale:g}), so its "
            "range is 0 and λ3–λ6 cannot be normalised",
            hint="declare a normalising range (reference_range) for this signal",
        )

    # λ1–λ6 and the errors, with the formulas every grouping shares (core.sums), on Python
    # numbers; the errors come back in the signal's units.
    totals = sums.record(scale)
    found = lambdas_from_sums(totals, span, correlation)
    mean_error = sums.error_mean / scale

    if max_lag_s is None:
        max_lag = max(1, n // 10)
    else:
        if not (math.isfinite(max_lag_s) and max_lag_s >= 0):
            raise DegenerateSignalError(f"max_lag_s must be ≥ 0 (got {max_lag_s!r})")
        max_lag = min(round(max_lag_s / dt), n - 1)
    lag_ref, lag_sim, lag_scale = ref, sim, scale
    if scale != 1.0:
        # Search the rescaled records themselves: their means, which are the sums' own units,
        # would underflow (or overflow) if taken back to the original scale, and a centring
        # by a lost mean can make a varying record look flat. Scaling by a power of two is
        # exact, so nothing else changes; the copies are made only in this rare case.
        lag_ref = np.multiply(ref, scale, dtype=np.float64)
        lag_sim = np.multiply(sim, scale, dtype=np.float64)
        lag_scale = 1.0
    # The sums are in the units of the records searched (rescaled or not): so are the means.
    r_mean = sums.ref_sum / n
    s_mean = sums.sim_sum / n
    whole: dict[str, float] = {}
    if n > _EXACT_LIMIT and max_lag > 0:
        # The pyramid's last level needs the whole records' centred sums: from the pass's sums
        # where they keep their digits, so the search reads only the samples it must.
        from .standard._moments import moments_from_pass

        moments = moments_from_pass(totals, ref, sim)
        whole = {"sim_energy": moments.sim_m2, "co_moment": moments.co_m2}
    search = _search(
        lag_ref,
        lag_sim,
        max_lag,
        ref_mean=r_mean,
        sim_mean=s_mean,
        scale=lag_scale,
        workers=workers,
        levels=levels or (),
        **whole,
    )
    del levels

    lambdas = tuple(found.lambdas[name] for name in FUSED_CHARACTERISTICS)
    return SignalCharacteristics(
        lambdas=lambdas,  # type: ignore[arg-type]
        lag_s=search.lag * float(dt),
        peak_correlation=search.correlation,
        mae=found.mae,
        rms=found.rms,
        delta_e=found.delta_e,
        error_std=found.error_std,
        mean_error=mean_error,
        reference_range=span,
        n_samples=n,
        dt=float(dt),
        correlation=correlation,
        correlation_at_zero_lag=search.zero_lag_correlation,
        max_lag_s=search.max_lag * float(dt),
        lag_at_bound=search.at_bound,
        lag_search=search,
        group_sums=group_sums,
        sums=totals,
    )
