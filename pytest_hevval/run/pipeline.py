"""One run of the pipeline, for both front ends: start, score, verdict, publish, finish.

``hevval run`` drives a :class:`Run` in one go: :meth:`Run.start`, :meth:`Run.score` over
every spec, :meth:`Run.close_scoring`, :meth:`Run.finish`. Under ``pytest --hevval`` the same
run is split across hooks and processes: each process starts it and scores the specs of the
items it runs (:meth:`Run.evaluate`); the controller gathers every result (:meth:`Run.keep`,
:meth:`Run.receive`), judges the campaign gates the xdist workers left to it
(:meth:`Run.judge_gate`) and finishes the run once. Either way the run's verdict is decided
here, once (:meth:`Run.finish`), and the exit code, the summary, the reports and the JSON
read it; the front ends only translate their flags into :class:`~.settings.RunSettings` and
print what the run says.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..data.remote import relative_to
from ..errors import HevvalError
from ..publish import Publisher, diagnosis_panels
from ..results.spec_result import SignalResult, SpecResult
from ..results.verdict import RegressedItem, RunVerdict
from ..spec.model import Spec
from .settings import RunSettings

if TYPE_CHECKING:
    # Scoring brings numpy's and scipy's numerics: a controller that only reports never
    # imports them, so it starts its xdist workers sooner.
    from ..scoring.engine import DataCache, Evaluation
    from ..scoring.run import RunOptions

__all__ = ["ClusterUnavailable", "Run"]


class ClusterUnavailable(HevvalError):
    """The Dask scheduler of the ``dask`` option could not score the specs: the option, not
    a spec, is at fault."""


class Run:
    """One run: its settings, the specs it scored, their results, its verdict and its notes.

    ``controller``: this process finishes the run (without xdist, the only one); an xdist
    worker scores the specs of its items and sends the results to the controller.
    Constructing it checks the publishing options (report formats, ``compare-fail``,
    ``ratchet``) and raises :class:`~pytest_hevval.errors.HevvalError` for one that cannot work.
    """

    def __init__(self, settings: RunSettings, *, controller: bool = True) -> None:
        self.settings = settings
        self.controller = controller
        self.publisher = Publisher(settings.publish)
        #: Specs of this run, by path relative to the root.
        self.specs: dict[str, Spec] = {}
        #: Each spec's evaluation in this process (or why it could not be scored), by spec key.
        self.evaluations: dict[str, Evaluation | HevvalError] = {}
        #: Results of this run, by spec: scored here or received from a worker.
        self.results: dict[str, SpecResult] = {}
        #: The JSON data of the results received from workers, by spec: what the reports and
        #: the history record take, so the controller does not turn each result back into it.
        self.received: dict[str, dict[str, Any]] = {}
        #: Diagnosis payloads by (spec, signal), for the reports (see publish.diagnosis_panels).
        self.diagnoses: dict[tuple[str, str], Mapping[str, Any]] = {}
        #: Specs (or recordings) that could not be scored, with their error's first line.
        self.unscored: dict[str, str] = {}
        #: The errors of specs :meth:`score` could not score, by spec path, in order.
        self.errors: list[tuple[str, HevvalError]] = []
        #: Lines for the end of the run (baseline, reports, history, comparison, ratchet).
        self.notes: list[str] = []
        #: GitHub workflow commands, each printed on its own line before the summary.
        self.annotations: list[str] = []
        #: The run's verdict, once finished.
        self.verdict: RunVerdict | None = None
        #: Results in the order :meth:`score` scored them; None when they were gathered item
        #: by item, in no order of their own (then by spec key).
        self._ordered: list[SpecResult] | None = None
        self._data: list[dict[str, Any]] | None = None
        self._scoring: RunOptions | None = None
        self._cache: DataCache | None = None

    @property
    def rootdir(self) -> Path:
        return self.settings.rootdir

    def relative(self, path: str) -> str:
        return relative_to(self.rootdir, path)

    # -- start ------------------------------------------------------------------------------
    def start(self) -> None:
        """Name the model version and pick the baseline, before this run records anything
        (every process reads it; the controller says what a missing one means and raises
        :class:`~pytest_hevval.errors.HevvalError` when that fails the run)."""
        self.notes.extend(self.publisher.start(controller=self.controller))

    # -- scoring ----------------------------------------------------------------------------
    @property
    def scoring(self) -> RunOptions:
        """How specs are scored in this run, made from the settings once."""
        if self._scoring is None:
            from ..scoring.run import RunOptions

            settings = self.settings
            formats = self.publisher.formats
            self._scoring = RunOptions(
                rootdir=self.rootdir,
                figures="html" in formats,
                workers=settings.workers,
                dask=settings.dask,
                data_hash=settings.data_hash,
                intervals=settings.intervals,
                # Without item reports only a report shows diagnoses; without one, scoring
                # keeps no data to diagnose.
                diagnose=settings.diagnose if settings.item_reports or formats else "off",
            )
        return self._scoring

    @property
    def cache(self) -> DataCache:
        """Reads each data file once for this process (created when first needed)."""
        if self._cache is None:
            from ..scoring.engine import DataCache

            self._cache = DataCache(self.scoring.data_hash)
        return self._cache

    def score(self, specs: Sequence[Spec], progress: Callable[[int], None] | None = None) -> None:
        """Score every spec at once (``hevval run``); ``progress`` is called with the number
        of specs done. Specs that cannot be scored are kept as errors, unless none can be:
        then the first error is raised."""
        from ..report.diagnosis_text import target_payload
        from ..scoring.engine import Evaluation
        from ..scoring.run import run_specs

        outcomes = run_specs(specs, self.scoring, progress=progress)
        self._ordered = []
        for spec, outcome in zip(specs, outcomes, strict=True):
            key = self.relative(spec.key)
            self.specs[key] = spec
            if isinstance(outcome, Evaluation):
                self._ordered.append(outcome.result)
                self.results[outcome.result.spec] = outcome.result
                self.diagnoses.update(
                    diagnosis_panels(
                        target_payload(outcome.result.spec, target, found)
                        for target, found in outcome.diagnoses.items()
                    )
                )
            else:
                self.errors.append((key, outcome))
                self.unscored[key] = str(outcome).splitlines()[0]
        if self.errors and not self._ordered:
            raise self.errors[0][1]

    def register(self, spec: Spec) -> None:
        """A spec collected in this process (pytest), to be scored by :meth:`evaluate`."""
        self.specs[self.relative(spec.key)] = spec
        self.cache.declare_spec(spec)

    def evaluate(self, spec: Spec) -> Evaluation:
        """Score a spec once per process; later items of the same spec reuse it. Raises the
        spec's :class:`~pytest_hevval.errors.HevvalError` when it cannot be scored, and
        :class:`ClusterUnavailable` when the Dask scheduler cannot score any."""
        key = spec.key
        options = self.scoring
        if key not in self.evaluations and options.dask:
            self._score_on_dask()
        if key not in self.evaluations:
            from ..scoring.run import run_specs

            (self.evaluations[key],) = run_specs([spec], options, cache=self.cache)
            # Its items judge from the evaluation: the data this spec declared may go.
            self.cache.release_spec(spec)
        outcome = self.evaluations[key]
        if isinstance(outcome, HevvalError):
            raise outcome
        return outcome

    def _score_on_dask(self) -> None:
        """Score every registered spec on the Dask cluster at once, before the items run."""
        options = self.scoring
        if not options.dask or not self.specs:
            return
        specs = list(self.specs.values())
        from ..scoring.run import run_specs

        try:
            outcomes = run_specs(specs, options)
        except HevvalError as exc:
            flag = self.settings.front_end.flag("dask")
            raise ClusterUnavailable(f"{flag}={options.dask}: {exc}") from None
        for spec, outcome in zip(specs, outcomes, strict=True):
            self.evaluations[spec.key] = outcome

    def close_scoring(self) -> None:
        """In every process that scored, once it is done: a kernel this run would have used
        is compiled for the next runs."""
        from ..data.kernel_cache import finish_run

        finish_run()

    # -- what items judge -------------------------------------------------------------------
    def diagnosis_for(
        self, evaluation: Evaluation | None, signal: SignalResult
    ) -> Mapping[str, Any] | None:
        """The diagnosis of the signal where this signal's error appears, if enabled."""
        mode = self.settings.diagnose
        if evaluation is None or mode == "off" or (mode == "failed" and signal.passed):
            return None
        # Imported here: the diagnosis brings scipy.linalg, which a run without one never needs.
        from ..report.diagnosis_text import target_payload
        from ..scoring.diagnosis import diagnosis_target

        target = diagnosis_target(signal)
        found = evaluation.diagnoses.get(target)
        if found is None:
            return None
        return target_payload(evaluation.result.spec, target, found)

    def regressions_for(self, result: SpecResult, signal: str | None) -> list[str]:
        """Rules of ``compare-fail`` this signal (or Φ, for None) breaks against the baseline;
        none when the run accepts its regressions."""
        return self.publisher.regressions_for(result, signal)

    def judge_campaign(
        self, outcomes: Mapping[str, SpecResult | HevvalError]
    ) -> tuple[float | None, str | None]:
        """A campaign gate's (pass rate, failure text or None) from its recordings' outcomes,
        by recording: what its item reports, in this process or, under xdist, on the
        controller."""
        from ..report.terminal import verdict_lines
        from ..results.campaign import verdict

        results = [o for o in outcomes.values() if isinstance(o, SpecResult)]
        if not results:
            return None, "no recording of the campaign could be scored:\n" + "\n".join(
                f"  {name}: {error}" for name, error in outcomes.items()
            )
        found = verdict(results)
        return found.pass_rate, None if found.passed else "\n".join(verdict_lines(found))

    def judge_gate(self, recordings: Sequence[str]) -> tuple[float | None, str | None]:
        """On the controller: a campaign gate an xdist worker left to it, judged on the results
        every worker sent (:meth:`judge_campaign`). A recording no worker scored (deselected
        with -k, or its data failed) is scored here, as the gate's item does without xdist."""
        from ..spec.load import load_specs

        outcomes: dict[str, SpecResult | HevvalError] = {}
        for key in recordings:
            if key not in self.results:
                try:
                    for spec in load_specs(str(self.rootdir / key)):
                        self.keep(self.evaluate(spec).result)
                except HevvalError as exc:
                    outcomes[key] = exc
                    continue
            outcomes[key] = self.results[key]
        return self.judge_campaign(outcomes)

    # -- gathering --------------------------------------------------------------------------
    def keep(self, result: SpecResult) -> None:
        """A result scored in the controller's own process."""
        self.results[result.spec] = result

    def receive(self, data: dict[str, Any]) -> None:
        """A result a worker sent, as JSON data (kept for the files the run writes)."""
        result = SpecResult.from_dict(data)
        self.results[result.spec] = result
        self.received[result.spec] = data

    def keep_diagnoses(self, payloads: Sequence[Mapping[str, Any]]) -> None:
        """Diagnosis payloads for the reports."""
        self.diagnoses.update(diagnosis_panels(payloads))

    def spec_results(self) -> list[SpecResult]:
        """The run's results: in the order scored, or, gathered item by item, by spec key."""
        if self._ordered is not None:
            return list(self._ordered)
        return [self.results[k] for k in sorted(self.results)]

    def result_data(self) -> list[dict[str, Any]]:
        """The results' JSON data, in :meth:`spec_results`' order; made once, and only when a
        file the run writes (or a comparison) asks for it."""
        if self._data is None:
            self._data = [self.received.get(r.spec) or r.to_dict() for r in self.spec_results()]
        return self._data

    # -- verdict, publishing ----------------------------------------------------------------
    def judge(self, results: Sequence[SpecResult]) -> RunVerdict:
        """The run's verdict: the results' gates, the campaigns' gates, the specs that could
        not be scored, and the regressions against the baseline."""
        errors = [f"{key}: {error}" for key, error in self.unscored.items()]
        if not results:
            return RunVerdict.decide(results, errors=errors)
        found = self.publisher.found_regressions(results)
        return RunVerdict.decide(
            results,
            regressions=[RegressedItem(r.spec, r.signal, r.field, str(r)) for r in found],
            regressions_accepted=self.settings.publish.accept,
            baseline=self.publisher.baseline_label,
            errors=errors,
        )

    def finish(self) -> RunVerdict:
        """On the controller, once every result is in: the verdict, then the reports, the
        comparison, the ratchet and the history record, then the kernel's note."""
        from ..data.kernel_cache import compile_note

        results = self.spec_results()
        verdict = self.judge(results)
        published = self.publisher.publish(
            results, self.specs, self.diagnoses, self.result_data, verdict
        )
        self.verdict = verdict.published(failed=published.failed)
        self.notes.extend(published.notes)
        kernel_note = compile_note()
        if kernel_note is not None:
            self.notes.append(kernel_note)
        self.annotations.extend(published.annotations)
        return self.verdict

    # -- what the front ends print ----------------------------------------------------------
    def summary(self) -> list[str]:
        """The summary: every spec's tree, each campaign's verdict, the run's verdict."""
        from ..report.terminal import run_summary

        return run_summary(self.spec_results(), details=self.settings.details, verdict=self.verdict)

    def json_document(self) -> dict[str, Any]:
        """The ``--json`` document of a finished run (the run envelope of results/envelope.py)."""
        from ..results.envelope import run_document
        from ..scoring.cluster import error_payload

        assert self.verdict is not None, "finish the run first"
        return run_document(
            self.result_data(),
            facts=self.publisher.run_facts(),
            verdict=self.verdict,
            campaigns=self.verdict.campaigns,
            errors=[error_payload(key, exc) for key, exc in self.errors],
        )
