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

import numpy as np

from ..registry import CharacteristicValue
from ._inputs import FloatArray, checked_pair, degenerate, reference_mean

__all__ = [
    "KlingGupta",
    "bounded_efficiency",
    "kge",
    "kge2012_characteristic",
    "kge_characteristic",
    "nse",
    "nse_characteristic",
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
    ref, sim = checked_pair(reference, simulated, metric="nse")
    scale = float(np.ptp(ref))
    o, s = ref / scale, sim / scale
    return 1.0 - float(np.sum((s - o) ** 2)) / float(np.sum((o - o.mean()) ** 2))


def kge(reference: FloatArray, simulated: FloatArray, *, form: int = 2009) -> KlingGupta:
    metric = "kge" if form == 2009 else "kge2012"
    ref, sim = checked_pair(reference, simulated, metric=metric)
    scale = float(np.max(np.abs(ref)))
    o, s = ref / scale, sim / scale
    mu_o = reference_mean(o, metric, "use nse or theil for signals that swing about zero")
    mu_s = float(s.mean())
    sigma_o, sigma_s = float(o.std()), float(s.std())
    if sigma_s == 0.0:
        raise degenerate(
            metric,
            "the simulated signal is constant, so its correlation r is undefined",
            "check the model output's column",
        )
    r = float(np.mean((o - mu_o) * (s - mu_s))) / (sigma_o * sigma_s)
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
    value = nse(reference, simulated)
    return CharacteristicValue(bounded_efficiency(value), {"NSE": value})


def _kge_value(k: KlingGupta, variability: str) -> CharacteristicValue:
    parts = {"KGE": k.kge, "r": k.r, variability: k.variability, "beta": k.beta}
    return CharacteristicValue(bounded_efficiency(k.kge), parts)


def kge_characteristic(
    reference: FloatArray, simulated: FloatArray, dt: float
) -> CharacteristicValue:
    """The registry's ``kge``: 1/(2 − KGE) of the 2009 form, with KGE, r, α and β."""
    return _kge_value(kge(reference, simulated, form=2009), "alpha")


def kge2012_characteristic(
    reference: FloatArray, simulated: FloatArray, dt: float
) -> CharacteristicValue:
    """The registry's ``kge2012``: 1/(2 − KGE′), with KGE′, r, γ and β."""
    return _kge_value(kge(reference, simulated, form=2012), "gamma")
