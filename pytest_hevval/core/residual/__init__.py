"""Residual diagnosis: which effect does the model lack, and is there one at all?

One aligned pair (reference, simulated) and a set of explanatory candidate series go in
(:func:`diagnose_residual`); a :class:`Diagnosis` comes out. Each step has a room of its own:

- :mod:`.thresholds`: the settings the diagnosis judges by;
- :mod:`.findings`: the typed, immutable values that go in and come out;
- :mod:`.inputs`: the inputs checked and brought to scale;
- :mod:`.inference`: intervals, p-values and R² that every step shares;
- :mod:`.headline`: timing, gain and offset of the simulated signal itself;
- :mod:`.candidates`: candidate series on the grids, dropped when constant or collinear,
  grouped when they measure one effect;
- :mod:`.responses`: channels set apart as responses and echoes of the scored signal;
- :mod:`.selection`: the Holm-guarded forward selection on the filtered GLS tests and each
  candidate's finding;
- :mod:`.sizing`: least-squares sizes with the AR-model covariance on the coarsest passing
  scale, and each effect's own fix;
- :mod:`.shares`: Shapley shares in the gatekeeping order, and interchangeable effects;
- :mod:`.effects`: the effects one can act on, their predicted λ and where the residual
  concentrates;
- :mod:`.diagnose`: :func:`diagnose_residual`, the steps in order.

Pure numpy/scipy, no wording: the layers above word the findings.
"""

from ..stats import Whiteness, ljung_box
from .diagnose import diagnose_residual
from .findings import (
    Candidate,
    CandidateFinding,
    Diagnosis,
    Effect,
    Localisation,
    Note,
    Response,
)
from .thresholds import (
    GENERIC_KINDS,
    MIN_EXPLAINED_INCREASE,
    MIN_SHARE,
    PREDICTED_CHARACTERISTICS,
    SLOW_SCALE_S,
)

__all__ = [
    "GENERIC_KINDS",
    "MIN_EXPLAINED_INCREASE",
    "MIN_SHARE",
    "PREDICTED_CHARACTERISTICS",
    "SLOW_SCALE_S",
    "Candidate",
    "CandidateFinding",
    "Diagnosis",
    "Effect",
    "Localisation",
    "Note",
    "Response",
    "Whiteness",
    "diagnose_residual",
    "ljung_box",
]
