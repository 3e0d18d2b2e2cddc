"""Is an error within the measurement uncertainty? The rule, in one place.

A signal may declare its sensor's accuracy (``uncertainty: {abs, rel, sigma}`` in the spec).
For every missed threshold of an error characteristic (λ3 MAE, λ4 RMS, λ5 RMS−MAE, λ6 σ; each
λ = 1 − E/R) this module gives the error's limit, the margin by which the error exceeds it, and
whether that margin lies within the expanded measurement uncertainty (docs/uncertainty.md,
"Measurement uncertainty").

Pure Python: no numpy, no files, no pytest. The check of one missed threshold, as a result,
is :class:`pytest_hevval.results.measurement.ErrorCheck`.

Notes
-----
Following ASME V&V 20-2009 (§2.4, §4), the validation comparison error is E = S − D and the
uncertainty of the data D is u_D. A declared accuracy is read as an expanded uncertainty
U = k·u stated at coverage factor k = ``sigma`` (``sigma: 2`` means "±abs is 2σ"). With y_ref
the measured reference on the scoring grid:

* u_D = √(abs² + (rel · RMS(y_ref))²) / k: the offset-like part ``abs`` and the
  reading-proportional part ``rel``·y_ref combined by root-sum-square as independent
  components (GUM §5.1.2); ``rel`` is applied to RMS(y_ref), the RMS of a reading-proportional
  error rel·y_ref over the record.
* U_D = k·u_D, reported at the same coverage k the figures were stated at.
* An error E with threshold t on a range R has the limit E_lim = (1 − t)·R and the margin
  m = E − E_lim (> 0 when the threshold is missed). The miss is *within measurement
  uncertainty* when m ≤ U_D.

Why U_D bounds the margin: a measurement error δ shifts e = y_ref − y_sim to e + δ, and by
Minkowski's inequality |RMS(e + δ) − RMS(e)| ≤ RMS(δ), |MAE(e + δ) − MAE(e)| ≤ MAE(δ) ≤ RMS(δ)
and |σ(e + δ) − σ(e)| ≤ σ(δ) ≤ RMS(δ). So an error that exceeds its limit by no more than the
measurement's own RMS error could be an artefact of the sensor. For λ5 (RMS − MAE) the shift
can reach 2·RMS(δ); U_D is used there too, which errs towards failing. Only u_D is counted:
u_num and u_input of V&V 20 are not declared in a spec, so U_val ≥ U_D.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from ..defaults import UNCERTAINTY_SIGMA

__all__ = [
    "ERROR_CHARACTERISTICS",
    "MeasurementUncertainty",
    "WithinUncertainty",
    "error_limit",
]

#: What a threshold miss within the measurement uncertainty does: fail the item, or pass it
#: with a note (the spec's ``measurement.within_uncertainty``).
WithinUncertainty = Literal["fail", "pass"]

#: The error characteristics λ = 1 − E/R, by name: (physical error key, how the error is named).
ERROR_CHARACTERISTICS: dict[str, tuple[str, str]] = {
    "mae": ("mae", "MAE"),
    "rms": ("rms", "RMS"),
    "anomaly": ("delta_e", "RMS−MAE"),
    "error_std": ("error_std", "σ"),
}


@dataclass(frozen=True)
class MeasurementUncertainty:
    """A sensor's declared accuracy: ±(abs ⊕ rel·reading), stated at coverage factor ``sigma``.

    ``abs`` is in the signal's unit, ``rel`` a fraction of the reading (0.01 for 1 %),
    ``sigma`` the coverage factor k the two figures are stated at (2 for ±2σ).
    """

    abs: float = 0.0
    rel: float = 0.0
    sigma: float = UNCERTAINTY_SIGMA
    line: int = 0

    def standard(self, reference_rms: float) -> float:
        """u_D = √(abs² + (rel · RMS(y_ref))²) / sigma, in the signal's unit."""
        return self.expanded(reference_rms) / self.sigma

    def expanded(self, reference_rms: float) -> float:
        """U_D = sigma · u_D = √(abs² + (rel · RMS(y_ref))²), in the signal's unit."""
        return math.hypot(self.abs, self.rel * abs(reference_rms))


def error_limit(threshold: float, reference_range: float) -> float:
    """E_lim = (1 − threshold)·R: the error at which λ = 1 − E/R meets ``threshold``."""
    return (1.0 - threshold) * reference_range
