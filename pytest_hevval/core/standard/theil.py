"""Theil's inequality coefficient U and its bias, variance and covariance proportions.

Theil, H. (1961/1966) *Applied Economic Forecasting*, ch. 2:

    U = √(mean (s − r)²) / (√(mean s²) + √(mean r²)),   0 ≤ U ≤ 1,

U = 0 for a perfect model, U = 1 for a model that predicts 0 throughout or is negatively
proportional to the reference (both stated by Theil). The mean squared error splits exactly into

    mean (s − r)² = (s̄ − r̄)² + (σ_s − σ_r)² + 2(1 − ρ)σ_s σ_r      (population σ),

and U_M, U_S, U_C are those three terms over the MSE: bias, unequal variation and imperfect
covariation; they sum to 1. Both square roots of the denominator are kept: without them U
changes with the signal's units.

hevval scores 1 − U (1 = perfect, in [0, 1] by Theil's bound). U is invariant under a change of
units (s, r → k·s, k·r) but not under an offset.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..registry import CharacteristicValue
from ._inputs import FloatArray
from ._moments import Moments, checked_moments

__all__ = [
    "TheilU",
    "theil_characteristic",
    "theil_characteristic_from_moments",
    "theil_from_moments",
    "theil_u",
]


@dataclass(frozen=True)
class TheilU:
    """U and its proportions (all 0 when the model is perfect: the split is then undefined)."""

    u: float
    bias: float
    variance: float
    covariance: float


def theil_u(reference: FloatArray, simulated: FloatArray) -> TheilU:
    return theil_from_moments(checked_moments(reference, simulated, "theil"))


def theil_from_moments(m: Moments) -> TheilU:
    """U and its proportions from a pair's moments (:mod:`._moments`)."""
    sums = m.check("theil").sums
    if sums.sq_error == 0.0:
        return TheilU(0.0, 0.0, 0.0, 0.0)
    n = sums.n
    # √mean(e²)/(√mean(s²) + √mean(r²)): the n cancels.
    u = math.sqrt(sums.sq_error) / (math.sqrt(sums.sim_sq) + math.sqrt(sums.ref_sq))
    sigma_s = math.sqrt(m.sim_m2 / n)
    sigma_r = math.sqrt(m.ref_m2 / n)
    # e = r − s, so s̄ − r̄ = −ē.
    bias = (sums.error_sum / n) ** 2
    variance = (sigma_s - sigma_r) ** 2
    # 2(1 − ρ)σ_sσ_r = σ_s² + σ_r² − 2cov = var(s − r) − (σ_s − σ_r)²: no division by σ.
    covariance = max(0.0, sums.error_m2 / n - variance)
    total = bias + variance + covariance
    return TheilU(min(1.0, u), bias / total, variance / total, covariance / total)


def theil_characteristic(
    reference: FloatArray, simulated: FloatArray, dt: float
) -> CharacteristicValue:
    """The registry's ``theil``: 1 − U, with U, U_M, U_S and U_C as components."""
    return theil_characteristic_from_moments(checked_moments(reference, simulated, "theil"))


def theil_characteristic_from_moments(m: Moments) -> CharacteristicValue:
    """:func:`theil_characteristic` from a pair's moments."""
    t = theil_from_moments(m)
    return CharacteristicValue(
        1.0 - t.u, {"U": t.u, "U_M": t.bias, "U_S": t.variance, "U_C": t.covariance}
    )
