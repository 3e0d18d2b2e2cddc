"""Per-process state of one pytest session: options, the data cache, evaluations, results.

The hooks in :mod:`pytest_hevval.plugin` delegate here. Every process evaluates the specs of
the items it runs; only the controller (the process without ``workerinput``) writes history
and reports, once, from the results the workers' reports carry back.
"""

from __future__ import annotations

import atexit
import gc
import json
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any, Literal

import pytest
from _pytest._code.code import TerminalRepr
from _pytest._io import TerminalWriter

from ..data.remote import relative_to
from ..errors import HevvalError
from ..escape import terminal
from ..options import get_option
from ..publish import Publisher, PublishOptions, diagnosis_panels
from ..report.terminal import run_summary
from ..results.spec_result import SignalResult, SpecResult
from ..results.verdict import RunVerdict
from ..spec.model import Spec

if TYPE_CHECKING:
    # Scoring brings numpy's and scipy's numerics: a controller that only reports never
    # imports them, so it starts its xdist workers sooner.
    from ..scoring.engine import DataCache, Evaluation
    from ..scoring.run import RunOptions

__all__ = ["HevvalSession", "judge_campaign"]

#: How a spec's item names its place in pytest's reports (``items._SpecItem.reportinfo``).
SPEC_ITEM_PLACE = "hevval "
#: The key of the campaign gates in an xdist worker's output to the controller.
_GATES = "hevval_campaign_gates"


# eq=False keeps identity hashing: pluggy (before 1.4) keeps registered plugins in a set.
@dataclass(eq=False)
class HevvalSession:
    config: pytest.Config
    evaluations: dict[str, Evaluation | HevvalError] = field(default_factory=dict)
    #: Specs collected by this process, by path relative to the rootdir.
    specs: dict[str, Spec] = field(default_factory=dict)
    #: Spec results seen by this process (the controller receives them from worker reports).
    results: dict[str, SpecResult] = field(default_factory=dict)
    #: The JSON data of the results received from workers, by spec: what the reports and the
    #: history record take, so the controller does not turn each result back into it.
    received: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: Spec results already attached to a report by this process.
    shipped: set[str] = field(default_factory=set)
    #: Diagnosis payloads by (spec, signal), for the reports (see publish.diagnosis_panels).
    diagnoses: dict[tuple[str, str], Mapping[str, Any]] = field(default_factory=dict)
    #: Lines for the terminal summary (history, comparison, ratchet).
    notes: list[str] = field(default_factory=list)
    annotations: list[str] = field(default_factory=list)
    #: The item that reported each spec's error first, by spec key.
    error_shown: dict[str, str] = field(default_factory=dict)
    #: On the controller: the specs that could not be scored (their items' setup failed), by
    #: spec key, with the error of the first item that reported it.
    unscored: dict[str, str] = field(default_factory=dict)
    #: The run's verdict, once published (see ``publish.Publication.verdict``).
    verdict: RunVerdict | None = None
    #: Campaign gate items the xdist workers left to this controller, by node id.
    gates: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: Outcomes of items a worker judged with another one (``items.carry_spec_items``), by the
    #: node id of the item whose report carried them, with the worker; reported once that
    #: item's reports are in.
    carried: dict[str, tuple[list[dict[str, Any]], Any]] = field(default_factory=dict)
    session: pytest.Session | None = None
    _publisher: Publisher | None = None
    _run_options: RunOptions | None = None
    _cache: DataCache | None = None

    @property
    def cache(self) -> DataCache:
        """Reads each data file once for this process (created when first needed)."""
        if self._cache is None:
            from ..scoring.engine import DataCache

            self._cache = DataCache()
        return self._cache

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

    def workers(self) -> int | None:
        """Threads each spec is scored on: ``--hevval-workers``, else, on an xdist worker, its
        share of the cores (the processes already fill them; more threads only contend)."""
        value = self.option("workers")
        if value in (None, ""):
            if self.is_controller:
                return None
            processes = int(self.config.workerinput.get("workercount", 1))  # type: ignore[attr-defined]
            return max(1, (os.cpu_count() or 1) // max(processes, 1))
        try:
            count = int(value)
        except ValueError:
            raise pytest.UsageError(
                f"--hevval-workers must be a whole number (got {value!r})"
            ) from None
        if count < 1:
            raise pytest.UsageError(f"--hevval-workers must be ≥ 1 (got {count})")
        return count

    @property
    def publisher(self) -> Publisher:
        if self._publisher is None:
            try:
                self._publisher = Publisher(PublishOptions.from_options(self.option, self.rootdir))
            except HevvalError as exc:
                raise pytest.UsageError(str(exc)) from None
        return self._publisher

    def validate_options(self) -> None:
        """Fail fast, before collection, on option values that cannot work."""
        self.workers()
        if self.option("dask") and self.config.getoption("numprocesses", None):
            raise pytest.UsageError(
                "--hevval-dask and -n both spread the specs over processes; use one of them"
            )
        self.publisher  # noqa: B018 (parses the report, compare and ratchet options)

    # -- session start: the baseline --------------------------------------------------------
    def start(self) -> None:
        """Pick the baseline before this run records anything (every process reads it)."""
        _freeze_objects_at_exit()
        try:
            self.notes.extend(self.publisher.start(controller=self.is_controller))
        except HevvalError as exc:
            raise pytest.UsageError(f"hevval: {exc}") from None

    # -- evaluation -------------------------------------------------------------------------
    def register(self, spec: Spec) -> None:
        self.specs[self.relative(spec.key)] = spec
        self.cache.declare_spec(spec)

    def run_options(self) -> RunOptions:
        """The scoring settings of this run, read from the options once."""
        if self._run_options is None:
            from ..scoring.run import RunOptions

            self._run_options = RunOptions(
                rootdir=self.rootdir,
                figures="html" in self.publisher.formats,
                workers=self.workers(),
                dask=str(self.option("dask")) if self.option("dask") else None,
                data_hash=str(self.option("hash")),
                intervals=not self.option("no-intervals"),
                diagnose=str(self.option("diagnose")),
            )
            self.cache.data_hash = self._run_options.data_hash
        return self._run_options

    def prefetch_on_dask(self) -> None:
        """Score every collected spec on the Dask cluster at once, before the items run."""
        options = self.run_options()
        if not options.dask or not self.specs:
            return
        specs = list(self.specs.values())
        from ..scoring.run import run_specs

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
            from ..scoring.run import run_specs

            (self.evaluations[key],) = run_specs([spec], options, cache=self.cache)
            # Its items judge from the evaluation: the data this spec declared may go.
            self.cache.release_spec(spec)
        outcome = self.evaluations[key]
        if isinstance(outcome, HevvalError):
            raise outcome
        return outcome

    def error_once(self, key: str, nodeid: str, error: HevvalError) -> str:
        """The text of a spec's error for the first of its items to report it; a pointer to
        that item for the others, so one bad spec prints its error once."""
        first = self.error_shown.setdefault(key, nodeid)
        if first == nodeid:
            return str(error)
        return f"not scored: the error of {first} stops this spec"

    def diagnosis_for(
        self, evaluation: Evaluation | None, signal: SignalResult
    ) -> Mapping[str, Any] | None:
        """The diagnosis of the signal where this signal's error appears, if enabled."""
        mode = self.option("diagnose")
        if evaluation is None or mode == "off" or (mode == "failed" and signal.passed):
            return None
        # Imported here: the diagnosis brings scipy.linalg, which a run without one never needs.
        from ..report.diagnosis import target_payload
        from ..scoring.diagnosis import diagnosis_target

        target = diagnosis_target(signal)
        found = evaluation.diagnoses.get(target)
        if found is None:
            return None
        return target_payload(evaluation.result.spec, target, found)

    def regressions_for(self, result: SpecResult, signal: str | None) -> list[str]:
        """Rules of --hevval-compare-fail this signal (or Φ, for None) breaks vs the baseline."""
        return self.publisher.regressions_for(result, signal)

    # -- results crossing from workers ------------------------------------------------------
    def ship(self, result: SpecResult) -> str | None:
        """The spec's result as JSON text the first time a worker reports on the spec; the
        controller (no xdist) keeps the typed result itself.

        Text, not a dict: xdist's serializer walks a dict value by value in Python, which for
        a campaign of thousands of signals cost the workers more than scoring them."""
        if result.spec in self.shipped:
            return None
        self.shipped.add(result.spec)
        if self.is_controller:
            self.results[result.spec] = result
            return None
        return json.dumps(result.to_dict())

    def keep_diagnosis(self, payload: Mapping[str, Any]) -> str | None:
        """Keep a diagnosis for the reports; JSON text to ship when this is a worker."""
        if self.is_controller:
            self.diagnoses.update(diagnosis_panels([payload]))
            return None
        return json.dumps(payload)

    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        # A worker sees its own reports too; only the controller gathers what they carry.
        if not self.is_controller:
            return
        if report.when == "setup" and report.failed and _is_spec_item(report):
            # The item's own node id less its name: the spec, or a campaign's recording.
            spec = report.nodeid.rsplit("::", 1)[0]
            error = report.longreprtext.strip().splitlines() or ["its setup failed"]
            self.unscored.setdefault(spec, error[0])
        payload = getattr(report, "hevval_spec", None)
        if payload is not None:
            self._receive(payload)
        diagnosis = getattr(report, "hevval_diagnosis", None)
        if diagnosis is not None:
            self.diagnoses.update(diagnosis_panels([json.loads(diagnosis)]))
        for recording in getattr(report, "hevval_campaign", None) or ():
            self._receive(recording)
        carried = getattr(report, "hevval_carried", None)
        if carried is not None:
            self.carried[report.nodeid] = (json.loads(carried), getattr(report, "node", None))

    def pytest_runtest_logfinish(self, nodeid: str) -> None:
        found = self.carried.pop(nodeid, None)
        if found is None or self.session is None:
            return
        outcomes, node = found
        for outcome in outcomes:
            log_outcome(self.session, outcome, node)

    # -- campaign gates under xdist ------------------------------------------------------------
    def defer(self, gates: list[dict[str, Any]]) -> None:
        """On a worker: hand the campaign gates to the controller (with the worker's output)."""
        output: dict[str, Any] = self.config.workeroutput  # type: ignore[attr-defined]
        output[_GATES] = gates

    def receive_gates(self, output: Mapping[str, Any]) -> None:
        """On the controller: the gates a worker deferred (every worker defers the same)."""
        for gate in output.get(_GATES, ()):
            self.gates.setdefault(gate["nodeid"], gate)

    def judge_gates(self, session: pytest.Session) -> None:
        """Judge each deferred campaign gate on the results every worker sent, and report it
        as its item's outcome. A recording no worker scored (deselected with -k, or its data
        failed) is scored here, as the gate item does without xdist."""
        from ..spec.load import load_specs

        for gate in self.gates.values():
            outcomes: dict[str, SpecResult | HevvalError] = {}
            for key in gate["recordings"]:
                if key not in self.results:
                    try:
                        for spec in load_specs(str(self.rootdir / key)):
                            self.ship(self.evaluate(spec).result)
                    except HevvalError as exc:
                        outcomes[key] = exc
                        continue
                outcomes[key] = self.results[key]
            pass_rate, failure = judge_campaign(outcomes)
            _log_gate(session, gate, pass_rate, failure)

    def _receive(self, payload: str) -> None:
        data = json.loads(payload)
        result = SpecResult.from_dict(data)
        self.results[result.spec] = result
        self.received[result.spec] = data

    def spec_results(self) -> list[SpecResult]:
        return [self.results[k] for k in sorted(self.results)]

    def relative(self, path: str) -> str:
        return relative_to(self.rootdir, path)

    # -- session end ------------------------------------------------------------------------
    def end(self, session: pytest.Session) -> None:
        """In every process: a kernel this run would have used is compiled for the next runs
        (before a worker reports done, so that the controller's note finds it under way)."""
        from ..data.kernel_cache import finish_run

        finish_run()
        if self.is_controller:
            self.finish(session)

    def finish(self, session: pytest.Session) -> None:
        """Judge deferred campaign gates; write reports, the comparison, the ratchet and the
        history record, once."""
        from ..data.kernel_cache import compile_note

        if self.gates and not (session.shouldfail or session.shouldstop):
            self.judge_gates(session)

        results = self.spec_results()
        dicts = [self.received.get(r.spec) or r.to_dict() for r in results]
        errors = [f"{spec}: {error}" for spec, error in self.unscored.items()]
        published = self.publisher.publish(results, self.specs, self.diagnoses, dicts, errors)
        self.verdict = published.verdict
        self.notes.extend(published.notes)
        kernel_note = compile_note()
        if kernel_note is not None:
            self.notes.append(kernel_note)
        self.annotations.extend(published.annotations)
        if published.failed and session.exitstatus == pytest.ExitCode.OK:
            session.exitstatus = pytest.ExitCode.TESTS_FAILED

    def summarise(self, terminalreporter: Any) -> None:
        results = self.spec_results()
        if not results and not self.notes and not self.annotations:
            return
        for line in self.annotations:
            terminalreporter.write_line(line)
        terminalreporter.write_sep("=", "hevval validation summary")
        for line in run_summary(
            results, details=bool(self.option("details")), verdict=self.verdict
        ):
            terminalreporter.write_line(terminal(line))
        for note in self.notes:
            for line in note.splitlines():
                terminalreporter.write_line(terminal(line))


def _is_spec_item(report: pytest.TestReport) -> bool:
    """Whether a report is of a spec's item (a signal or Φ), whichever process ran it: those
    name their place ``hevval <spec name>: <item>`` (``items._SpecItem.reportinfo``)."""
    return str(report.location[2]).startswith(SPEC_ITEM_PLACE)


def judge_campaign(
    outcomes: Mapping[str, SpecResult | HevvalError],
) -> tuple[float | None, str | None]:
    """A campaign gate's (pass rate, failure text or None) from its recordings' outcomes, by
    recording: what its item reports, in this process or, under xdist, on the controller."""
    from ..report.terminal import verdict_lines
    from ..results.campaign import verdict

    results = [o for o in outcomes.values() if isinstance(o, SpecResult)]
    if not results:
        return None, "no recording of the campaign could be scored:\n" + "\n".join(
            f"  {name}: {error}" for name, error in outcomes.items()
        )
    found = verdict(results)
    return found.pass_rate, None if found.passed else "\n".join(verdict_lines(found))


def _freeze_objects_at_exit() -> None:
    """At exit, move every object out of the cycle collector's reach (``gc.freeze``).

    A campaign leaves hundreds of thousands of objects (pytest's reports, the results) that the
    interpreter walks in each of its collections while it shuts down: about a second for 200
    recordings, paid by every process of the run and, under xdist, by the controller waiting
    for its workers to end. Nothing needs a cycle collected once the process exits, and an
    ``atexit`` handler runs only then, so a pytest run inside another (pytester) loses nothing.
    """
    global _freeze_registered
    if not _freeze_registered:
        atexit.register(gc.freeze)
        _freeze_registered = True


_freeze_registered = False


def _log_gate(
    session: pytest.Session, gate: Mapping[str, Any], pass_rate: float | None, failure: str | None
) -> None:
    """Report a campaign gate's outcome as pytest reports a run item: the terminal, JUnit XML
    and ``--lf`` see it like any other."""
    log_outcome(
        session,
        {
            "nodeid": gate["nodeid"],
            "location": gate["location"],
            "keywords": gate["keywords"],
            "outcome": "passed" if failure is None else "failed",
            "when": "call",
            "longrepr": None if failure is None else terminal(failure),
            "user_properties": [
                *gate.get("properties", []),
                *([] if pass_rate is None else [["pass_rate", f"{pass_rate:.6f}"]]),
            ],
        },
    )


@dataclass(eq=False)
class _SetupError(TerminalRepr):
    """A setup error's text as pytest reports a ``pytest.fail`` in setup: the text, and the
    crash line ``Failed: …`` that the short summary and JUnit XML quote."""

    text: str

    @property
    def reprcrash(self) -> SimpleNamespace:
        return SimpleNamespace(message=f"Failed: {self.text}", path=None, lineno=None)

    def toterminal(self, tw: TerminalWriter) -> None:
        tw.line(self.text)


def log_outcome(session: pytest.Session, outcome: Mapping[str, Any], node: Any = None) -> None:
    """Report an item run elsewhere (:func:`pytest_hevval.plugin.items.outcome_of`) as pytest
    reports a run item, phase by phase; ``node`` is the xdist worker that judged it."""
    hook = session.config.hook
    nodeid = str(outcome["nodeid"])
    fspath, lineno, domain = outcome["location"]
    location = (str(fspath), lineno, str(domain))
    keywords: dict[str, Literal[1]] = {str(word): 1 for word in outcome["keywords"]}
    failed_when = outcome["when"] if outcome["outcome"] == "failed" else None
    properties = [(str(k), str(v)) for k, v in outcome["user_properties"]]
    hook.pytest_runtest_logstart(nodeid=nodeid, location=location)
    # A setup that fails has no call phase, as in pytest's own run of an item.
    phases: tuple[Literal["setup", "call", "teardown"], ...] = (
        ("setup", "teardown") if failed_when == "setup" else ("setup", "call", "teardown")
    )
    for when in phases:
        failed = when == failed_when
        text = outcome["longrepr"]
        report = pytest.TestReport(
            nodeid,
            location,
            keywords,
            "failed" if failed else "passed",
            (_SetupError(text) if when == "setup" else text) if failed else None,
            when,
            user_properties=properties if when != "setup" else [],
        )
        if node is not None:
            report.node = node  # type: ignore[attr-defined]
        if when == "call" and outcome.get("diagnosis"):
            # Gathered from the report, as from a worker's (pytest_runtest_logreport).
            report.hevval_diagnosis = outcome["diagnosis"]  # type: ignore[attr-defined]
        hook.pytest_runtest_logreport(report=report)
        if node is not None and failed:
            _count_worker_failure(session, report)
    # pytest's session counts the failure from its report (testsfailed, --maxfail).
    hook.pytest_runtest_logfinish(nodeid=nodeid, location=location)


def _count_worker_failure(session: pytest.Session, report: pytest.TestReport) -> None:
    """Count a failure judged on an xdist worker as xdist counts the failures its workers
    report, so that -x and --maxfail stop the workers as they do for any item.

    xdist counts them in its own session plugin, not in pytest's: without this the controller
    knew of the failure, but the workers went on with their queues to the end."""
    dsession = session.config.pluginmanager.getplugin("dsession")
    count = getattr(dsession, "_handlefailures", None)
    if callable(count):
        count(report)
