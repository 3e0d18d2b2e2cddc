"""λ1–λ6 from additive sums: the one place their formulas are written.

The whole record (:func:`~pytest_hevval.core.characteristics.signal_characteristics`), its
windows, segments and region cells (:func:`~pytest_hevval.core.local.group_lambdas`) and the
bootstrap replicates (:func:`~pytest_hevval.core.uncertainty.sums_lambdas`) all reduce a signal
pair to the same few sums (n, Σ|e|, Σe², Σ(e − ē)², Σref·sim, Σref², Σsim², Σref, Σsim and the
count of matching derivative signs) and take λ1–λ6 from them with :func:`lambdas_from_sums`.

The function works elementwise on either kind of operand and keeps the arithmetic of each:

* **Python numbers** (the whole record, whose characteristics are Python floats): ``x**2`` is
  C ``pow``, clipping is ``min``/``max``, the square root is :func:`math.sqrt`.
* **numpy arrays** of any shape (groups; replicates × signals): ``x**2`` is ``np.square``,
  clipping is ``np.clip``, and groups of fewer than :data:`MIN_GROUP_SAMPLES` samples get NaN.

The two differ in the last bit now and then (``pow(x, 2)`` is not always ``x·x`` rounded) and on
−0.0 (``max(0.0, -0.0)`` is 0.0, ``np.clip(-0.0, 0, 1)`` is −0.0), so each kind of operand goes
through its own primitives and every path computes exactly what it computed before the formulas
were shared.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Generic, TypeVar, overload

import numpy as np
import numpy.typing as npt

from ..errors import DegenerateSignalError

__all__ = [
    "MIN_GROUP_SAMPLES",
    "RecordSums",
    "SumLambdas",
    "from_shifted_sums",
    "lambdas_from_sums",
    "normalised_error",
    "zero_lag_correlation",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
V = TypeVar("V", float, FloatArray)

#: Fewer samples than this in a window, cell or replicate: its characteristics are NaN.
MIN_GROUP_SAMPLES = 3
# Powers at or below this count as none (λ1's degenerate cases).
_TINY = 1e-300


@dataclass(frozen=True)
class RecordSums:
    """A whole record's sums as the λ pass leaves them, in the record's units times ``scale``
    (a power of two, 1 unless the squares would leave the float range): what the standard
    metrics built from moments take instead of reading the record again."""

    n: int
    ref_sum: float
    sim_sum: float
    ref_sq: float
    sim_sq: float
    cross: float
    #: e = ref − sim.
    sq_error: float
    error_sum: float
    #: Σ(e − ē)², merged over chunks as the λ pass merges it.
    error_m2: float
    ref_min: float
    ref_max: float
    scale: float


class _Numbers:
    """The primitives on Python numbers (the whole record)."""

    sqrt = staticmethod(math.sqrt)
    maximum = staticmethod(max)

    @staticmethod
    def where(condition: Any, yes: Any, no: Any) -> Any:
        return yes if condition else no

    @staticmethod
    def clip(value: Any) -> float:
        return float(min(1.0, max(0.0, value)))

    @staticmethod
    def check_range(reference_range: Any) -> Any:
        if not reference_range > 0:
            raise DegenerateSignalError(
                f"the normalising range must be > 0 (got {reference_range!r})"
            )
        return reference_range

    @staticmethod
    def any(mask: Any) -> bool:
        return bool(mask)


class _Arrays:
    """The primitives on numpy arrays (groups, replicates)."""

    sqrt = staticmethod(np.sqrt)
    maximum = staticmethod(np.maximum)
    where = staticmethod(np.where)

    @staticmethod
    def clip(value: Any) -> Any:
        return np.clip(value, 0.0, 1.0)

    @staticmethod
    def check_range(reference_range: Any) -> Any:
        ranges = np.asarray(reference_range, dtype=np.float64)
        if not bool(np.all(np.isfinite(ranges) & (ranges > 0))):
            raise DegenerateSignalError(
                f"the normalising range must be > 0 (got {reference_range!r})"
            )
        return ranges

    @staticmethod
    def any(mask: Any) -> bool:
        return bool(np.any(mask))


def _ops(*operands: object) -> Any:
    """The primitives for these operands: arrays if any of them is one."""
    return _Arrays if any(isinstance(x, np.ndarray) for x in operands) else _Numbers


@dataclass(frozen=True)
class SumLambdas(Generic[V]):
    """λ1–λ6 and the errors they are built from, elementwise over the sums given.

    ``lambdas`` maps the names of λ1–λ6 (paper order, as ``FUSED_CHARACTERISTICS``) to their
    values, NaN where a group has fewer than :data:`MIN_GROUP_SAMPLES` samples. The errors
    are in the sums' units divided by ``scale`` and are not masked.
    """

    lambdas: dict[str, V]
    mae: V
    rms: V
    delta_e: V
    error_std: V


@overload
def _coefficient(cross: float, power_a: float, power_b: float) -> float: ...
@overload
def _coefficient(cross: FloatArray, power_a: FloatArray, power_b: FloatArray) -> FloatArray: ...
def _coefficient(cross: Any, power_a: Any, power_b: Any) -> Any:
    """cross / √(power_a·power_b) clipped to [0, 1], with the degenerate cases defined.

    Two signals with no power (all zero, or constant for Pearson) are the same shape: 1.
    One with power against one without share nothing: 0. Elementwise on arrays.
    """
    ops = _ops(cross, power_a, power_b)
    a_empty = power_a <= _TINY
    b_empty = power_b <= _TINY
    with np.errstate(invalid="ignore", divide="ignore"):
        value = (
            cross
            / ops.sqrt(ops.where(a_empty, 1.0, power_a))
            / ops.sqrt(ops.where(b_empty, 1.0, power_b))
        )
    value = ops.clip(value)
    value = ops.where(a_empty | b_empty, 0.0, value)
    return ops.where(a_empty & b_empty, 1.0, value)


@overload
def zero_lag_correlation(
    n: float,
    cross: float,
    ref_sq: float,
    sim_sq: float,
    ref_sum: float | None = None,
    sim_sum: float | None = None,
    correlation: str = "xcorr",
) -> float: ...
@overload
def zero_lag_correlation(
    n: FloatArray,
    cross: FloatArray,
    ref_sq: FloatArray,
    sim_sq: FloatArray,
    ref_sum: FloatArray | None = None,
    sim_sum: FloatArray | None = None,
    correlation: str = "xcorr",
) -> FloatArray: ...
def zero_lag_correlation(
    n: Any,
    cross: Any,
    ref_sq: Any,
    sim_sq: Any,
    ref_sum: Any = None,
    sim_sum: Any = None,
    correlation: str = "xcorr",
) -> Any:
    """λ1: the zero-lag coefficient Σref·sim / √(Σref²·Σsim²) (``xcorr``) or Pearson's r from
    the same sums and Σref, Σsim over ``n`` samples (``pearson``), clipped to [0, 1]."""
    if correlation == "pearson":
        if ref_sum is None or sim_sum is None:
            raise ValueError("Pearson's coefficient needs ref_sum and sim_sum")
        cov = cross - ref_sum * sim_sum / n
        var_r = ref_sq - ref_sum**2 / n
        var_s = sim_sq - sim_sum**2 / n
        return _coefficient(cov, var_r, var_s)
    return _coefficient(cross, ref_sq, sim_sq)


def normalised_error(error: float, reference_range: float) -> float:
    """λ = 1 − E / R clipped to [0, 1] (eqs. 8, 9, 10 and 12 of the paper).

    ``error`` is E_MAE, E_RMS, ΔE or σ in the signal's units and ``reference_range`` is
    R = y_ref,max − y_ref,min (or a declared range).
    """
    _Numbers.check_range(reference_range)
    return _Numbers.clip(1.0 - error / reference_range)


def lambdas_from_sums(
    *,
    n: Any,
    abs_error: V,
    sq_error: V,
    error_m2: V,
    ref_sq: V,
    sim_sq: V,
    cross: V,
    sign_matches: Any,
    reference_range: Any,
    correlation: str = "xcorr",
    ref_sum: V | None = None,
    sim_sum: V | None = None,
    scale: float = 1.0,
) -> SumLambdas[V]:
    """λ1–λ6 from additive sums, elementwise.

    Parameters
    ----------
    n:
        Samples: an ``int`` for Python numbers, an integer array for arrays.
    abs_error, sq_error, error_m2:
        Σ|e|, Σe² and Σ(e − ē)² with e = ref − sim.
    ref_sq, sim_sq, cross:
        Σref², Σsim², Σref·sim.
    sign_matches:
        Samples whose central-difference derivative signs agree (integers).
    reference_range:
        The normalising range R in the sums' units divided by ``scale``; broadcasts against the
        sums for arrays.
    correlation:
        ``"xcorr"`` or ``"pearson"`` (then ``ref_sum`` and ``sim_sum``, Σref and Σsim, are
        needed).
    scale:
        The factor the samples were multiplied by before summing; errors are divided by it.

    Raises
    ------
    DegenerateSignalError
        ``reference_range`` is not > 0 (for arrays also: not finite).
    """
    ops = _ops(n)
    ranges = ops.check_range(reference_range)
    nf = n.astype(np.float64) if isinstance(n, np.ndarray) else n
    small = n < MIN_GROUP_SAMPLES
    safe_n = ops.where(small, 1.0, nf)
    mae = abs_error / safe_n
    rms = ops.sqrt(sq_error / safe_n)
    error_std = ops.sqrt(error_m2 / ops.where(small, 1.0, nf - 1.0))
    if scale != 1.0:
        mae = mae / scale
        rms = rms / scale
        error_std = error_std / scale
    # RMS ≥ MAE holds mathematically; rounding can break it by an ulp.
    rms = ops.maximum(rms, mae)
    delta_e = rms - mae
    lag_correlation = zero_lag_correlation(
        safe_n, cross, ref_sq, sim_sq, ref_sum, sim_sum, correlation
    )

    def normalised(error: Any) -> Any:
        return ops.clip(1.0 - error / ranges)

    values = {
        "lag_correlation": lag_correlation,
        "derivative_match": sign_matches / safe_n,
        "mae": normalised(mae),
        "rms": normalised(rms),
        "anomaly": normalised(delta_e),
        "error_std": normalised(error_std),
    }
    if ops.any(small):
        values = {name: ops.where(small, math.nan, value) for name, value in values.items()}
    return SumLambdas(values, mae, rms, delta_e, error_std)


def from_shifted_sums(
    n: IntArray, shifted_sum: FloatArray, shifted_sq: FloatArray, shift: float | FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Σe² and Σ(e − ē)² from the sums Σd, Σd² of d = e − ``shift`` over ``n`` samples (see
    :class:`~pytest_hevval.core.local.SumTable`), elementwise; both at least 0."""
    nf = n.astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        error_m2 = np.where(n > 0, shifted_sq - shifted_sum**2 / np.maximum(nf, 1.0), 0.0)
    sq_error = np.maximum(shifted_sq + 2.0 * shift * shifted_sum + nf * shift * shift, 0.0)
    return sq_error, np.maximum(error_m2, 0.0)
