"""A missed error threshold checked against the measurement uncertainty, as a result.

The rule (:mod:`pytest_hevval.core.measurement`) is pure arithmetic; this is its outcome for one
missed threshold, in the signal's unit, and its JSON form.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ..core.measurement import MeasurementUncertainty, error_limit

__all__ = ["ErrorCheck", "check_error"]


@dataclass(frozen=True)
class ErrorCheck:
    """One missed error threshold against the measurement uncertainty (signal's unit)."""

    #: The error E (MAE, RMS, RMS−MAE or σ).
    error: float
    #: E_lim = (1 − threshold)·R: the largest error the threshold accepts.
    limit: float
    #: E − E_lim: by how much the error exceeds its limit.
    margin: float
    #: U_D at coverage ``sigma``; None when the signal declares no uncertainty.
    uncertainty: float | None = None
    #: u_D, the standard uncertainty (U_D / sigma).
    standard_uncertainty: float | None = None
    sigma: float | None = None

    @property
    def within(self) -> bool | None:
        """Whether the margin lies within U_D (None: no uncertainty declared)."""
        if self.uncertainty is None:
            return None
        return self.margin <= self.uncertainty

    def to_dict(self) -> dict[str, Any]:
        return {
            "error": self.error,
            "limit": self.limit,
            "margin": self.margin,
            "uncertainty": self.uncertainty,
            "standard_uncertainty": self.standard_uncertainty,
            "sigma": self.sigma,
            "within": self.within,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ErrorCheck:
        def optional(key: str) -> float | None:
            value = data.get(key)
            return None if value is None else float(value)

        return cls(
            error=float(data["error"]),
            limit=float(data["limit"]),
            margin=float(data["margin"]),
            uncertainty=optional("uncertainty"),
            standard_uncertainty=optional("standard_uncertainty"),
            sigma=optional("sigma"),
        )


def check_error(
    error: float,
    threshold: float,
    reference_range: float,
    uncertainty: MeasurementUncertainty | None = None,
    reference_rms: float = 0.0,
) -> ErrorCheck:
    """The limit and margin of ``error`` and, with a declared uncertainty, U_D beside them."""
    limit = error_limit(threshold, reference_range)
    if uncertainty is None:
        return ErrorCheck(error=error, limit=limit, margin=error - limit)
    return ErrorCheck(
        error=error,
        limit=limit,
        margin=error - limit,
        uncertainty=uncertainty.expanded(reference_rms),
        standard_uncertainty=uncertainty.standard(reference_rms),
        sigma=uncertainty.sigma,
    )
