"""The field's standard validation metrics, each checked against its source.

One module per family: :mod:`.iso18571` (ISO/TS 18571), :mod:`.theil` (Theil's U and its
proportions), :mod:`.sprague_geers` (Sprague–Geers and Russell), :mod:`.kge` (KGE 2009 and
2012, NSE) and :mod:`.ashrae14` (CV(RMSE) and NMBE, ASHRAE Guideline 14). The registry
(:mod:`pytest_hevval.core.registry`) describes each as a characteristic that a spec switches
on with ``metrics: [...]``. Pure numpy/scipy.
"""

from __future__ import annotations

from .ashrae14 import (
    GUIDELINE14_HOURLY,
    GUIDELINE14_HOURLY_THRESHOLDS,
    GUIDELINE14_MONTHLY,
    CalibrationErrors,
    calibration_errors,
)
from .iso18571 import ISO18571_PARAMETERS, Iso18571Parameters, Iso18571Rating, iso18571_rating
from .kge import KlingGupta, bounded_efficiency, kge, nse
from .sprague_geers import MagnitudePhase, russell, sprague_geers
from .theil import TheilU, theil_u

__all__ = [
    "GUIDELINE14_HOURLY",
    "GUIDELINE14_HOURLY_THRESHOLDS",
    "GUIDELINE14_MONTHLY",
    "ISO18571_PARAMETERS",
    "CalibrationErrors",
    "Iso18571Parameters",
    "Iso18571Rating",
    "KlingGupta",
    "MagnitudePhase",
    "TheilU",
    "bounded_efficiency",
    "calibration_errors",
    "iso18571_rating",
    "kge",
    "nse",
    "russell",
    "sprague_geers",
    "theil_u",
]
