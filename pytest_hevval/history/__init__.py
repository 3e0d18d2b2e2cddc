"""Validation results over model versions: records, an append-only store, comparison with a
baseline, regression rules, a threshold ratchet, and trends.

Pure functions plus :class:`HistoryStore`; nothing here imports pytest or matplotlib at import
time. See ``docs/history.md`` for the record format and the option names.
"""

from ..results.changes import Comparison, FieldDelta, SignalComparison, SpecComparison
from ._base import ERROR_FIELDS, HistoryError
from .compare import compare
from .compare_fail import RULE_FIELDS, Rule, parse_compare_fail
from .index import TREND_RUNS
from .load import latest_results, load_document, load_side, report_problems
from .policy import (
    BaselineDecision,
    acceptance,
    is_ci,
    missing_baseline,
    records_this_run,
)
from .ratchet import (
    DEFAULT_MARGIN,
    RatchetOutcome,
    Thresholds,
    load_sidecar,
    merge_thresholds,
    parse_margin,
    ratchet_spec,
    ratchet_thresholds,
    render_sidecar,
    sidecar_path,
    write_sidecar,
)
from .records import (
    ACCEPTANCE,
    MODEL_VERSION_ENV,
    SCHEMA_VERSION,
    default_tool_versions,
    format_utc,
    make_record,
    migrate_record,
    parse_utc,
    resolve_commit,
    resolve_model_version,
    validate_record,
)
from .regressions import Regression, regressions
from .render import comparison_json, comparison_markdown, comparison_table
from .store import DEFAULT_HISTORY_DIR, HistoryStore, StoredRecord, StoreProblem, slugify
from .trends import (
    HistoryRow,
    Step,
    detect_steps,
    history_table,
    noise_sigma,
    plot_history,
    render_history_table,
)

__all__ = [
    "ACCEPTANCE",
    "DEFAULT_HISTORY_DIR",
    "DEFAULT_MARGIN",
    "ERROR_FIELDS",
    "MODEL_VERSION_ENV",
    "RULE_FIELDS",
    "SCHEMA_VERSION",
    "TREND_RUNS",
    "BaselineDecision",
    "Comparison",
    "FieldDelta",
    "HistoryError",
    "HistoryRow",
    "HistoryStore",
    "RatchetOutcome",
    "Regression",
    "Rule",
    "SignalComparison",
    "SpecComparison",
    "Step",
    "StoreProblem",
    "StoredRecord",
    "Thresholds",
    "acceptance",
    "compare",
    "comparison_json",
    "comparison_markdown",
    "comparison_table",
    "default_tool_versions",
    "detect_steps",
    "format_utc",
    "history_table",
    "is_ci",
    "latest_results",
    "load_document",
    "load_side",
    "load_sidecar",
    "make_record",
    "merge_thresholds",
    "migrate_record",
    "missing_baseline",
    "noise_sigma",
    "parse_compare_fail",
    "parse_margin",
    "parse_utc",
    "plot_history",
    "ratchet_spec",
    "ratchet_thresholds",
    "records_this_run",
    "regressions",
    "render_history_table",
    "render_sidecar",
    "report_problems",
    "resolve_commit",
    "resolve_model_version",
    "sidecar_path",
    "slugify",
    "validate_record",
    "write_sidecar",
]
