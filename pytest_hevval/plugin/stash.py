"""The key under which a pytest session keeps its hevval state.

A module of its own, importing nothing heavy, so the plugin can ask whether hevval is active
without loading the engine (and numpy, pandas, scipy) into every pytest run.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    from .session import HevvalSession

__all__ = ["session_key", "state_of"]

session_key: pytest.StashKey[HevvalSession] = pytest.StashKey()


def state_of(config: pytest.Config) -> HevvalSession | None:
    """The session state when ``--hevval`` is active in this run, else None."""
    return config.stash.get(session_key, None)
