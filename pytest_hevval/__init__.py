"""pytest-hevval: multi-fidelity behavioural validation of simulation models.

The public API, importable without pytest or matplotlib being loaded::

    from pytest_hevval import signal_characteristics, global_metric

Names are resolved on first use (PEP 562), so ``import pytest_hevval`` — which pytest does
for every run in an environment where the plugin is installed — loads no numpy, pandas or
scipy.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from .errors import CharacteristicError, DataError, ExpressionError, HevvalError, SpecError
from .lazy import import_own

if TYPE_CHECKING:
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


def _version() -> str:
    """The installed distribution's version; from pyproject.toml when run from a source tree."""
    from importlib import metadata

    try:
        return metadata.version("pytest-hevval")
    except metadata.PackageNotFoundError:
        import re
        from pathlib import Path

        pyproject = Path(__file__).resolve().parent.parent / "pyproject.toml"
        found = re.search(r'^version = "([^"]+)"', pyproject.read_text("utf-8"), re.MULTILINE)
        return found.group(1) if found else "unknown"


#: One source: ``version`` in pyproject.toml (installed as the distribution's metadata).
__version__ = _version()

#: Public name → the module that defines it, imported when the name is first used.
_LAZY: dict[str, str] = {
    "CHARACTERISTICS": ".core",
    "ScoredNode": ".core",
    "SignalCharacteristics": ".core",
    "TreeNode": ".core",
    "emergent": ".core",
    "error_origins": ".core",
    "global_metric": ".core",
    "normalised_error": ".core",
    "score_tree": ".core",
    "signal_characteristics": ".core",
    "Characteristic": ".core.registry",
    "CharacteristicValue": ".core.registry",
    "register_characteristic": ".core.registry",
}

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


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_own(module, __name__), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
