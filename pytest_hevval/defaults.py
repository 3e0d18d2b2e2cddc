"""Defaults shared by the pytest options and the ``hevval`` command line, each defined once."""

from __future__ import annotations

__all__ = ["HISTORY_DIR", "REPORT_DIR", "SPEC_GLOBS"]

#: Spec files, as pytest's ``python_files`` globs (ini ``hevval_files`` overrides them).
SPEC_GLOBS: tuple[str, ...] = ("*.hevval.yaml", "*.hevval.yml")
#: Where run records go, relative to the project root.
HISTORY_DIR = ".hevval/history"
#: Where reports go, relative to the project root.
REPORT_DIR = ".hevval/report"
