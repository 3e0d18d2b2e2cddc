"""Shared test set-up.

Inline pytester runs (``pytester.runpytest``) restore ``sys.modules`` afterwards, removing
whatever the run imported. The plugin imports the engine only once ``--hevval`` is given, so
the first inline run would import numpy and the restore would remove it again; a second import
of numpy's C extensions in one process fails. Importing the engine here keeps the numeric stack
loaded for the whole test session.
"""

from __future__ import annotations

from pytest_hevval import engine, session

_KEPT_LOADED = (engine, session)
