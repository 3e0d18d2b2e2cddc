"""The small inference helpers every step of the diagnosis shares: Student-t intervals and
two-sided p-values, whether an interval excludes zero, unit scaling of an interval, and the
centred R² of a residual on a few columns at the original rate."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ..stats import RCOND, FloatArray, dot


def _excludes_zero(interval: tuple[float, float]) -> bool:
    return not interval[0] <= 0.0 <= interval[1]


def _interval(beta: float, se: float, df: int, alpha: float) -> tuple[float, float]:
    from scipy import stats  # over a second to import; scoring never needs it

    half = float(stats.t.ppf(1.0 - alpha / 2.0, df)) * se
    return (beta - half, beta + half)


def _p_value(beta: float, se: float, df: int) -> float:
    if se <= 0.0 or not math.isfinite(se):
        return 0.0 if beta != 0.0 and se == 0.0 else 1.0
    from scipy import stats

    return float(2.0 * stats.t.sf(abs(beta) / se, df))


def _scaled(interval: tuple[float, float], unit: float) -> tuple[float, float]:
    return (interval[0] * unit, interval[1] * unit)


def _full_rate_r2(r: FloatArray, columns: Sequence[FloatArray]) -> float:
    """Centred R² of r on an intercept and ``columns``, from their Gram matrix."""
    if not columns:
        return 0.0
    rc = r - float(np.mean(r))
    total = dot(rc, rc)
    if total <= 0.0:
        return 0.0
    centred = [c - float(np.mean(c)) for c in columns]
    k = len(centred)
    gram = np.empty((k, k))
    cross = np.empty(k)
    for i in range(k):
        cross[i] = dot(centred[i], rc)
        for j in range(i, k):
            gram[i, j] = gram[j, i] = dot(centred[i], centred[j])
    coef = np.linalg.pinv(gram, rcond=RCOND) @ cross
    return float(min(max(float(coef @ cross) / total, 0.0), 1.0))
