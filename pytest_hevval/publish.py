"""The end of the pipeline, once for both front ends: results → everything a run leaves behind.

The run (:mod:`pytest_hevval.run`) scores specs (:mod:`pytest_hevval.scoring`), judges its
verdict, then hands the typed results and the verdict here: each signal gets its diagnosis and
its history trend, the reports are written, the run is compared with its baseline, the
thresholds are ratcheted and the run is recorded. What comes back are lines for the front end
to print and whether a step failed. Results become JSON data here, where they are written, and
nowhere before.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .defaults import UNKNOWN_MODEL_VERSION
from .errors import HevvalError
from .flags import PYTEST, FrontEnd
from .results.recorded import RecordedPoint, RecordedRun, RecordedSpec
from .results.spec_result import SpecResult
from .results.verdict import RunVerdict
from .spec.model import Spec

if TYPE_CHECKING:
    from .history import Comparison, Regression
    from .report.panels import SignalPanels

__all__ = ["Publication", "PublishOptions", "Publisher", "diagnosis_panels"]

#: The results' JSON data as a step of :meth:`Publisher.publish` asks for it (made once).
_Data = Callable[[], list[dict[str, Any]]]

#: The title of every report a run writes.
REPORT_TITLE = "hevval validation report"
#: The summary's line for a run that was not recorded, and how to record one.
NOT_RECORDED = (
    "history: not recorded (runs are recorded in CI, or when asked: --hevval-history, "
    "hevval run --history, or hevval_history = true in the ini file)"
)


@dataclass(frozen=True)
class PublishOptions:
    """What a run leaves behind; read once from pytest's options or the command line."""

    #: The project root: files are named relative to it in the notes.
    rootdir: Path
    #: Report formats, comma-separated (``html,json,md``); empty for none.
    report: str = ""
    report_dir: Path = Path(".hevval/report")
    history_dir: Path = Path(".hevval/history")
    #: Write this run's record (see :func:`~pytest_hevval.history.records_this_run`).
    record: bool = True
    #: Read the history at all (trends, baselines): False with ``no-history``.
    use_history: bool = True
    #: The model version as given (``None``: from the environment or git).
    model_version: str | None = None
    #: The baseline to compare with (``latest``, ``accepted`` or a model version), or ``None``.
    compare: str | None = None
    compare_fail: str | None = None
    create_baseline: bool = False
    #: Record this run as an accepted baseline whatever the comparison finds.
    accept: bool = False
    #: The ratchet margin as given, or ``None`` for no ratchet.
    ratchet: str | None = None
    #: The front end in use: messages name its flags.
    front_end: FrontEnd = PYTEST
    #: The run is on a CI runner (:func:`~pytest_hevval.history.is_ci`), detected once.
    ci: bool = False
    #: The run is on GitHub Actions: its reports add workflow annotations.
    github_actions: bool = False

    @classmethod
    def from_options(
        cls,
        option: Callable[[str], Any],
        rootdir: Path,
        front_end: FrontEnd = PYTEST,
        environ: Mapping[str, str] = os.environ,
    ) -> PublishOptions:
        """From an option getter that takes the names of :data:`~pytest_hevval.options.OPTIONS`
        (pytest's ``--hevval-NAME`` and ``hevval run --NAME`` share them); the environment is
        read here, once."""

        from .history import is_ci, records_this_run

        def text(name: str) -> str | None:
            value = option(name)
            return None if value in (None, "") else str(value)

        return cls(
            rootdir=rootdir,
            report=text("report") or "",
            report_dir=rootdir / str(option("report-dir")),
            history_dir=rootdir / str(option("history-dir")),
            record=records_this_run(
                asked=any(bool(option(name)) for name in ("history", "create-baseline", "accept")),
                refused=bool(option("no-history")),
                environ=environ,
            ),
            use_history=not option("no-history"),
            model_version=text("model-version"),
            compare=text("compare"),
            compare_fail=text("compare-fail"),
            create_baseline=bool(option("create-baseline")),
            accept=bool(option("accept")),
            ratchet=text("ratchet"),
            front_end=front_end,
            ci=is_ci(environ),
            github_actions=environ.get("GITHUB_ACTIONS") == "true",
        )


@dataclass
class Publication:
    """What publishing said and whether one of its steps failed the run."""

    notes: list[str] = field(default_factory=list)
    #: GitHub workflow commands, printed each on its own line before the summary.
    annotations: list[str] = field(default_factory=list)
    #: A step of publishing failed (a report or the record could not be written).
    failed: bool = False


class Publisher:
    """Publishes one run; :meth:`start` before scoring, :meth:`publish` after.

    Option values that cannot work raise :class:`~pytest_hevval.errors.HevvalError` at
    construction, before anything is scored.
    """

    def __init__(self, options: PublishOptions) -> None:
        from .history import parse_compare_fail, parse_margin
        from .report import parse_formats

        self.options = options
        self.formats = parse_formats(options.report, options.front_end) if options.report else set()
        front_end = options.front_end
        self.rules = (
            parse_compare_fail(options.compare_fail, front_end=front_end)
            if options.compare_fail
            else []
        )
        self.margin = (
            parse_margin(options.ratchet, front_end=front_end) if options.ratchet else None
        )
        self.baseline: RecordedRun | None = None
        self._regressions: dict[str, list[Regression]] = {}
        #: Each result as a comparison reads it, made once (by its ``spec`` key).
        self._recorded: dict[str, RecordedSpec] = {}
        self.model_version = UNKNOWN_MODEL_VERSION
        self.started = datetime.now(timezone.utc)

    @property
    def run_label(self) -> str:
        """This run's name in comparisons and trends: its model version, or, when none could
        be found (no git, no --hevval-model-version), ``this run``."""
        return "this run" if self.model_version == UNKNOWN_MODEL_VERSION else self.model_version

    def run_facts(self) -> dict[str, Any]:
        """The run's model version, start and tool versions, as its history record has them."""
        from .history import default_tool_versions, format_utc

        return {
            "model_version": self.model_version,
            "started_utc": format_utc(self.started),
            "tool_versions": default_tool_versions(),
        }

    @property
    def baseline_label(self) -> str | None:
        """The baseline in words (model version, commit, time), or None without one."""
        return None if self.baseline is None else self.baseline.describe()

    @property
    def wants_comparison(self) -> bool:
        return bool(self.options.compare or self.options.compare_fail)

    def start(self, *, controller: bool = True) -> list[str]:
        """Name the model version and pick the baseline before this run records anything.

        Every process of a run reads the baseline (items judge regressions against it); only
        the ``controller`` decides what a missing one means, and raises when it fails the run.
        """
        from .history import HistoryStore, missing_baseline, resolve_model_version
        from .history.load import baseline_run

        self.model_version = resolve_model_version(
            self.options.model_version, os.environ, self.options.rootdir
        )
        if not self.wants_comparison:
            return []
        wanted = self.options.compare or "latest"
        self.baseline = baseline_run(HistoryStore(self.options.history_dir), wanted)
        if self.baseline is not None or not controller:
            return []
        decision = missing_baseline(
            ci=self.options.ci,
            create_baseline=self.options.create_baseline or self.options.accept,
            directory=self.options.history_dir,
            wanted=wanted,
            recorded=self.options.record,
            front_end=self.options.front_end,
        )
        if decision.fails:
            raise HevvalError(decision.message)
        return [decision.message]

    def recorded(self, result: SpecResult) -> RecordedSpec:
        """The result as a comparison reads it, made once per result."""
        found = self._recorded.get(result.spec)
        if found is None:
            found = self._recorded[result.spec] = RecordedSpec.of(result)
        return found

    def regressions(self, result: SpecResult) -> list[Regression]:
        """Every rule of ``compare-fail`` the result breaks against the baseline; each result
        is compared once, however many of its signals ask."""
        if self.baseline is None or not self.rules:
            return []
        found = self._regressions.get(result.spec)
        if found is None:
            from .history import compare, regressions

            found = regressions(compare([self.recorded(result)], self.baseline), self.rules)
            self._regressions[result.spec] = found
        return found

    def regressions_for(self, result: SpecResult, signal: str | None) -> list[str]:
        """Rules of ``compare-fail`` this signal (or Φ, for None) breaks against the baseline,
        as its item's failure; none under ``accept``, which reports them and fails nothing."""
        if self.options.accept:
            return []
        return [
            str(found)
            for found in self.regressions(result)
            if found.signal == signal and (signal is not None or found.field == "phi")
        ]

    def found_regressions(self, results: Sequence[SpecResult]) -> list[Regression]:
        """Every rule of ``compare-fail`` each result breaks against the baseline, in the order
        of ``results``."""
        return [regression for result in results for regression in self.regressions(result)]

    def acceptance(self, found: Sequence[object]) -> str:
        """Why this run's record is, or is not, an accepted baseline (``ACCEPTANCE``)."""
        from .history import acceptance

        return acceptance(
            compared=self.wants_comparison,
            baseline_found=self.baseline is not None,
            regressed=bool(found),
            create_baseline=self.options.create_baseline,
            accept=self.options.accept,
        )

    def publish(
        self,
        results: Sequence[SpecResult],
        specs: Mapping[str, Spec],
        diagnoses: Mapping[tuple[str, str], Mapping[str, Any]],
        data: _Data,
        verdict: RunVerdict,
    ) -> Publication:
        """The run's reports, comparison, ratchet and history record, saying ``verdict``.

        ``specs`` by the result's ``spec`` key (for the ratchet's thresholds); ``diagnoses`` by
        (spec, signal), as :func:`diagnosis_panels` gives them; ``data`` makes the results'
        JSON data (``SpecResult.to_dict`` of each, in order), called only if a step uses it: a
        run that writes nothing does not pay for it (the tables of a spec with windows and
        regions cost seconds to turn into JSON).
        """
        out = Publication()
        if not results:
            return out
        comparison = None
        if self.baseline is not None:
            from .history import compare

            comparison = compare(
                [self.recorded(result) for result in results],
                self.baseline,
                after_label=self.run_label,
            )
        self._write_reports(results, data, diagnoses, out, comparison, verdict)
        self._compare(comparison, out)
        self._ratchet(results, specs, out)
        self._record(data, self.acceptance(verdict.regressions), out)
        return out

    def _relative(self, path: Path | str) -> str:
        from .data.remote import relative_to

        return relative_to(self.options.rootdir, str(path))

    def _write_reports(
        self,
        results: Sequence[SpecResult],
        data: _Data,
        diagnoses: Mapping[tuple[str, str], Mapping[str, Any]],
        out: Publication,
        comparison: Comparison | None,
        verdict: RunVerdict,
    ) -> None:
        if self.formats:
            from .report import write_reports

            try:
                written = write_reports(
                    results,
                    self.formats,
                    self.options.report_dir,
                    title=REPORT_TITLE,
                    verdict=verdict,
                    comparison=comparison,
                    facts=self.run_facts(),
                    panels=self._panels(results, diagnoses),
                    data=data() if "json" in self.formats else None,
                    front_end=self.options.front_end,
                )
            except HevvalError as exc:
                out.notes.append(f"report: error: {exc}")
                out.failed = True
            else:
                out.notes.extend(f"report: {self._relative(p)}" for p in written)
        if self.options.github_actions:
            from .report import github_annotations

            out.annotations.extend(github_annotations(results, self.options.rootdir))

    def _panels(
        self,
        results: Sequence[SpecResult],
        diagnoses: Mapping[tuple[str, str], Mapping[str, Any]],
    ) -> SignalPanels:
        """Each signal's diagnosis and history trend, as the reports show them beside it.

        A trend shows the newest recorded runs that hold the signal (``TREND_RUNS``, from the
        history's index, so that a long history costs a run no more than a short one), then
        this run.
        """
        from .report.panels import SignalPanels

        trends: dict[tuple[str, str], list[RecordedPoint]] = {}
        if self.options.use_history:
            from .history import HistoryStore

            trends = HistoryStore(self.options.history_dir).trends(
                (result.spec, signal.path) for result in results for signal in result.signals
            )
        return SignalPanels(diagnoses, trends, self.model_version)

    def _compare(self, comparison: Comparison | None, out: Publication) -> None:
        """The comparison in the terminal, when it was asked for by name."""
        if comparison is None or not self.options.compare:
            return
        from .history import comparison_table
        from .history.compare import campaign_change_lines

        found = [r for result in self._regressions.values() for r in result] if self.rules else None
        out.notes.append(comparison_table(comparison, found))
        out.notes.extend(campaign_change_lines(comparison))

    def _ratchet(
        self, results: Sequence[SpecResult], specs: Mapping[str, Spec], out: Publication
    ) -> None:
        if self.margin is None:
            return
        from .history import ratchet_spec

        for result in results:
            spec = specs.get(result.spec)
            if spec is None:
                continue
            if spec.campaign is not None:
                # One sidecar per spec file cannot hold each recording's own thresholds.
                note = f"ratchet: {self._relative(spec.path)}: a campaign, not ratcheted"
                if note not in out.notes:
                    out.notes.append(note)
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
                    margin=self.margin,
                    model_version=self.model_version,
                    created_utc=self.started,
                )
            except HevvalError as exc:
                out.notes.append(f"ratchet: error: {exc}")
                out.failed = True
                continue
            out.notes.append(outcome.summary())

    def _record(self, data: _Data, acceptance: str, out: Publication) -> None:
        if not self.options.record:
            if self.options.use_history:
                out.notes.append(NOT_RECORDED)
            return
        from .history import ACCEPTANCE, HistoryStore, make_record, resolve_commit

        try:
            path = HistoryStore(self.options.history_dir, front_end=self.options.front_end).append(
                make_record(
                    data(),
                    model_version=self.model_version,
                    started_utc=self.started,
                    acceptance=acceptance,
                    commit=resolve_commit(self.options.rootdir),
                    baseline=None if self.baseline is None else self.baseline.summary(),
                    front_end=self.options.front_end,
                )
            )
        except (HevvalError, OSError) as exc:
            out.notes.append(f"history: error: the run was not recorded: {exc}")
            out.failed = True
            return
        accepted = (
            f"accepted as a baseline: {acceptance}"
            if ACCEPTANCE[acceptance]
            else f"not accepted as a baseline: {acceptance}"
        )
        out.notes.append(
            f"history: recorded {self.model_version} in {self._relative(path)} ({accepted})"
        )


def diagnosis_panels(
    payloads: Iterable[Mapping[str, Any]],
) -> dict[tuple[str, str], Mapping[str, Any]]:
    """Diagnosis payloads (see :func:`pytest_hevval.report.diagnosis_text.payload`) keyed by the
    (spec, signal) a report shows them at."""
    return {(str(p.get("spec", "")), str(p["signal"])): p for p in payloads}
