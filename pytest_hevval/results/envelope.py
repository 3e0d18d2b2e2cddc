"""One envelope around a run's results: the documents a run leaves, built and read here.

Three documents hold a run's results: the run document (``hevval run --json``), the report
(``report.json``) and the history record. Inside, each holds the same spec results
(``SpecResult.to_dict``, result schema :data:`~.spec_result.RESULT_SCHEMA_VERSION`); they
differ only in what they wrap around them. :func:`run_document` builds the run document and
:func:`history_record` the record (its layout in :mod:`.record_schema`); :func:`read_document`
reads any of the three, as this version or an earlier one wrote it, into the spec results
and the run's facts (model version, start time, tool versions), migrating old forms.

Schema versions. The run document's ``schema_version`` is the result schema's, 2: the
document is the results plus the run's facts, and it says the one version its results carry
(versions up to 0.x wrote 1 there beside results of schema 2; both read the same). A history
record keeps the ``schema_version`` of its own documented layout (4; 1 to 3 are migrated) and
``report.json`` its ``report_schema_version``; the results inside both are of the same result
schema.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import datetime
from typing import Any, Literal

from .campaign import CampaignVerdict
from .record_schema import (
    ACCEPTANCE,
    SCHEMA_VERSION,
    HistoryError,
    baseline_summary,
    check_acceptance,
    format_utc,
    migrate_record,
    normalised_spec,
)
from .recorded import RecordedRun
from .spec_result import RESULT_SCHEMA_VERSION
from .verdict import RunVerdict

__all__ = [
    "RUN_SCHEMA_VERSION",
    "RunDocument",
    "history_record",
    "read_document",
    "run_document",
]

#: The ``schema_version`` of the run document: that of the results it holds.
RUN_SCHEMA_VERSION = RESULT_SCHEMA_VERSION

#: What to pass instead, when a file is none of the documents.
_HINT_WHAT = "pass the output of `hevval run --json` or a history record"


def run_document(
    specs: Sequence[Mapping[str, Any]],
    *,
    facts: Mapping[str, Any],
    verdict: RunVerdict,
    campaigns: Sequence[CampaignVerdict] = (),
    errors: Sequence[Mapping[str, Any]] = (),
) -> dict[str, Any]:
    """The run document (``hevval run --json``): the spec results (JSON data, in order), the
    run's ``facts`` as its history record holds them, its verdict, the campaign verdicts and
    the specs that could not be scored (``errors``, each a JSON object)."""
    from .. import __version__

    payload: dict[str, Any] = {
        "schema_version": RUN_SCHEMA_VERSION,
        "hevval_version": __version__,
        # The run's facts, as a history record holds them (hevval evidence reads them).
        "run": dict(facts),
        "passed": verdict.passed,
        "verdict": verdict.to_dict(),
        "specs": list(specs),
        **({"campaigns": [v.to_dict() for v in campaigns]} if campaigns else {}),
        **({"errors": list(errors)} if errors else {}),
    }
    # The common single-spec case also exposes the spec's own fields at the top level.
    if len(specs) == 1:
        payload.update({k: v for k, v in specs[0].items() if k != "schema_version"})
    return payload


def history_record(
    specs: Sequence[Mapping[str, Any]],
    *,
    model_version: str,
    tool_versions: Mapping[str, str],
    started_utc: datetime,
    acceptance: str,
    commit: str | None,
    baseline: Mapping[str, Any] | None,
) -> dict[str, Any]:
    """The history record of a run: its spec results (JSON data) in the record's layout
    (:mod:`.record_schema`), checked: figures and diagnoses left out, non-finite numbers
    ``null``; ``acceptance`` is a key of :data:`~.record_schema.ACCEPTANCE`."""
    record = {
        "schema_version": SCHEMA_VERSION,
        "model_version": model_version.strip(),
        "started_utc": format_utc(started_utc),
        "commit": commit,
        "accepted": ACCEPTANCE.get(acceptance),
        "acceptance": acceptance,
        "baseline": None if baseline is None else baseline_summary(baseline),
        "tool_versions": dict(tool_versions),
        "specs": [normalised_spec(spec, f"specs[{i}]", None) for i, spec in enumerate(specs)],
    }
    check_acceptance(record, None)
    return record


@dataclass(frozen=True)
class RunDocument:
    """A document a run left, read: which kind, and its content in the current form."""

    kind: Literal["record", "run", "report"]
    #: The document, migrated: a record of the current schema, or a run document or report
    #: whose ``specs`` holds only spec results.
    content: dict[str, Any]

    @property
    def source(self) -> str:
        """Where the results come from, in words: ``history record`` or ``hevval run`` (a
        run document, or a report, which holds the same results)."""
        return "history record" if self.kind == "record" else "hevval run"

    @property
    def specs(self) -> list[dict[str, Any]]:
        """The spec results, as JSON data."""
        specs: list[dict[str, Any]] = self.content["specs"]
        return specs

    @property
    def facts(self) -> dict[str, Any]:
        """The run's facts (model version, start, tool versions): a record holds them at its
        top, a run document under ``run``; a report holds none."""
        if self.kind == "record":
            return self.content
        facts = self.content.get("run") if self.kind == "run" else None
        return dict(facts) if isinstance(facts, Mapping) else {}

    def recorded(self) -> RecordedRun:
        """The run as history compares it: its results and facts, typed."""
        return RecordedRun.from_json(self.content, self.specs)


def read_document(document: Any, *, file: str | None = None) -> RunDocument:
    """Read any document a run of this or an earlier version wrote: a history record of any
    schema (migrated to the current one), a run document of schema 1 or 2, or a report.json.
    Anything else raises :class:`HistoryError` naming ``file``."""
    if (
        isinstance(document, dict)
        and "schema_version" in document
        and ("model_version" in document or "results" in document)
    ):
        return RunDocument("record", migrate_record(document, file=file))
    if isinstance(document, dict) and isinstance(document.get("specs"), list):
        version = document.get("schema_version")
        if type(version) is int and version > RUN_SCHEMA_VERSION:
            raise HistoryError(
                f"schema_version {version} is newer than this pytest-hevval understands "
                f"(up to {RUN_SCHEMA_VERSION})",
                file=file,
                key="schema_version",
                hint="upgrade pytest-hevval to read it",
            )
        specs = [spec for spec in document["specs"] if isinstance(spec, Mapping)]
        kind: Literal["run", "report"] = "report" if "report_schema_version" in document else "run"
        return RunDocument(kind, {**document, "specs": specs})
    raise HistoryError(
        "neither a history record nor a run result (no 'specs' list)",
        file=file,
        hint=_HINT_WHAT,
    )
