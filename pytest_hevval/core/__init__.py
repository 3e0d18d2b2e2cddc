"""The pure computational core: numpy and scipy only, no files, no pytest, no YAML."""

from .characteristics import (
    CHARACTERISTIC_LABELS,
    CHARACTERISTICS,
    SignalCharacteristics,
    normalised_error,
    signal_characteristics,
)
from .diagnosis import (
    Candidate,
    CandidateFinding,
    Diagnosis,
    Whiteness,
    diagnose_residual,
    ljung_box,
)
from .lag import LagSearch, correlation_curve, search_lag
from .tree import (
    ScoredNode,
    TreeNode,
    emergent,
    error_origins,
    global_metric,
    iter_nodes,
    score_tree,
)

__all__ = [
    "CHARACTERISTICS",
    "CHARACTERISTIC_LABELS",
    "Candidate",
    "CandidateFinding",
    "Diagnosis",
    "LagSearch",
    "ScoredNode",
    "SignalCharacteristics",
    "TreeNode",
    "Whiteness",
    "correlation_curve",
    "diagnose_residual",
    "emergent",
    "error_origins",
    "global_metric",
    "iter_nodes",
    "ljung_box",
    "normalised_error",
    "score_tree",
    "search_lag",
    "signal_characteristics",
]
