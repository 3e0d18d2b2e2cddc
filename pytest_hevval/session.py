"""Per-process state of one pytest session: options, the data cache, evaluations, results.

The hooks in :mod:`pytest_hevval.plugin` delegate here. Every process evaluates the specs of
the items it runs; only the controller (the process without ``workerinput``) writes history
and reports, once, from the results the workers' reports carry back.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import pytest

from .engine import DataCache, Evaluation
from .errors import HevvalError
from .options import get_option
from .result import SignalResult, SpecResult
from .run import RunOptions, relative_to, run_specs
from .spec.model import Spec
from .terminal import tree_summary

__all__ = ["HevvalSession"]


# eq=False keeps identity hashing: pluggy (before 1.4) keeps registered plugins in a set.
@dataclass(eq=False)
class HevvalSession:
    config: pytest.Config
    cache: DataCache = field(default_factory=DataCache)
    evaluations: dict[str, Evaluation | HevvalError] = field(default_factory=dict)
    #: Specs collected by this process, by path relative to the rootdir.
    specs: dict[str, Spec] = field(default_factory=dict)
    #: Spec results seen by this process (the controller receives them from worker reports).
    results: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: Spec results already attached to a report by this process.
    shipped: set[str] = field(default_factory=set)
    #: Lines for the terminal summary (history, comparison, ratchet).
    notes: list[str] = field(default_factory=list)
    annotations: list[str] = field(default_factory=list)
    diagnoses: dict[tuple[str, str], dict[str, Any]] = field(default_factory=dict)
    received_diagnoses: dict[tuple[str, str], dict[str, Any]] = field(default_factory=dict)
    compare_rules: list[Any] = field(default_factory=list)
    ratchet_margin: float | None = None
    baseline: dict[str, Any] | None = None
    model_version: str = "unknown"
    started: datetime = field(default_factory=lambda: datetime.now(timezone.utc))
    _run_options: RunOptions | None = None

    # -- options ----------------------------------------------------------------------------
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

    def history_dir(self) -> Path:
        return self.rootdir / str(self.option("history-dir"))

    def wants_comparison(self) -> bool:
        return bool(self.option("compare") or self.option("compare-fail"))

    def validate_options(self) -> None:
        """Fail fast, before collection, on option values that cannot work."""
        from .history import HistoryError, parse_compare_fail, parse_margin

        self.workers()
        if self.option("dask") and self.config.getoption("numprocesses", None):
            raise pytest.UsageError(
                "--hevval-dask and -n both spread the specs over processes; use one of them"
            )
        try:
            expression = self.option("compare-fail")
            if expression:
                self.compare_rules = parse_compare_fail(str(expression))
            margin = self.option("ratchet")
            if margin:
                self.ratchet_margin = parse_margin(str(margin))
        except HistoryError as exc:
            raise pytest.UsageError(str(exc)) from None
        if self.option("report"):
            from .report import parse_formats

            try:
                parse_formats(str(self.option("report")))
            except HevvalError as exc:
                raise pytest.UsageError(str(exc)) from None

    # -- session start: the baseline --------------------------------------------------------
    def start(self) -> None:
        """Pick the baseline before this run records anything (every process reads it)."""
        from .core.kernel import cold_cache_note
        from .history import (
            HistoryStore,
            is_ci,
            missing_baseline,
            resolve_model_version,
        )

        self.model_version = resolve_model_version(
            self.option("model-version"), os.environ, self.rootdir
        )
        kernel_note = cold_cache_note() if self.is_controller else None
        if kernel_note is not None:
            self.notes.append(kernel_note)
        if not self.wants_comparison():
            return
        wanted = str(self.option("compare") or "latest")
        store = HistoryStore(self.history_dir())
        self.baseline = store.latest() if wanted == "latest" else store.find(wanted)
        if self.baseline is not None or not self.is_controller:
            return
        decision = missing_baseline(
            ci=is_ci(os.environ),
            create_baseline=bool(self.option("create-baseline")),
            directory=self.history_dir(),
            wanted=wanted,
        )
        if decision.fails:
            raise pytest.UsageError(f"hevval: {decision.message}")
        self.notes.append(decision.message)

    # -- evaluation -------------------------------------------------------------------------
    def register(self, spec: Spec) -> None:
        self.specs[self.relative(spec.key)] = spec
        self.cache.declare(spec.reference, spec.reference_columns())
        self.cache.declare(spec.model, spec.model_columns())

    def run_options(self) -> RunOptions:
        """The scoring settings of this run, read from the options once."""
        if self._run_options is None:
            self._run_options = RunOptions(
                rootdir=self.rootdir,
                figures=self.wants_figures(),
                keep_arrays=self.option("diagnose") != "off",
                workers=self.workers(),
                dask=str(self.option("dask")) if self.option("dask") else None,
                data_hash=str(self.option("hash")),
                intervals=not self.option("no-intervals"),
            )
            self.cache.data_hash = self._run_options.data_hash
        return self._run_options

    def prefetch_on_dask(self) -> None:
        """Score every collected spec on the Dask cluster at once, before the items run."""
        options = self.run_options()
        if not options.dask or not self.specs:
            return
        specs = list(self.specs.values())
        try:
            outcomes = run_specs(specs, options)
        except HevvalError as exc:
            raise pytest.UsageError(f"--hevval-dask={options.dask}: {exc}") from None
        for spec, outcome in zip(specs, outcomes, strict=True):
            self.evaluations[spec.key] = outcome

    def evaluate(self, spec: Spec) -> Evaluation:
        """Evaluate a spec once per process; later items of the same spec reuse it."""
        key = spec.key
        options = self.run_options()
        if key not in self.evaluations and options.dask:
            self.prefetch_on_dask()
        if key not in self.evaluations:
            (self.evaluations[key],) = run_specs([spec], options, cache=self.cache)
        outcome = self.evaluations[key]
        if isinstance(outcome, HevvalError):
            raise outcome
        return outcome

    def diagnosis_for(
        self, evaluation: Evaluation | None, signal: SignalResult
    ) -> dict[str, Any] | None:
        """The diagnosis of the signal where this signal's error appears, if enabled."""
        mode = self.option("diagnose")
        if evaluation is None or mode == "off" or (mode == "failed" and signal.passed):
            return None
        if evaluation.aligned is None:  # scored on a Dask worker: no data here to diagnose
            return None
        from .diagnose import diagnose_origin

        target = signal.origins[0] if signal.origins else signal.path
        key = (str(evaluation.spec.path), target)
        if key not in self.diagnoses:
            try:
                self.diagnoses[key] = diagnose_origin(evaluation, target)
            except HevvalError as exc:
                self.diagnoses[key] = {"signal": target, "summary": f"not diagnosed: {exc}"}
        return self.diagnoses[key]

    def receive_diagnosis(self, payload: dict[str, Any]) -> None:
        """Controller: keep a worker's diagnosis to show it in the reports."""
        self.received_diagnoses[(payload["spec"], payload["signal"])] = payload

    def regressions_for(self, result: SpecResult, signal: str | None) -> list[str]:
        """Rules of --hevval-compare-fail this signal (or Φ, for None) breaks vs the baseline."""
        if self.baseline is None or not self.compare_rules:
            return []
        from .history import compare, regressions

        comparison = compare([result.to_dict()], self.baseline)
        return [
            str(found)
            for found in regressions(comparison, self.compare_rules)
            if found.signal == signal and (signal is not None or found.field == "phi")
        ]

    # -- results crossing from workers ------------------------------------------------------
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
        diagnosis = getattr(report, "hevval_diagnosis", None)
        if diagnosis is not None:
            self.receive_diagnosis(diagnosis)
        for recording in getattr(report, "hevval_campaign", None) or ():
            self.receive(recording)

    def spec_results(self) -> list[SpecResult]:
        return [SpecResult.from_dict(self.results[k]) for k in sorted(self.results)]

    def relative(self, path: str) -> str:
        return relative_to(self.rootdir, path)

    # -- session end: controller only -------------------------------------------------------
    def finish(self, session: pytest.Session) -> None:
        """Write reports, the comparison, the ratchet and the history record, once."""
        dicts = [self.results[k] for k in sorted(self.results)]
        if not dicts:
            return
        failed = False
        failed |= self._write_reports(dicts)
        self._compare(dicts)
        failed |= self._ratchet(dicts)
        failed |= self._record(dicts)
        if failed and session.exitstatus == pytest.ExitCode.OK:
            session.exitstatus = pytest.ExitCode.TESTS_FAILED

    def _decorate(self, dicts: list[dict[str, Any]]) -> list[dict[str, Any]]:
        """Report copies of the results with each signal's diagnosis and history trend."""
        trends: dict[tuple[str, str], list[dict[str, Any]]] = {}
        phis: dict[str, list[dict[str, Any]]] = {}
        if not self.option("no-history"):
            from .history import HistoryStore

            for record in HistoryStore(self.history_dir()).records():
                version = str(record.get("model_version", "?"))
                for spec in record.get("specs", []):
                    phis.setdefault(spec.get("spec", ""), []).append(
                        {"version": version, "phi": spec.get("phi")}
                    )
                    for signal in spec.get("signals", []):
                        trends.setdefault((spec.get("spec", ""), signal["path"]), []).append(
                            {
                                "version": version,
                                "phi": spec.get("phi"),
                                "lambdas": signal.get("lambdas"),
                            }
                        )
        decorated = []
        for result in dicts:
            copy = dict(result)
            signals = []
            for signal in result["signals"]:
                item = dict(signal)
                found = self.received_diagnoses.get((result["spec"], signal["path"]))
                if found is None and signal.get("origins"):
                    found = self.received_diagnoses.get((result["spec"], signal["origins"][0]))
                if found is not None:
                    item["diagnosis"] = found
                history = trends.get((result["spec"], signal["path"]))
                if history:
                    item["history"] = [
                        *history,
                        {
                            "version": self.model_version,
                            "phi": result["phi"],
                            "lambdas": signal["lambdas"],
                        },
                    ]
                signals.append(item)
            copy["signals"] = signals
            decorated.append(copy)
        return decorated

    def _write_reports(self, dicts: list[dict[str, Any]]) -> bool:
        formats = str(self.option("report") or "")
        if formats:
            from .report import parse_formats, write_reports

            try:
                written = write_reports(
                    self._decorate(dicts),
                    parse_formats(formats),
                    self.rootdir / str(self.option("report-dir")),
                    title="hevval validation report",
                )
            except HevvalError as exc:
                self.notes.append(f"report: error: {exc}")
                return True
            self.notes.extend(f"report: {self.relative(str(p))}" for p in written)
        if os.environ.get("GITHUB_ACTIONS") == "true":
            from .report import github_annotations

            # Printed by the terminal summary: a workflow command must start its own line.
            self.annotations.extend(github_annotations(dicts, self.rootdir))
        return False

    def _compare(self, dicts: list[dict[str, Any]]) -> None:
        if self.baseline is None or not self.option("compare"):
            return
        from .history import compare, comparison_table, regressions
        from .history.compare import campaign_change_lines

        comparison = compare(dicts, self.baseline, after_label=self.model_version)
        found = regressions(comparison, self.compare_rules) if self.compare_rules else None
        self.notes.append(comparison_table(comparison, found))
        self.notes.extend(campaign_change_lines(comparison))

    def _ratchet(self, dicts: list[dict[str, Any]]) -> bool:
        if self.ratchet_margin is None:
            return False
        from .history import ratchet_spec

        failed = False
        for result in dicts:
            spec = self.specs.get(result["spec"])
            if spec is None:
                continue
            if spec.campaign is not None:
                # One sidecar per spec file cannot hold each recording's own thresholds.
                note = f"ratchet: {self.relative(str(spec.path))}: a campaign, not ratcheted"
                if note not in self.notes:
                    self.notes.append(note)
                continue
            written = {
                "/".join(path): {**spec.thresholds, **node.thresholds}
                for _, path, node in spec.walk()
            }
            try:
                outcome = ratchet_spec(
                    spec.path,
                    result,
                    written,
                    margin=self.ratchet_margin,
                    model_version=self.model_version,
                    created_utc=self.started,
                )
            except HevvalError as exc:
                self.notes.append(f"ratchet: error: {exc}")
                failed = True
                continue
            self.notes.append(outcome.summary())
        return failed

    def _record(self, dicts: list[dict[str, Any]]) -> bool:
        if self.option("no-history"):
            return False
        from .history import HistoryStore, make_record

        try:
            path = HistoryStore(self.history_dir()).append(
                make_record(dicts, model_version=self.model_version, started_utc=self.started)
            )
        except (HevvalError, OSError) as exc:
            self.notes.append(f"history: error: the run was not recorded: {exc}")
            return True
        self.notes.append(f"history: recorded {self.model_version} in {self.relative(str(path))}")
        return False

    def summarise(self, terminalreporter: Any) -> None:
        results = self.spec_results()
        if not results and not self.notes and not self.annotations:
            return
        for line in self.annotations:
            terminalreporter.write_line(line)
        terminalreporter.write_sep("=", "hevval validation summary")
        for line in tree_summary(results, details=bool(self.option("details"))):
            terminalreporter.write_line(line)
        if any(r.recording is not None for r in results):
            from .campaign import campaign_verdicts, verdict_lines

            for found in campaign_verdicts(results):
                for line in verdict_lines(found):
                    terminalreporter.write_line(line)
        for note in self.notes:
            for line in note.splitlines():
                terminalreporter.write_line(line)
