"""Per-process state of one pytest session: options, the data cache, evaluations, results.

The hooks in :mod:`pytest_hevval.plugin` delegate here. Workers evaluate; only the controller
(the process without ``workerinput``) writes history and reports.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from .engine import DataCache, Evaluation, evaluate_spec
from .errors import HevvalError
from .options import get_option
from .result import SignalResult, SpecResult
from .spec.model import Spec
from .terminal import tree_summary

__all__ = ["HevvalSession", "session_key"]


@dataclass
class HevvalSession:
    config: pytest.Config
    cache: DataCache = field(default_factory=DataCache)
    evaluations: dict[str, Evaluation | HevvalError] = field(default_factory=dict)
    #: Spec results seen by this process (the controller receives them from worker reports).
    results: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: Spec results already attached to a report by this process.
    shipped: set[str] = field(default_factory=set)
    failed_items: int = 0

    @property
    def enabled(self) -> bool:
        return bool(get_option(self.config, ""))

    @property
    def is_controller(self) -> bool:
        return not hasattr(self.config, "workerinput")

    @property
    def rootdir(self) -> Path:
        return Path(str(self.config.rootpath))

    def option(self, name: str) -> Any:
        return get_option(self.config, name)

    def wants_figures(self) -> bool:
        return "html" in str(self.option("report") or "")

    def workers(self) -> int | None:
        value = self.option("workers")
        if value in (None, ""):
            return None
        try:
            count = int(value)
        except ValueError:
            raise pytest.UsageError(
                f"--hevval-workers must be a whole number (got {value!r})"
            ) from None
        if count < 1:
            raise pytest.UsageError(f"--hevval-workers must be ≥ 1 (got {count})")
        return count

    def evaluate(self, spec: Spec) -> Evaluation:
        """Evaluate a spec once per process; later items of the same spec reuse it."""
        key = str(spec.path)
        if key not in self.evaluations:
            try:
                self.evaluations[key] = evaluate_spec(
                    spec,
                    cache=self.cache,
                    rootdir=self.rootdir,
                    figures=self.wants_figures(),
                    keep_arrays=self.option("diagnose") != "off",
                    workers=self.workers(),
                )
                self._make_relative(self.evaluations[key])
            except HevvalError as exc:
                self.evaluations[key] = exc
        outcome = self.evaluations[key]
        if isinstance(outcome, HevvalError):
            raise outcome
        return outcome

    def _make_relative(self, outcome: Evaluation | HevvalError) -> None:
        """Results name files relative to the rootdir, so records move between machines."""
        if isinstance(outcome, HevvalError):
            return
        result = outcome.result
        result.spec = self.relative(result.spec)
        for side in result.data.values():
            if isinstance(side, dict) and side.get("path") and "://" not in str(side["path"]):
                side["path"] = self.relative(str(side["path"]))

    def diagnosis_line(self, evaluation: Evaluation | None, signal: SignalResult) -> str | None:
        """One line naming the top significant finding for a failing signal, if enabled."""
        return None

    def ship(self, result: SpecResult) -> dict[str, Any] | None:
        """The spec's result dict the first time this process reports on the spec."""
        if result.spec in self.shipped:
            return None
        self.shipped.add(result.spec)
        return result.to_dict()

    def receive(self, payload: dict[str, Any]) -> None:
        self.results[payload["spec"]] = payload

    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        payload = getattr(report, "hevval_spec", None)
        if payload is not None:
            self.receive(payload)

    def validate_options(self) -> None:
        """Fail fast, before collection, on option values that cannot work."""
        self.workers()

    def finish(self, session: pytest.Session) -> None:
        """Controller only: write history and reports once for the whole run."""

    def summarise(self, terminalreporter: Any) -> None:
        results = self.spec_results()
        if not results:
            return
        terminalreporter.write_sep("=", "hevval validation summary")
        for line in tree_summary(results, details=bool(self.option("details"))):
            terminalreporter.write_line(line)

    def spec_results(self) -> list[SpecResult]:
        return [SpecResult.from_dict(self.results[k]) for k in sorted(self.results)]

    def relative(self, path: str) -> str:
        try:
            return os.path.relpath(path, self.rootdir)
        except ValueError:
            return path


session_key = pytest.StashKey[HevvalSession]()
