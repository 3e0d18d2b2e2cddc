"""pytest-hevval: multi-fidelity behavioural validation of simulation models.

The public API, importable without pytest or matplotlib being loaded::

    from pytest_hevval import signal_characteristics, global_metric
"""

from .core import (
    CHARACTERISTICS,
    ScoredNode,
    SignalCharacteristics,
    TreeNode,
    emergent,
    error_origins,
    global_metric,
    normalised_error,
    score_tree,
    signal_characteristics,
)
from .core.registry import Characteristic, CharacteristicValue, register_characteristic
from .errors import CharacteristicError, DataError, ExpressionError, HevvalError, SpecError

__version__ = "0.1.0"

__all__ = [
    "CHARACTERISTICS",
    "Characteristic",
    "CharacteristicError",
    "CharacteristicValue",
    "DataError",
    "ExpressionError",
    "HevvalError",
    "ScoredNode",
    "SignalCharacteristics",
    "SpecError",
    "TreeNode",
    "__version__",
    "emergent",
    "error_origins",
    "global_metric",
    "normalised_error",
    "register_characteristic",
    "score_tree",
    "signal_characteristics",
]
