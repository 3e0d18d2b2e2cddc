"""The pure computational core: numpy and scipy only, no files, no pytest, no YAML."""

from typing import TYPE_CHECKING, Any

from .characteristics import (
    CHARACTERISTIC_LABELS,
    CHARACTERISTICS,
    SignalCharacteristics,
    normalised_error,
    signal_characteristics,
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

if TYPE_CHECKING:
    from .residual import *  # noqa: F403

# Diagnosis needs scipy.signal and scipy.stats (over a second to import); scoring does not.
_DIAGNOSIS = {
    "Candidate",
    "CandidateFinding",
    "Diagnosis",
    "Whiteness",
    "diagnose_residual",
    "ljung_box",
}


def __getattr__(name: str) -> Any:
    if name in _DIAGNOSIS:
        from . import residual

        return getattr(residual, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "CHARACTERISTICS",
    "CHARACTERISTIC_LABELS",
    "LagSearch",
    "ScoredNode",
    "SignalCharacteristics",
    "TreeNode",
    "correlation_curve",
    "emergent",
    "error_origins",
    "global_metric",
    "iter_nodes",
    "normalised_error",
    "score_tree",
    "search_lag",
    "signal_characteristics",
    *sorted(_DIAGNOSIS),
]
