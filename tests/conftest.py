"""Shared test set-up.

Inline pytester runs (``pytester.runpytest``) restore ``sys.modules`` afterwards, removing
whatever the run imported. The plugin imports the engine only once ``--hevval`` is given, and
the readers import pandas and pyarrow only when a file is read, so the first inline run would
import them and the restore would remove them again. A second import of numpy's C extensions,
or of pyarrow's extension types, in one process fails. Importing them here keeps them loaded
for the whole test session, whatever order the tests run in.
"""

from __future__ import annotations

import contextlib
import importlib

from pytest_hevval import engine, session

_KEPT_LOADED = [engine, session, importlib.import_module("pandas")]
with contextlib.suppress(ImportError):  # the parquet extra
    _KEPT_LOADED.append(importlib.import_module("pyarrow"))
