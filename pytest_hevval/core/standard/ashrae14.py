"""CV(RMSE) and NMBE, with the calibration criteria of ASHRAE Guideline 14-2014.

With y the measurement (reference), ŷ the model, ȳ the measurement's mean and p = 1
(ASHRAE Guideline 14-2014, clause 4.3.3.1 and Annex B, for a calibrated simulation):

    CV(RMSE) = √(Σ(y − ŷ)²/(n − p)) / ȳ · 100 %
    NMBE     = Σ(y − ŷ) / ((n − p)·ȳ) · 100 %     (positive: the model is low)

Guideline 14 calls a simulation calibrated to hourly data when |NMBE| ≤ 10 % and
CV(RMSE) ≤ 30 % (monthly data: 5 % and 15 %).

Neither is a [0, 1] rating, so hevval scores 1 − CV(RMSE) and 1 − |NMBE| (as fractions,
clipped to [0, 1]). The Guideline's criteria are then ordinary thresholds — hourly
``cvrmse: 0.70`` and ``nmbe: 0.90`` (:data:`GUIDELINE14_HOURLY_THRESHOLDS`) — and are gates
only when a spec sets them. Both default to weight 0 in Φ: they are pass/fail criteria, not
scores. Both are invariant under a change of units, not under an offset (they are meant for
quantities with a natural zero: energy, power, flow); a negative mean normalises by |ȳ|, and a
reference with mean 0 is refused. The criteria are checked on the samples of hevval's grid;
Guideline 14's monthly limits apply to monthly totals, which a spec does not form.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..registry import CharacteristicValue
from ._inputs import FloatArray
from ._moments import Moments, checked_moments, reference_mean

__all__ = [
    "GUIDELINE14_HOURLY",
    "GUIDELINE14_HOURLY_THRESHOLDS",
    "GUIDELINE14_MONTHLY",
    "CalibrationErrors",
    "calibration_errors",
    "calibration_errors_from_moments",
    "cvrmse_characteristic",
    "cvrmse_characteristic_from_moments",
    "nmbe_characteristic",
    "nmbe_characteristic_from_moments",
]

#: Guideline 14's limits in percent: (|NMBE|, CV(RMSE)).
GUIDELINE14_HOURLY = (10.0, 30.0)
GUIDELINE14_MONTHLY = (5.0, 15.0)
#: The hourly limits as thresholds on hevval's scores 1 − |NMBE| and 1 − CV(RMSE).
GUIDELINE14_HOURLY_THRESHOLDS = {
    "nmbe": 1.0 - GUIDELINE14_HOURLY[0] / 100.0,
    "cvrmse": 1.0 - GUIDELINE14_HOURLY[1] / 100.0,
}
#: Parameters of a calibrated simulation (Guideline 14's p).
_PARAMETERS = 1
_METRIC = "cvrmse/nmbe"


@dataclass(frozen=True)
class CalibrationErrors:
    """CV(RMSE) and NMBE in percent of the reference's mean."""

    cv_rmse: float
    nmbe: float

    def meets(self, limits: tuple[float, float]) -> bool:
        return abs(self.nmbe) <= limits[0] and self.cv_rmse <= limits[1]


def calibration_errors(reference: FloatArray, simulated: FloatArray) -> CalibrationErrors:
    return calibration_errors_from_moments(checked_moments(reference, simulated, _METRIC))


def calibration_errors_from_moments(m: Moments) -> CalibrationErrors:
    """CV(RMSE) and NMBE from a pair's moments (:mod:`._moments`)."""
    sums = m.check(_METRIC).sums
    mean = reference_mean(
        m, _METRIC, "these metrics are for quantities with a natural zero; use theil"
    )
    # The residual y − ŷ is the λ pass's e = ref − sim.
    dof = sums.n - _PARAMETERS
    cv = math.sqrt(sums.sq_error / dof) / abs(mean) * 100.0
    bias = sums.error_sum / (dof * abs(mean)) * 100.0
    return CalibrationErrors(cv, bias)


def _components(e: CalibrationErrors) -> dict[str, float]:
    return {
        "CV_RMSE_percent": e.cv_rmse,
        "NMBE_percent": e.nmbe,
        "meets_guideline14_hourly": float(e.meets(GUIDELINE14_HOURLY)),
    }


def cvrmse_characteristic(
    reference: FloatArray, simulated: FloatArray, dt: float
) -> CharacteristicValue:
    """The registry's ``cvrmse``: 1 − CV(RMSE), with both errors and the criteria met."""
    return cvrmse_characteristic_from_moments(checked_moments(reference, simulated, _METRIC))


def cvrmse_characteristic_from_moments(m: Moments) -> CharacteristicValue:
    """:func:`cvrmse_characteristic` from a pair's moments."""
    e = calibration_errors_from_moments(m)
    return CharacteristicValue(min(1.0, max(0.0, 1.0 - e.cv_rmse / 100.0)), _components(e))


def nmbe_characteristic(
    reference: FloatArray, simulated: FloatArray, dt: float
) -> CharacteristicValue:
    """The registry's ``nmbe``: 1 − |NMBE|, with both errors and the criteria met."""
    return nmbe_characteristic_from_moments(checked_moments(reference, simulated, _METRIC))


def nmbe_characteristic_from_moments(m: Moments) -> CharacteristicValue:
    """:func:`nmbe_characteristic` from a pair's moments."""
    e = calibration_errors_from_moments(m)
    return CharacteristicValue(min(1.0, max(0.0, 1.0 - abs(e.nmbe) / 100.0)), _components(e))
