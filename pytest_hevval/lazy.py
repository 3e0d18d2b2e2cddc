"""The package's own modules imported on first use, one thread at a time."""

from __future__ import annotations

import importlib
import threading
from types import ModuleType

__all__ = ["import_own"]

_IMPORTING = threading.RLock()


def import_own(name: str, package: str | None = None) -> ModuleType:
    """``importlib.import_module`` for a module of this package, one thread at a time.

    Under pytest, the plugin's modules are imported through pytest's assertion rewriting, which
    parses their source with :mod:`ast`; on Python 3.11 two threads parsing at once can fail
    with ``SystemError: AST constructor recursion depth mismatch``. Specs evaluated side by
    side (Dask worker threads) and signals scored side by side import the readers, metrics and
    kernel they need on first use, so those imports take turns.
    """
    with _IMPORTING:
        return importlib.import_module(name, package)
