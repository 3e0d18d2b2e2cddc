"""λ1–λ6 from additive sums: the one type of the core's sums, and the one place λ's formulas
are written.

The whole record (:func:`~pytest_hevval.core.characteristics.signal_characteristics`), its
windows, segments and region cells (:func:`~pytest_hevval.core.groups.group_lambdas`) and the
bootstrap replicates (:func:`~pytest_hevval.core.uncertainty.sums_lambdas`) all reduce a signal
pair to the same few sums (n, Σe, Σ|e|, Σe², Σ(e − ē)², Σref·sim, Σref², Σsim², Σref, Σsim and
the count of matching derivative signs), held in one :class:`Sums`, and take λ1–λ6 from it with
:func:`lambdas_from_sums`. The standard metrics' moments
(:class:`~pytest_hevval.core.standard._moments.Moments`) are built on the whole record's
:class:`Sums` too. Sums that add up across groups, whose error sums are taken about a shift,
are stored as a table (:class:`~pytest_hevval.core.groups.SumTable`, columns
:data:`SUM_COLUMNS`), which :meth:`Sums.of_table` reads.

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
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any, Generic, TypeVar, overload

import numpy as np
import numpy.typing as npt

from ..errors import DegenerateSignalError

__all__ = [
    "MIN_GROUP_SAMPLES",
    "SUM_COLUMNS",
    "SumLambdas",
    "Sums",
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


#: Columns of a table of additive sums (:class:`~pytest_hevval.core.groups.SumTable`), one row
#: per group. Every column adds up across groups; the error sums are taken about a shift near
#: the mean error (shifted sums), so the spread Σ(e − ē)² of any union of groups is
#: S2 − S1²/n without losing it to a large bias.
SUM_COLUMNS = (
    "n",
    "shifted_sum",
    "shifted_sq",
    "abs_error",
    "ref_sum",
    "sim_sum",
    "ref_sq",
    "sim_sq",
    "cross",
    "sign_matches",
)


@dataclass(frozen=True)
class Sums(Generic[V]):
    """The sums behind λ1–λ6 of a signal pair, with e = ref − sim: of one whole record (``V``
    float, ``n`` and ``sign_matches`` ints) or, elementwise, of groups, cells, replicates or
    several signals at once (``V`` an array, ``n`` and ``sign_matches`` integer arrays of its
    shape).

    A producer that has no use for a sum leaves it NaN: the standard metrics' moments of two
    arrays take no Σ|e| or sign count, a bootstrap replicate of the ``xcorr`` form no Σref or
    Σsim.
    """

    n: Any
    #: Σe.
    error_sum: V
    #: Σ|e|.
    abs_error: V
    #: Σe².
    sq_error: V
    #: Σ(e − ē)², kept apart from Σe² so that a large bias does not cancel the spread.
    error_m2: V
    ref_sum: V
    sim_sum: V
    ref_sq: V
    sim_sq: V
    #: Σref·sim.
    cross: V
    #: Samples whose central-difference derivative signs agree.
    sign_matches: Any
    #: The power of two the samples were multiplied by before summing (1 unless their squares
    #: would leave the float range): λ are ratios and do not change, and
    #: :func:`lambdas_from_sums` divides the errors by it. Sums read from a table keep 1 here:
    #: the table holds its scale (``SumTable.scale``), and their readers scale the range.
    scale: float = 1.0
    #: The reference's smallest and largest sample (times ``scale``), which the whole record's
    #: pass finds along; NaN for groups and replicates.
    ref_min: float = math.nan
    ref_max: float = math.nan

    def rows(self, selection: slice | npt.NDArray[np.intp]) -> Sums[V]:
        """The sums of some of the groups only."""
        picked = {name: getattr(self, name)[selection] for name in _ELEMENTWISE}
        return Sums(**picked, scale=self.scale, ref_min=self.ref_min, ref_max=self.ref_max)

    @classmethod
    def of_columns(
        cls, columns: Mapping[str, FloatArray], shift: float | FloatArray
    ) -> Sums[FloatArray]:
        """The sums of columns named as :data:`SUM_COLUMNS`, of one shape (e.g. groups, or
        replicates × signals), whose error sums are taken about ``shift`` (broadcast against
        them: one for all, or one per row or signal). ``ref_sum`` and ``sim_sum`` may be left
        out (NaN then)."""
        n = np.rint(columns["n"]).astype(np.int64)
        shifted_sum = columns["shifted_sum"]
        sq_error, error_m2 = from_shifted_sums(n, shifted_sum, columns["shifted_sq"], shift)
        unsummed = np.broadcast_to(np.float64(math.nan), n.shape)
        return Sums(
            n=n,
            error_sum=shifted_sum + n.astype(np.float64) * shift,
            abs_error=columns["abs_error"],
            sq_error=sq_error,
            error_m2=error_m2,
            ref_sum=columns.get("ref_sum", unsummed),
            sim_sum=columns.get("sim_sum", unsummed),
            ref_sq=columns["ref_sq"],
            sim_sq=columns["sim_sq"],
            cross=columns["cross"],
            sign_matches=np.rint(columns["sign_matches"]).astype(np.int64),
        )

    @classmethod
    def of_table(cls, table: FloatArray, shift: float | FloatArray) -> Sums[FloatArray]:
        """The sums of rows of :data:`SUM_COLUMNS` whose error sums are taken about ``shift``
        (one for all rows, or one per row: the tables of several signals stacked)."""
        return cls.of_columns({name: table[:, c] for c, name in enumerate(SUM_COLUMNS)}, shift)


#: The fields of :class:`Sums` that hold one value per group, in order (``dataclasses.fields``
#: builds them anew on every call).
_ELEMENTWISE = tuple(f.name for f in fields(Sums) if f.name not in ("scale", "ref_min", "ref_max"))


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
    sums: Sums[V], reference_range: Any, correlation: str = "xcorr"
) -> SumLambdas[V]:
    """λ1–λ6 from a pair's :class:`Sums`, elementwise.

    Parameters
    ----------
    sums:
        The sums: Python numbers for a whole record, arrays for groups or replicates.
        ``sums.scale`` is the factor the samples were multiplied by; errors are divided by it.
    reference_range:
        The normalising range R in the sums' units divided by ``sums.scale``; broadcasts
        against the sums for arrays.
    correlation:
        ``"xcorr"`` or ``"pearson"`` (then from Σref and Σsim too).

    Raises
    ------
    DegenerateSignalError
        ``reference_range`` is not > 0 (for arrays also: not finite).
    """
    n = sums.n
    scale = sums.scale
    ops = _ops(n)
    ranges = ops.check_range(reference_range)
    nf = n.astype(np.float64) if isinstance(n, np.ndarray) else n
    small = n < MIN_GROUP_SAMPLES
    safe_n = ops.where(small, 1.0, nf)
    mae = sums.abs_error / safe_n
    rms = ops.sqrt(sums.sq_error / safe_n)
    error_std = ops.sqrt(sums.error_m2 / ops.where(small, 1.0, nf - 1.0))
    if scale != 1.0:
        mae = mae / scale
        rms = rms / scale
        error_std = error_std / scale
    # RMS ≥ MAE holds mathematically; rounding can break it by an ulp.
    rms = ops.maximum(rms, mae)
    delta_e = rms - mae
    lag_correlation = zero_lag_correlation(
        safe_n, sums.cross, sums.ref_sq, sums.sim_sq, sums.ref_sum, sums.sim_sum, correlation
    )

    def normalised(error: Any) -> Any:
        return ops.clip(1.0 - error / ranges)

    values = {
        "lag_correlation": lag_correlation,
        "derivative_match": sums.sign_matches / safe_n,
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
    :data:`SUM_COLUMNS`), elementwise; both at least 0."""
    nf = n.astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        error_m2 = np.where(n > 0, shifted_sq - shifted_sum**2 / np.maximum(nf, 1.0), 0.0)
    sq_error = np.maximum(shifted_sq + 2.0 * shift * shifted_sum + nf * shift * shift, 0.0)
    return sq_error, np.maximum(error_m2, 0.0)
