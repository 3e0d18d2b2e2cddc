"""Per-process state of one pytest session: the run, and what crosses between processes.

The hooks in :mod:`pytest_hevval.plugin` delegate here, and this to the session's
:class:`~pytest_hevval.run.Run`, which scores, judges and publishes. Every process scores the
specs of the items it runs; only the controller (the process without ``workerinput``) writes
history and reports, once, from the results the workers' reports carry back. What is left here
is pytest's side: the options read once, results and outcomes shipped between xdist processes,
and errors worded for pytest.
"""

from __future__ import annotations

import atexit
import gc
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any, Literal

import pytest
from _pytest._code.code import TerminalRepr
from _pytest._io import TerminalWriter

from ..errors import HevvalError
from ..escape import terminal
from ..flags import PYTEST
from ..options import snapshot
from ..results.spec_result import SignalResult, SpecResult
from ..run import ClusterUnavailable, Run, RunSettings
from ..spec.model import Spec

if TYPE_CHECKING:
    from ..scoring.engine import Evaluation

__all__ = ["HevvalSession"]

#: How a spec's item names its place in pytest's reports (``items._SpecItem.reportinfo``).
SPEC_ITEM_PLACE = "hevval "
#: The key of the campaign gates in an xdist worker's output to the controller.
_GATES = "hevval_campaign_gates"


# eq=False keeps identity hashing: pluggy (before 1.4) keeps registered plugins in a set.
@dataclass(eq=False)
class HevvalSession:
    config: pytest.Config
    #: This process's share of the run (the whole run on the controller).
    run: Run
    #: Spec results already attached to a report by this process.
    shipped: set[str] = field(default_factory=set)
    #: The item that reported each spec's error first, by spec key.
    error_shown: dict[str, str] = field(default_factory=dict)
    #: Campaign gate items the xdist workers left to this controller, by node id.
    gates: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: Outcomes of items a worker judged with another one (``items.carry_spec_items``), by the
    #: node id of the item whose report carried them, with the worker; reported once that
    #: item's reports are in.
    carried: dict[str, tuple[list[dict[str, Any]], Any]] = field(default_factory=dict)
    session: pytest.Session | None = None

    @classmethod
    def configure(cls, config: pytest.Config) -> HevvalSession:
        """The session of this process: pytest's options read once into the run's settings,
        checked before collection; a value that cannot work is a usage error."""
        worker = getattr(config, "workerinput", None)
        values = snapshot(config)
        try:
            settings = RunSettings.read(
                values.__getitem__,
                Path(str(config.rootpath)),
                PYTEST,
                processes=None if worker is None else int(worker.get("workercount", 1)),
                item_reports=True,
            )
            if settings.dask and config.getoption("numprocesses", None):
                raise pytest.UsageError(
                    f"{PYTEST.flag('dask')} and -n both spread the specs over processes; "
                    "use one of them"
                )
            run = Run(settings, controller=worker is None)
        except HevvalError as exc:
            raise pytest.UsageError(str(exc)) from None
        return cls(config, run)

    @property
    def is_controller(self) -> bool:
        return self.run.controller

    # -- session start: the baseline --------------------------------------------------------
    def start(self) -> None:
        """Pick the baseline before this run records anything (every process reads it)."""
        _freeze_objects_at_exit()
        try:
            self.run.start()
        except HevvalError as exc:
            raise pytest.UsageError(f"hevval: {exc}") from None

    # -- evaluation -------------------------------------------------------------------------
    def evaluate(self, spec: Spec) -> Evaluation:
        """The spec's evaluation (scored once per process); a Dask scheduler that cannot
        score is a usage error, a spec that cannot be scored its items' error."""
        try:
            return self.run.evaluate(spec)
        except ClusterUnavailable as exc:
            raise pytest.UsageError(str(exc)) from None

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
        return self.run.diagnosis_for(evaluation, signal)

    def regressions_for(self, result: SpecResult, signal: str | None) -> list[str]:
        """Rules of compare-fail this signal (or Φ, for None) breaks against the baseline."""
        return self.run.regressions_for(result, signal)

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
            self.run.keep(result)
            return None
        return json.dumps(result.to_dict())

    def keep_diagnosis(self, payload: Mapping[str, Any]) -> str | None:
        """Keep a diagnosis for the reports; JSON text to ship when this is a worker."""
        if self.is_controller:
            self.run.keep_diagnoses([payload])
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
            self.run.unscored.setdefault(spec, error[0])
        payload = getattr(report, "hevval_spec", None)
        if payload is not None:
            self.run.receive(json.loads(payload))
        diagnosis = getattr(report, "hevval_diagnosis", None)
        if diagnosis is not None:
            self.run.keep_diagnoses([json.loads(diagnosis)])
        for recording in getattr(report, "hevval_campaign", None) or ():
            self.run.receive(json.loads(recording))
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

    def relative(self, path: str) -> str:
        return self.run.relative(path)

    # -- session end ------------------------------------------------------------------------
    def end(self, session: pytest.Session) -> None:
        """In every process: scoring closes (before a worker reports done, so that the
        controller's note finds a kernel compile under way). On the controller: the campaign
        gates the workers deferred are judged and reported as their items' outcomes, then the
        run is finished once (verdict, reports, comparison, ratchet, history record)."""
        run = self.run
        run.close_scoring()
        if not run.controller:
            return
        if self.gates and not (session.shouldfail or session.shouldstop):
            for gate in self.gates.values():
                pass_rate, failure = run.judge_gate(gate["recordings"])
                _log_gate(session, gate, pass_rate, failure)
        if run.finish().publishing_failed and session.exitstatus == pytest.ExitCode.OK:
            session.exitstatus = pytest.ExitCode.TESTS_FAILED

    def summarise(self, terminalreporter: Any) -> None:
        run = self.run
        if not run.results and not run.notes and not run.annotations:
            return
        for line in run.annotations:
            terminalreporter.write_line(line)
        terminalreporter.write_sep("=", "hevval validation summary")
        for line in run.summary():
            terminalreporter.write_line(terminal(line))
        for note in run.notes:
            for line in note.splitlines():
                terminalreporter.write_line(terminal(line))


def _is_spec_item(report: pytest.TestReport) -> bool:
    """Whether a report is of a spec's item (a signal or Φ), whichever process ran it: those
    name their place ``hevval <spec name>: <item>`` (``items._SpecItem.reportinfo``)."""
    return str(report.location[2]).startswith(SPEC_ITEM_PLACE)


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
