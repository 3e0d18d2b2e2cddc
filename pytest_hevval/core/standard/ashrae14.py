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

from dataclasses import dataclass

import numpy as np

from ..registry import CharacteristicValue
from ._inputs import FloatArray, checked_pair, reference_mean

__all__ = [
    "GUIDELINE14_HOURLY",
    "GUIDELINE14_HOURLY_THRESHOLDS",
    "GUIDELINE14_MONTHLY",
    "CalibrationErrors",
    "calibration_errors",
    "cvrmse_characteristic",
    "nmbe_characteristic",
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


@dataclass(frozen=True)
class CalibrationErrors:
    """CV(RMSE) and NMBE in percent of the reference's mean."""

    cv_rmse: float
    nmbe: float

    def meets(self, limits: tuple[float, float]) -> bool:
        return abs(self.nmbe) <= limits[0] and self.cv_rmse <= limits[1]


def calibration_errors(reference: FloatArray, simulated: FloatArray) -> CalibrationErrors:
    ref, sim = checked_pair(reference, simulated, metric="cvrmse/nmbe")
    scale = float(np.max(np.abs(ref)))
    y, y_hat = ref / scale, sim / scale
    mean = reference_mean(
        y, "cvrmse/nmbe", "these metrics are for quantities with a natural zero; use theil"
    )
    residual = y - y_hat
    dof = y.shape[0] - _PARAMETERS
    cv = float(np.sqrt(np.sum(residual**2) / dof)) / abs(mean) * 100.0
    bias = float(np.sum(residual)) / (dof * abs(mean)) * 100.0
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
    e = calibration_errors(reference, simulated)
    return CharacteristicValue(min(1.0, max(0.0, 1.0 - e.cv_rmse / 100.0)), _components(e))


def nmbe_characteristic(
    reference: FloatArray, simulated: FloatArray, dt: float
) -> CharacteristicValue:
    """The registry's ``nmbe``: 1 − |NMBE|, with both errors and the criteria met."""
    e = calibration_errors(reference, simulated)
    return CharacteristicValue(min(1.0, max(0.0, 1.0 - abs(e.nmbe) / 100.0)), _components(e))
