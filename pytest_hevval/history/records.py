"""History records: the facts a record keeps about a run (model version, commit, tool versions)
and the record of a run, built through the run envelope.

The record's layout, its validation and the migration of older schemas live with the results
(:mod:`pytest_hevval.results.record_schema`), as one of the envelopes around a run's results
(:mod:`pytest_hevval.results.envelope`); they are re-exported here, where the history's users
have always found them. See ``docs/history.md`` for the format.
"""

from __future__ import annotations

import platform
import subprocess
from collections.abc import Mapping, Sequence
from datetime import datetime
from importlib import metadata
from pathlib import Path
from typing import Any

from ..defaults import UNKNOWN_MODEL_VERSION
from ..flags import PYTEST, FrontEnd
from ..results.envelope import history_record
from ..results.record_schema import (
    ACCEPTANCE,
    EARLIER_SCHEMA,
    SCHEMA_VERSION,
    baseline_summary,
    format_utc,
    migrate_record,
    parse_utc,
    validate_record,
)
from ._base import HistoryError

__all__ = [
    "ACCEPTANCE",
    "EARLIER_SCHEMA",
    "MODEL_VERSION_ENV",
    "SCHEMA_VERSION",
    "baseline_summary",
    "default_tool_versions",
    "format_utc",
    "make_record",
    "migrate_record",
    "parse_utc",
    "record_time",
    "resolve_commit",
    "resolve_model_version",
    "validate_record",
]

MODEL_VERSION_ENV = "HEVVAL_MODEL_VERSION"
_GIT_TIMEOUT_S = 5.0


def record_time(record: Mapping[str, Any]) -> datetime:
    """The start time of a (validated, schema 2) record."""
    return parse_utc(record["started_utc"])


def default_tool_versions() -> dict[str, str]:
    """Versions of pytest-hevval, numpy, scipy, pandas and Python, the scoring path (``kernel``:
    numba or numpy) and the platform, for reproducing a recorded run."""
    from ..core.kernel import loaded_path

    versions: dict[str, str] = {}
    for dist in ("pytest-hevval", "numpy", "scipy", "pandas"):
        try:
            versions[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            versions[dist] = "unknown"
    versions["python"] = platform.python_version()
    versions["kernel"] = loaded_path()
    versions["platform"] = platform.platform()
    return versions


def resolve_model_version(cli_value: str | None, env: Mapping[str, str], cwd: Path) -> str:
    """The model version a run is recorded under.

    Precedence: the ``--hevval-model-version`` value, then ``$HEVVAL_MODEL_VERSION``, then
    ``git describe --always --dirty`` in ``cwd``, then ``"unknown"`` (not a git checkout, git
    missing, or git too slow).
    """
    for candidate in (cli_value, env.get(MODEL_VERSION_ENV)):
        if candidate is not None and candidate.strip():
            return candidate.strip()
    return _git(cwd, "describe", "--always", "--dirty") or UNKNOWN_MODEL_VERSION


def _git(cwd: Path, *arguments: str) -> str | None:
    """What ``git ARGUMENTS`` prints in ``cwd``, or ``None`` when it cannot say (not a git
    checkout, git missing, or git too slow)."""
    try:
        completed = subprocess.run(
            ["git", *arguments],
            cwd=cwd,
            capture_output=True,
            text=True,
            timeout=_GIT_TIMEOUT_S,
            check=False,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    printed = completed.stdout.strip()
    return printed if completed.returncode == 0 and printed else None


def resolve_commit(cwd: Path) -> str | None:
    """The git commit checked out in ``cwd`` (``git rev-parse HEAD``), or ``None``."""
    return _git(cwd, "rev-parse", "--verify", "-q", "HEAD")


def make_record(
    spec_results: Sequence[Mapping[str, Any]],
    *,
    model_version: str,
    tool_versions: Mapping[str, str] | None = None,
    started_utc: datetime,
    acceptance: str = "not-compared",
    commit: str | None = None,
    baseline: Mapping[str, Any] | None = None,
    front_end: FrontEnd = PYTEST,
) -> dict[str, Any]:
    """Build a history record from the run's spec results.

    ``tool_versions`` is laid over :func:`default_tool_versions`, so the versions of
    pytest-hevval, numpy and scipy are always present. Non-finite numbers become ``null``.
    ``acceptance`` is a key of :data:`ACCEPTANCE`; ``baseline`` the record the run was
    compared with, if any. A missing model version is named as ``front_end`` spells its
    option.
    """
    if not isinstance(model_version, str) or not model_version.strip():
        raise HistoryError(
            f"model_version must be a non-empty string (got {model_version!r})",
            hint=f"pass {front_end.flag('model-version')} or set {MODEL_VERSION_ENV}",
        )
    versions = default_tool_versions()
    versions.update({str(k): str(v) for k, v in (tool_versions or {}).items()})
    return history_record(
        spec_results,
        model_version=model_version,
        tool_versions=versions,
        started_utc=started_utc,
        acceptance=acceptance,
        commit=commit,
        baseline=baseline,
    )
