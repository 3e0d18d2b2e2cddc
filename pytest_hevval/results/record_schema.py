"""The history record's layout: its current schema, its validation, and the migration of the
schemas before it.

A record is plain JSON (see ``docs/history.md``)::

    {"schema_version": 4, "model_version": "v1.4-3-gabc123", "started_utc": "...Z",
     "commit": "<git commit>" | null, "accepted": true, "acceptance": "no-regression",
     "baseline": {"model_version": ..., "started_utc": ..., "commit": ...} | null,
     "tool_versions": {"pytest-hevval": "...", "numpy": "...", "scipy": "...", "python": "..."},
     "specs": [<spec result>, ...]}

Each signal's ``lambdas`` and each spec's ``weights`` map characteristic name to value.
Schema 3 (no acceptance, commit or baseline: read as accepted), schema 2 (λ values and weights
as lists in paper order) and schema 1 (``version``, ``timestamp`` in POSIX seconds, ``tools``,
``results``) are migrated on read; records are never rewritten on disk.

This lives with the results, not in ``history/``, because a record is one of the envelopes
around a run's results (:mod:`.envelope`): the envelope writes records and reads them with
every other document a run leaves, and the history folder only stores and finds them.
"""

from __future__ import annotations

from collections.abc import Mapping
from datetime import datetime, timezone
from typing import Any

from ..core.registry import PAPER_CHARACTERISTICS
from ..errors import HevvalError
from .codec import checked_number, plain_json
from .spec_result import ERROR_KEYS, MEASURED_NUMBERS

__all__ = [
    "ACCEPTANCE",
    "EARLIER_SCHEMA",
    "SCHEMA_VERSION",
    "HistoryError",
    "baseline_summary",
    "check_acceptance",
    "format_utc",
    "migrate_record",
    "normalised_spec",
    "parse_utc",
    "validate_record",
]


class HistoryError(HevvalError, ValueError):
    """A history record, history folder, comparison rule or threshold sidecar is unusable."""


SCHEMA_VERSION = 4
#: Why a run was, or was not, accepted as a baseline (its record's ``acceptance``), and
#: whether it was (its ``accepted``): one table, so the two fields never disagree.
ACCEPTANCE: dict[str, bool] = {
    "not-compared": True,  # the run asked for no comparison
    "no-regression": True,  # compared with a baseline; no rule of compare-fail broken
    "first-baseline": True,  # no baseline yet, and --hevval-create-baseline made this one
    "manual": True,  # --hevval-accept, whatever the comparison found
    "earlier-schema": True,  # written before records carried acceptance (schema 1 to 3)
    "regressed": False,  # broke a rule of compare-fail against the baseline
    "no-baseline": False,  # asked for a comparison and found nothing to compare with
}
#: The acceptance of a record written before records carried one.
EARLIER_SCHEMA = "earlier-schema"

# Keys kept from a spec result and from each signal result. A whitelist keeps the documented
# record format stable and small: figures and diagnosis payloads are not archived.
_SPEC_KEYS = (
    "schema_version",
    "name",
    "spec",
    "spec_hash",
    "phi",
    "min_phi",
    "min_phi_line",
    "min_phi_on",
    "phi_interval",
    "phi_passed",
    "passed",
    "weights",
    "data",
    "alignment",
    "local",
    "requirements",
    "runtime",
)
_SIGNAL_KEYS = (
    "path",
    "name",
    "set",
    "level",
    "position",
    "alpha",
    "line",
    "unit",
    "description",
    "lambdas",
    *ERROR_KEYS,
    "components",
    "thresholds",
    "failures",
    "passed",
    "origin",
    "origins",
    "children",
    "intervals",
    "block_samples",
    "within_uncertainty",
    "requirements",
)
_HINT_CORRUPT = (
    "the file was not written by pytest-hevval or was edited by hand; "
    "restore it from version control or move it out of the history folder"
)


def format_utc(moment: datetime) -> str:
    """ISO 8601 in UTC with microseconds and a ``Z``: ``2024-05-01T12:00:00.000000Z``."""
    if moment.tzinfo is None or moment.utcoffset() is None:
        raise HistoryError(
            f"started_utc must be timezone-aware (got naive {moment.isoformat()})",
            hint="pass datetime.now(timezone.utc)",
        )
    return moment.astimezone(timezone.utc).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def parse_utc(text: Any, *, where: str = "started_utc", file: str | None = None) -> datetime:
    """Parse the ISO 8601 time of a record into an aware UTC ``datetime``."""
    if not isinstance(text, str):
        raise HistoryError(
            f"expected an ISO 8601 UTC time string (got {text!r})",
            file=file,
            key=where,
            hint=_HINT_CORRUPT,
        )
    try:
        # Python 3.10's fromisoformat does not accept a trailing Z.
        moment = datetime.fromisoformat(text[:-1] + "+00:00" if text.endswith("Z") else text)
    except ValueError:
        raise HistoryError(
            f"not an ISO 8601 time (got {text!r})", file=file, key=where, hint=_HINT_CORRUPT
        ) from None
    if moment.tzinfo is None:
        moment = moment.replace(tzinfo=timezone.utc)
    try:
        return moment.astimezone(timezone.utc)
    except OverflowError:  # 9999-12-31T23:59:59-12:00 is in year 10000 in UTC
        raise HistoryError(
            f"the time {text!r} lies outside the years 1 to 9999 in UTC",
            file=file,
            key=where,
            hint=_HINT_CORRUPT,
        ) from None


def baseline_summary(record: Mapping[str, Any]) -> dict[str, Any]:
    """What a record keeps of the baseline its run was compared with."""
    return {
        "model_version": record["model_version"],
        "started_utc": record["started_utc"],
        "commit": record.get("commit"),
    }


def migrate_record(document: Any, *, file: str | None = None) -> dict[str, Any]:
    """Return ``document`` as a validated schema-3 record, migrating older layouts.

    Schema 3 differs from 4 in that it has no ``accepted``, ``acceptance``, ``commit`` or
    ``baseline``: such a record is read as accepted (acceptance ``earlier-schema``), as every
    record was a baseline then. Schema 2 differs from 3 only in that each signal's ``lambdas``
    and each spec's ``weights`` were lists in paper order (λ1…λ7) rather than mappings by
    characteristic name.
    Schema 1 differs from 2 in four places: ``version`` → ``model_version``; ``timestamp``
    (POSIX seconds) → ``started_utc`` (ISO 8601 UTC); ``tools`` → ``tool_versions``;
    ``results`` → ``specs``; and each signal's ``lambdas`` was a mapping by characteristic name
    rather than a list in paper order.
    """
    if not isinstance(document, Mapping):
        raise HistoryError(
            f"a history record must be a JSON object (got {type(document).__name__})",
            file=file,
            hint=_HINT_CORRUPT,
        )
    version = document.get("schema_version")
    if version == SCHEMA_VERSION:
        return validate_record(document, file=file)
    if version == 3:
        return validate_record(_migrate_3_to_4(document), file=file)
    if version == 2:
        return validate_record(_migrate_3_to_4(_migrate_2_to_3(document)), file=file)
    if version == 1:
        migrated = _migrate_3_to_4(_migrate_2_to_3(_migrate_1_to_2(document, file)))
        return validate_record(migrated, file=file)
    if isinstance(version, int) and not isinstance(version, bool) and version > SCHEMA_VERSION:
        raise HistoryError(
            f"schema_version {version} is newer than this pytest-hevval understands "
            f"(up to {SCHEMA_VERSION})",
            file=file,
            key="schema_version",
            hint="upgrade pytest-hevval to read it",
        )
    raise HistoryError(
        f"unknown schema_version (got {version!r}); expected 1 to {SCHEMA_VERSION}",
        file=file,
        key="schema_version",
        hint=_HINT_CORRUPT,
    )


def _migrate_1_to_2(old: Mapping[str, Any], file: str | None) -> dict[str, Any]:
    timestamp = old.get("timestamp")
    if isinstance(timestamp, bool) or not isinstance(timestamp, (int, float)):
        raise HistoryError(
            f"schema 1 needs a numeric timestamp in POSIX seconds (got {timestamp!r})",
            file=file,
            key="timestamp",
            hint=_HINT_CORRUPT,
        )
    try:
        started = datetime.fromtimestamp(float(timestamp), tz=timezone.utc)
    except (OverflowError, OSError, ValueError):
        raise HistoryError(
            f"timestamp out of range (got {timestamp!r})",
            file=file,
            key="timestamp",
            hint=_HINT_CORRUPT,
        ) from None
    results = old.get("results")
    if not isinstance(results, list):
        raise HistoryError(
            f"schema 1 needs a list under 'results' (got {type(results).__name__})",
            file=file,
            key="results",
            hint=_HINT_CORRUPT,
        )
    specs = []
    for spec in results:
        if not isinstance(spec, Mapping):
            specs.append(spec)  # validate_record reports it with its position
            continue
        new_spec = dict(spec)
        signals = spec.get("signals")
        if isinstance(signals, list):
            new_spec["signals"] = [_migrate_signal_1(sig) for sig in signals]
        specs.append(new_spec)
    return {
        "schema_version": 2,
        "model_version": old.get("version"),
        "started_utc": format_utc(started),
        "tool_versions": old.get("tools", {}),
        "specs": specs,
    }


def _migrate_signal_1(signal: Any) -> Any:
    if not isinstance(signal, Mapping):
        return signal
    new = dict(signal)
    lambdas = signal.get("lambdas")
    if isinstance(lambdas, Mapping):
        new["lambdas"] = [lambdas.get(name) for name in PAPER_CHARACTERISTICS]
    return new


def _migrate_2_to_3(old: Mapping[str, Any]) -> dict[str, Any]:
    """Lists in paper order become mappings by characteristic name."""
    specs = []
    for spec in old.get("specs", []) if isinstance(old.get("specs"), list) else []:
        if not isinstance(spec, Mapping):
            specs.append(spec)
            continue
        new_spec = dict(spec)
        if isinstance(spec.get("weights"), list):
            new_spec["weights"] = _paper_order(spec["weights"])
        signals = spec.get("signals")
        if isinstance(signals, list):
            new_spec["signals"] = [
                {**sig, "lambdas": _paper_order(sig["lambdas"])}
                if isinstance(sig, Mapping) and isinstance(sig.get("lambdas"), list)
                else sig
                for sig in signals
            ]
        specs.append(new_spec)
    return {**old, "schema_version": 3, "specs": specs if specs else old.get("specs")}


def _migrate_3_to_4(old: Mapping[str, Any]) -> dict[str, Any]:
    """Every record before acceptance was a baseline: it reads as accepted."""
    return {
        **old,
        "schema_version": SCHEMA_VERSION,
        "commit": None,
        "accepted": ACCEPTANCE[EARLIER_SCHEMA],
        "acceptance": EARLIER_SCHEMA,
        "baseline": None,
    }


def _paper_order(values: list[Any]) -> Any:
    # A list of the wrong length stays a list, so that validation names it.
    if len(values) != len(PAPER_CHARACTERISTICS):
        return values
    return dict(zip(PAPER_CHARACTERISTICS, values, strict=True))


def validate_record(record: Mapping[str, Any], *, file: str | None = None) -> dict[str, Any]:
    """Check a record of the current schema and return a normalised copy; errors name the
    file and key."""
    if record.get("schema_version") != SCHEMA_VERSION:
        raise HistoryError(
            f"expected schema_version {SCHEMA_VERSION} (got {record.get('schema_version')!r})",
            file=file,
            key="schema_version",
            hint="read records through migrate_record()",
        )
    model_version = record.get("model_version")
    if not isinstance(model_version, str) or not model_version:
        raise HistoryError(
            f"expected a non-empty string (got {model_version!r})",
            file=file,
            key="model_version",
            hint=_HINT_CORRUPT,
        )
    started = parse_utc(record.get("started_utc"), file=file)
    tools = record.get("tool_versions", {})
    if not isinstance(tools, Mapping) or not all(
        isinstance(k, str) and isinstance(v, str) for k, v in tools.items()
    ):
        raise HistoryError(
            "expected a mapping of tool name to version string",
            file=file,
            key="tool_versions",
            hint=_HINT_CORRUPT,
        )
    specs = record.get("specs")
    if not isinstance(specs, list):
        raise HistoryError(
            f"expected a list of spec results (got {type(specs).__name__})",
            file=file,
            key="specs",
            hint=_HINT_CORRUPT,
        )
    check_acceptance(record, file)
    commit = record.get("commit")
    if commit is not None and (not isinstance(commit, str) or not commit):
        raise HistoryError(
            f"expected a commit string or null (got {commit!r})",
            file=file,
            key="commit",
            hint=_HINT_CORRUPT,
        )
    return {
        "schema_version": SCHEMA_VERSION,
        "model_version": model_version,
        "started_utc": format_utc(started),
        "commit": commit,
        "accepted": record["accepted"],
        "acceptance": record["acceptance"],
        "baseline": _checked_baseline(record.get("baseline"), file),
        "tool_versions": dict(tools),
        "specs": [normalised_spec(spec, f"specs[{i}]", file) for i, spec in enumerate(specs)],
    }


def check_acceptance(record: Mapping[str, Any], file: str | None) -> None:
    """``acceptance`` is a known reason and ``accepted`` says what that reason means."""
    reason = record.get("acceptance")
    if reason not in ACCEPTANCE:
        raise HistoryError(
            f"unknown acceptance {reason!r}; expected one of {', '.join(ACCEPTANCE)}",
            file=file,
            key="acceptance",
            hint=_HINT_CORRUPT if file else "pass a key of ACCEPTANCE",
        )
    if record.get("accepted") is not ACCEPTANCE[reason]:
        raise HistoryError(
            f"accepted is {record.get('accepted')!r} but acceptance {reason!r} means "
            f"{ACCEPTANCE[reason]}",
            file=file,
            key="accepted",
            hint=_HINT_CORRUPT,
        )


def _checked_baseline(raw: Any, file: str | None) -> dict[str, Any] | None:
    if raw is None:
        return None
    if not isinstance(raw, Mapping) or not isinstance(raw.get("model_version"), str):
        raise HistoryError(
            "expected the baseline's model_version, started_utc and commit, or null",
            file=file,
            key="baseline",
            hint=_HINT_CORRUPT,
        )
    started = parse_utc(raw.get("started_utc"), where="baseline.started_utc", file=file)
    commit = raw.get("commit")
    return {
        "model_version": raw["model_version"],
        "started_utc": format_utc(started),
        "commit": commit if isinstance(commit, str) and commit else None,
    }


def normalised_spec(spec: Any, where: str, file: str | None) -> dict[str, Any]:
    if not isinstance(spec, Mapping):
        raise HistoryError(
            f"expected a spec result object (got {type(spec).__name__})",
            file=file,
            key=where,
            hint=_HINT_CORRUPT if file else "pass the engine's spec result dicts",
        )
    name = spec.get("name", spec.get("spec"))
    if not isinstance(name, str) or not name:
        raise HistoryError(
            f"a spec result needs a 'name' or 'spec' string (got {name!r})",
            file=file,
            key=f"{where}.name",
            hint=_HINT_CORRUPT if file else "pass the engine's spec result dicts",
        )
    out: dict[str, Any] = {key: spec[key] for key in _SPEC_KEYS if key in spec}
    out["name"] = name
    out["phi"] = checked_number(
        spec.get("phi"), where=f"{where}.phi", file=file, error=HistoryError
    )
    if "weights" in spec:
        out["weights"] = _lambda_mapping(spec["weights"], f"{where}.weights", file)
    if "min_phi" in spec:
        out["min_phi"] = checked_number(
            spec["min_phi"], where=f"{where}.min_phi", file=file, error=HistoryError
        )
    signals = spec.get("signals", [])
    if not isinstance(signals, list):
        raise HistoryError(
            f"expected a list (got {type(signals).__name__})",
            file=file,
            key=f"{where}.signals",
            hint=_HINT_CORRUPT,
        )
    out["signals"] = [
        _normalise_signal(sig, f"{where}.signals[{j}]", file) for j, sig in enumerate(signals)
    ]
    normalised: dict[str, Any] = plain_json(out, strict=True, where=where, error=HistoryError)
    return normalised


def _normalise_signal(signal: Any, where: str, file: str | None) -> dict[str, Any]:
    if not isinstance(signal, Mapping) or not isinstance(signal.get("path"), str):
        raise HistoryError(
            "expected a signal result object with a 'path' string",
            file=file,
            key=where,
            hint=_HINT_CORRUPT if file else "pass the engine's spec result dicts",
        )
    out: dict[str, Any] = {key: signal[key] for key in _SIGNAL_KEYS if key in signal}
    out["lambdas"] = _lambda_mapping(signal.get("lambdas"), f"{where}.lambdas", file)
    if isinstance(signal.get("local"), Mapping):
        out["local"] = _compact_local(signal["local"])
    if isinstance(signal.get("local_failures"), list):
        out["local_failures"] = list(signal["local_failures"])
    for key in MEASURED_NUMBERS:
        if key in signal:
            out[key] = checked_number(
                signal[key], where=f"{where}.{key}", file=file, error=HistoryError
            )
    return out


def _lambda_mapping(raw: Any, where: str, file: str | None) -> dict[str, float | None]:
    """Values keyed by characteristic name; a spec result of schema 1 gives seven in order."""
    if isinstance(raw, (list, tuple)) and len(raw) == len(PAPER_CHARACTERISTICS):
        raw = dict(zip(PAPER_CHARACTERISTICS, raw, strict=True))
    if not isinstance(raw, Mapping) or not raw or not all(isinstance(k, str) for k in raw):
        raise HistoryError(
            f"expected a mapping of characteristic name to value (got {raw!r})",
            file=file,
            key=where,
            hint=_HINT_CORRUPT if file else "pass the engine's spec result dicts",
        )
    return {
        name: checked_number(raw[name], where=f"{where}.{name}", file=file, error=HistoryError)
        for name in raw
    }


def _compact_local(local: Mapping[str, Any]) -> dict[str, Any]:
    """A signal's ``local`` as history keeps it: every table, but windows without their λ.

    Per-window λ of every signal of every run would make a record as large as the report;
    the windows' samples, RMS and mean error are enough to say which stretches a model change
    improved or broke.
    """
    out = {key: value for key, value in local.items() if key != "windows"}
    windows = local.get("windows")
    if isinstance(windows, Mapping):
        out["windows"] = {
            key: windows[key] for key in ("labels", "n", "rms", "mean_error") if key in windows
        }
    return out
