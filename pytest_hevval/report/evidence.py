"""One evidence record per run: what an auditor needs to reproduce and trust its verdicts.

The record is one JSON document (``evidence.json``) that validates against the schema shipped
with the package (``pytest_hevval/schemas/evidence.schema.json``, :func:`schema`): the tool
and its scoring path, the environment, each spec file's digest, each data file's digest, the
model's identity and parameters, every verdict with its interval, the requirement links and the
model's runtime. It is made from a run's spec results and the facts of the run (model version,
start time, tool versions), so ``hevval evidence`` makes the same record from a history record
or a ``hevval run --json`` file as ``--hevval-report=evidence`` does during the run
(docs/evidence.md).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from importlib import resources
from typing import Any

from ..core.uncertainty import Interval
from ..results.codec import json_number, plain_json
from ..results.spec_facts import FileData, ModelData
from ..results.spec_result import SignalResult, SpecResult
from ..results.verdict import RunVerdict
from .model import campaigns_of

__all__ = ["EVIDENCE_SCHEMA_VERSION", "RunFacts", "evidence_record", "render_evidence", "schema"]

EVIDENCE_SCHEMA_VERSION = 1
#: The schema's file inside the package.
SCHEMA_FILE = "evidence.schema.json"

#: What a run's facts hold: ``model_version``, ``started_utc`` and ``tool_versions`` (the
#: history record's keys), any of which may be missing.
RunFacts = Mapping[str, Any]

#: Model keys that identify it (beside its kind).
_MODEL_KEYS = (
    "callable",
    "module_file",
    "module_sha256",
    "path",
    "hash",
    "digest",
    "guid",
    "params",
)
#: A campaign's gate verdict as the record keeps it.
_CAMPAIGN_KEYS = (
    "spec",
    "name",
    "passed",
    "pass_rate",
    "min_pass_rate",
    "phi_quantile",
    "failures",
)
_NO_RUNTIME = {
    "file": "the model is exported files: it ran elsewhere, so no runtime was measured",
    None: "no runtime was recorded with this result",
}


def schema() -> dict[str, Any]:
    """The evidence record's JSON Schema (draft 2020-12), as shipped with the package."""
    shipped = resources.files("pytest_hevval").joinpath("schemas").joinpath(SCHEMA_FILE)
    document: dict[str, Any] = json.loads(shipped.read_text("utf-8"))
    return document


def _interval(interval: Interval | None) -> dict[str, Any] | None:
    if interval is None:
        return None
    return {"low": interval.low, "high": interval.high}


def _lambda_interval(interval: Interval) -> dict[str, Any] | None:
    """A λ's interval as its result's JSON holds it: no bounds where the low one is unknown."""
    low = json_number(interval.low)
    return None if low is None else {"low": low, "high": json_number(interval.high)}


def _signal(signal: SignalResult) -> dict[str, Any]:
    """What the record keeps of a signal: its verdict and what it was judged on."""
    return {
        "path": signal.path,
        "passed": signal.passed,
        "lambdas": {name: float(v) for name, v in signal.lambdas.items()},
        "thresholds": dict(signal.thresholds),
        "failures": [f.to_dict() for f in signal.failures],
        "requirements": list(signal.requirements),
        "intervals": {name: _lambda_interval(i) for name, i in signal.intervals.items()},
    }


def _source(side: FileData | None) -> dict[str, Any]:
    return {
        "path": side.path if side is not None else None,
        "hash": side.hash if side is not None else None,
        "digest": side.digest if side is not None else None,
    }


def _model(model: ModelData | None) -> dict[str, Any]:
    # The record names what the result recorded of its model, in the result's own JSON form.
    recorded = model.to_dict() if model is not None else {}
    out: dict[str, Any] = {"kind": recorded.get("kind", "file")}
    out.update({key: recorded[key] for key in _MODEL_KEYS if key in recorded})
    out.setdefault("params", {})
    return out


def _spec(spec: SpecResult) -> dict[str, Any]:
    model = _model(spec.data.model)
    out: dict[str, Any] = {
        "key": spec.spec,
        "name": spec.name,
        "spec_sha256": spec.spec_hash or None,
        "recording": spec.recording,
        "role": spec.role,
        "reference": _source(spec.data.reference),
        "model": model,
        "verdict": {
            "passed": spec.passed,
            "phi": spec.phi,
            "phi_interval": _interval(spec.phi_interval),
            "min_phi": spec.min_phi,
            "min_phi_on": spec.min_phi_on,
            "phi_passed": spec.phi_passed,
        },
        "requirements": list(spec.requirements),
        "signals": [_signal(s) for s in spec.signals],
        "runtime": spec.runtime.to_dict() if spec.runtime is not None else None,
    }
    if out["runtime"] is None:
        out["runtime_note"] = _NO_RUNTIME.get(model["kind"], _NO_RUNTIME[None])
    return out


def _links(specs: Sequence[SpecResult]) -> dict[str, list[dict[str, Any]]]:
    """Requirement ID → the items that verify it, spec by spec."""
    links: dict[str, list[dict[str, Any]]] = {}
    for spec in specs:
        for requirement in spec.requirements:
            links.setdefault(requirement, []).append({"spec": spec.spec, "items": ["Phi"]})
        found: dict[str, list[str]] = {}
        for signal in spec.signals:
            for requirement in signal.requirements:
                if requirement not in spec.requirements:
                    found.setdefault(requirement, []).append(signal.path)
        for requirement, paths in found.items():
            links.setdefault(requirement, []).append({"spec": spec.spec, "items": paths})
    return dict(sorted(links.items()))


def evidence_record(
    spec_results: Sequence[SpecResult],
    facts: RunFacts,
    *,
    source: str,
    verdict: RunVerdict | None = None,
) -> dict[str, Any]:
    """The evidence record of a run: its spec results and facts.

    ``source`` says where the results come from: ``pytest run``, ``hevval run`` output or a
    ``history record``.
    """
    versions = dict(facts.get("tool_versions") or {})
    specs = [_spec(spec) for spec in spec_results]
    campaigns = [
        {key: found[key] for key in _CAMPAIGN_KEYS}
        for found in (judged.to_dict() for judged in campaigns_of(spec_results, verdict))
    ]
    record = {
        "evidence_schema_version": EVIDENCE_SCHEMA_VERSION,
        "source": source,
        "run": {
            "model_version": facts.get("model_version"),
            "started_utc": facts.get("started_utc"),
            "passed": all(s["verdict"]["passed"] for s in specs)
            and all(c["passed"] for c in campaigns),
        },
        "tool": {
            "name": "pytest-hevval",
            "version": versions.get("pytest-hevval"),
            "kernel": versions.get("kernel"),
        },
        "environment": {
            "python": versions.get("python"),
            "numpy": versions.get("numpy"),
            "scipy": versions.get("scipy"),
            "pandas": versions.get("pandas"),
            "platform": versions.get("platform"),
        },
        "specs": specs,
        "campaigns": campaigns,
        "requirements": _links(spec_results),
    }
    plain: dict[str, Any] = plain_json(record)
    return plain


def render_evidence(
    spec_results: Sequence[SpecResult],
    facts: RunFacts,
    *,
    source: str,
    verdict: RunVerdict | None = None,
) -> str:
    """:func:`evidence_record` as sorted, strict JSON text (``verdict``: the run's, whose
    campaign verdicts it reuses; without one they are judged from the results)."""
    record = evidence_record(spec_results, facts, source=source, verdict=verdict)
    return json.dumps(record, indent=2, sort_keys=True, ensure_ascii=False, allow_nan=False) + "\n"
