"""Kling–Gupta efficiency (2009 and 2012 forms) and the Nash–Sutcliffe efficiency.

With o the reference (observation), s the model, r Pearson's correlation, μ and σ the means
and (population) standard deviations:

* **NSE** (Nash & Sutcliffe 1970, *J. Hydrol.* 10, eq. 1): NSE = 1 − Σ(s − o)²/Σ(o − ō)².
  NSE = 0 is a model no better than the reference's mean.
* **KGE 2009** (Gupta, Kling, Yilmaz & Martinez 2009, *J. Hydrol.* 377, eq. 9):
  KGE = 1 − √((r − 1)² + (α − 1)² + (β − 1)²), α = σ_s/σ_o, β = μ_s/μ_o. The same paper
  (eq. 4) decomposes NSE = 2αr − α² − β_n² with β_n = (μ_s − μ_o)/σ_o; the tests check it.
* **KGE 2012** (Kling, Fuchs & Paulin 2012, *J. Hydrol.* 424–425, eq. 3): α is replaced by
  the ratio of coefficients of variation γ = (σ_s/μ_s)/(σ_o/μ_o), so bias and variability do
  not cross-correlate.

All three lie in (−∞, 1]. hevval scores them bounded: 1/(2 − E) (Nossent & Bauwens 2012's
normalised NSE, applied alike to KGE), a strictly increasing map of (−∞, 1] onto (0, 1] with
1 ↦ 1 and 0 ↦ 0.5, so a threshold on the score is a threshold on the efficiency. The raw
efficiency and its parts are the components. NSE is invariant under a common change of units
and offset; KGE under a change of units only (β and γ use the mean). KGE needs a nonzero
reference mean.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..registry import CharacteristicValue
from ._inputs import FloatArray, degenerate
from ._moments import Moments, checked_moments, reference_mean

__all__ = [
    "KlingGupta",
    "bounded_efficiency",
    "kge",
    "kge2012_characteristic",
    "kge2012_characteristic_from_moments",
    "kge_characteristic",
    "kge_characteristic_from_moments",
    "kge_from_moments",
    "nse",
    "nse_characteristic",
    "nse_characteristic_from_moments",
    "nse_from_moments",
]


@dataclass(frozen=True)
class KlingGupta:
    """KGE and its parts; ``variability`` is α (2009) or γ (2012)."""

    kge: float
    r: float
    variability: float
    beta: float


def bounded_efficiency(efficiency: float) -> float:
    """1/(2 − E): (−∞, 1] onto (0, 1], 1 ↦ 1, 0 ↦ 0.5 (Nossent & Bauwens 2012)."""
    return 1.0 / (2.0 - min(1.0, efficiency))


def nse(reference: FloatArray, simulated: FloatArray) -> float:
    return nse_from_moments(checked_moments(reference, simulated, "nse"))


def nse_from_moments(m: Moments) -> float:
    """NSE from a pair's moments (:mod:`._moments`): 1 − Σe²/Σ(o − ō)²."""
    return 1.0 - m.check("nse").sums.sq_error / m.ref_m2


def kge(reference: FloatArray, simulated: FloatArray, *, form: int = 2009) -> KlingGupta:
    metric = "kge" if form == 2009 else "kge2012"
    return kge_from_moments(checked_moments(reference, simulated, metric), form=form)


def kge_from_moments(m: Moments, *, form: int = 2009) -> KlingGupta:
    """KGE from a pair's moments (:mod:`._moments`)."""
    metric = "kge" if form == 2009 else "kge2012"
    m.check(metric)
    mu_o = reference_mean(m, metric, "use nse or theil for signals that swing about zero")
    mu_s = m.sim_mean
    sigma_o, sigma_s = math.sqrt(m.ref_m2 / m.n), math.sqrt(m.sim_m2 / m.n)
    if sigma_s == 0.0:
        raise degenerate(
            metric,
            "the simulated signal is constant, so its correlation r is undefined",
            "check the model output's column",
        )
    r = (m.co_m2 / m.n) / (sigma_o * sigma_s)
    beta = mu_s / mu_o
    if form == 2009:
        variability = sigma_s / sigma_o
    else:
        if mu_s == 0.0:
            raise degenerate(
                metric,
                "the simulated signal's mean is 0, so its coefficient of variation is undefined",
                "use kge (2009) or nse",
            )
        variability = (sigma_s / mu_s) / (sigma_o / mu_o)
    value = 1.0 - math.sqrt((r - 1.0) ** 2 + (variability - 1.0) ** 2 + (beta - 1.0) ** 2)
    return KlingGupta(value, r, variability, beta)


def nse_characteristic(
    reference: FloatArray, simulated: FloatArray, dt: float
) -> CharacteristicValue:
    """The registry's ``nse``: 1/(2 − NSE), with NSE as the component."""
    return nse_characteristic_from_moments(checked_moments(reference, simulated, "nse"))


def nse_characteristic_from_moments(m: Moments) -> CharacteristicValue:
    """:func:`nse_characteristic` from a pair's moments."""
    value = nse_from_moments(m)
    return CharacteristicValue(bounded_efficiency(value), {"NSE": value})


def _kge_value(k: KlingGupta, variability: str) -> CharacteristicValue:
    parts = {"KGE": k.kge, "r": k.r, variability: k.variability, "beta": k.beta}
    return CharacteristicValue(bounded_efficiency(k.kge), parts)


def kge_characteristic(
    reference: FloatArray, simulated: FloatArray, dt: float
) -> CharacteristicValue:
    """The registry's ``kge``: 1/(2 − KGE) of the 2009 form, with KGE, r, α and β."""
    return kge_characteristic_from_moments(checked_moments(reference, simulated, "kge"))


def kge_characteristic_from_moments(m: Moments) -> CharacteristicValue:
    """:func:`kge_characteristic` from a pair's moments."""
    return _kge_value(kge_from_moments(m, form=2009), "alpha")


def kge2012_characteristic(
    reference: FloatArray, simulated: FloatArray, dt: float
) -> CharacteristicValue:
    """The registry's ``kge2012``: 1/(2 − KGE′), with KGE′, r, γ and β."""
    return kge2012_characteristic_from_moments(checked_moments(reference, simulated, "kge2012"))


def kge2012_characteristic_from_moments(m: Moments) -> CharacteristicValue:
    """:func:`kge2012_characteristic` from a pair's moments."""
    return _kge_value(kge_from_moments(m, form=2012), "gamma")
